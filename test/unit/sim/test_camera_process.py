"""The camera's child process: renders the newest snapshot, reports its failures to the parent."""
import os
import time

import pytest

from ball_balance.hardware.camera_process import CameraProcess
from ball_balance.sim.config import CameraConfig, SimConfig
from ball_balance.sim.world import SimWorld


def wait_for(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.02)


@pytest.fixture(scope="module")
def world():
    return SimWorld(SimConfig(camera=CameraConfig(width_px=320, height_px=240)))


def test_child_process_renders_submitted_snapshots_and_stops(world):
    errors = []
    camera = CameraProcess(world.model, world.config.camera, 1.0, None, errors.append)
    camera.start()
    try:
        camera.submit(world.snapshot())
        wait_for(lambda: camera.frames_rendered >= 1, 60.0, "the first rendered frame")
        for _ in range(20):   # a burst: the child renders the newest and counts the ones it dropped
            world.step(5)
            camera.submit(world.snapshot())
        wait_for(lambda: camera.frames_rendered + camera.frames_skipped >= 21, 60.0, "the burst to be taken")
        assert camera.last_render_s > 0.0 and camera.render_cpu_s > 0.0
    finally:
        camera.stop()
    assert errors == []


def test_child_failure_reaches_the_parent(world, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "no_such_backend")
    errors = []
    camera = CameraProcess(world.model, world.config.camera, 1.0, None, errors.append)
    camera.start()
    try:
        wait_for(lambda: errors, 60.0, "the child's error")
    finally:
        camera.stop()
    assert "camera process" in str(errors[0])
    camera.submit(world.snapshot())   # after the failure: nothing raised in the loop


def child_threads(world, **options) -> list:
    """(scheduling policy, name) of each thread of a camera child started with `options`,
    once it has rendered its first frame."""
    errors = []
    camera = CameraProcess(world.model, world.config.camera, 1.0, None, errors.append, **options)
    camera.start()
    try:
        camera.submit(world.snapshot())
        wait_for(lambda: camera.frames_rendered >= 1, 60.0, "the first rendered frame")
        tasks = f"/proc/{camera._process.pid}/task"
        threads = []
        for tid in os.listdir(tasks):
            with open(f"{tasks}/{tid}/comm") as comm:
                threads.append((os.sched_getscheduler(int(tid)), comm.read().strip()))
    finally:
        camera.stop()
    assert errors == []
    return threads


def test_the_child_and_its_render_threads_run_normally_scheduled(world):
    """Software rendering is the graph's heaviest work: never at a real-time priority."""
    assert {policy for policy, _ in child_threads(world)} <= {os.SCHED_OTHER, os.SCHED_BATCH}


def test_extra_render_time_slows_every_frame(world):
    camera = CameraProcess(world.model, world.config.camera, 1.0, None, None, extra_render_s=0.3)
    camera.start()
    try:
        camera.submit(world.snapshot())
        wait_for(lambda: camera.frames_rendered >= 1, 60.0, "the first rendered frame")
        assert camera.last_render_s >= 0.3
    finally:
        camera.stop()


def test_camera_render_threads_sets_the_software_renderers_thread_count(world):
    render_threads = [name for _, name in child_threads(world, render_threads=1) if name.startswith("llvmpipe")]
    if not render_threads:
        pytest.skip("not rendering with Mesa's llvmpipe here (a GPU, or another software renderer)")
    assert render_threads == ["llvmpipe-0"]

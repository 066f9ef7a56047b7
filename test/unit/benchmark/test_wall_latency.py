"""Camera-to-command on the wall clock (ball_balance/benchmark/wall_latency.py): simulated
stamps mapped through /clock's write times, each state paired with the first command after it."""
import numpy as np

from ball_balance.benchmark.wall_latency import CameraToCommand

WALL0_S = 1.7e9          # wall clock at simulated time 0


def simulated_graph(pipeline_s=0.012, camera_hz=60.0, clock_hz=100.0, seconds=2.0, jitter_s=0.0005, seed=0):
    """A simulation running at real time (wall = WALL0 + sim + a loop's jitter), /clock at
    clock_hz, each frame's /ball_state written 8 ms after capture and its command
    pipeline_s after capture; a controller timer also writes commands in between."""
    rng = np.random.default_rng(seed)
    latency = CameraToCommand()
    for sim_s in np.arange(0.0, seconds, 1.0 / clock_hz):
        latency.add_clock(sim_s, WALL0_S + sim_s + rng.uniform(0.0, jitter_s))
    for stamp_s in np.arange(0.1, seconds - 0.1, 1.0 / camera_hz):
        latency.add_state(stamp_s, WALL0_S + stamp_s + 0.008)
        latency.add_command(WALL0_S + stamp_s + pipeline_s)
        latency.add_command(WALL0_S + stamp_s + pipeline_s + 0.2 / camera_hz)   # a later, unrelated one
    return latency


def test_simulated_stamps_give_the_wall_clock_pipeline_time():
    latency = simulated_graph(pipeline_s=0.012).latencies_s()
    assert latency.size > 100
    assert np.all(np.isfinite(latency))
    assert np.all(np.abs(latency - 0.012) < 0.001)     # the loop's jitter, no sim-clock quantisation


def test_without_clock_samples_stamps_are_wall_clock_times():
    latency = CameraToCommand()
    latency.add_state(100.000, 100.004)
    latency.add_command(100.003)           # before the state: acts on an older one
    latency.add_command(100.009)
    latency.add_command(100.011)
    assert np.allclose(latency.latencies_s(), [0.009])


def test_a_state_no_command_followed_yet_is_not_counted():
    latency = CameraToCommand()
    latency.add_clock(0.0, 50.0)
    latency.add_state(0.0, 50.004)
    assert latency.latencies_s().size == 0


def test_a_clock_that_goes_back_starts_the_map_over():
    latency = CameraToCommand()
    for sim_s in (0.0, 5.0, 10.0):
        latency.add_clock(sim_s, 1000.0 + sim_s)
    for sim_s in (0.0, 5.0):             # simulation restarted 20 s of wall time later
        latency.add_clock(sim_s, 1030.0 + sim_s)
    assert abs(latency.capture_wall_s(2.5) - 1032.5) < 1e-9


def test_a_state_after_the_last_clock_sample_read_is_not_counted():
    # slower than real time (wall = 1.4 x simulated): the offset grows, so a stamp past the
    # clock samples read cannot be mapped by holding the last offset
    latency = CameraToCommand()
    for sim_s in np.arange(0.0, 1.0, 0.01):
        latency.add_clock(sim_s, WALL0_S + 1.4 * sim_s)
    for stamp_s in np.arange(0.1, 2.0, 1.0 / 60.0):
        latency.add_state(stamp_s, WALL0_S + 1.4 * stamp_s + 0.008)
        latency.add_command(WALL0_S + 1.4 * stamp_s + 0.012)
    out = latency.latencies_s()
    assert out.size == 54                           # the states stamped 0.1-0.99 s
    assert np.all(np.abs(out - 0.012) < 1e-6)


def test_on_the_stamps_each_frame_is_answered_by_the_command_written_after_its_state():
    # simulated time at a fifth of real time; the controller stamps its commands with the last
    # /clock it saw (a 10 ms grid), so the answer to a frame may be stamped before it: the write
    # order pairs them, the stamps give the figure
    latency = CameraToCommand()
    frames_s = np.arange(0.1, 1.0, 1.0 / 30.0)
    for frame_s in frames_s:
        latency.add_state(frame_s, WALL0_S + 5.0 * (frame_s + 0.004))
        latency.add_command(WALL0_S + 5.0 * (frame_s + 0.006), np.floor(frame_s * 100.0) / 100.0)
    out = latency.stamp_latencies_s()
    assert out.size == frames_s.size
    assert np.allclose(out, np.floor(frames_s * 100.0) / 100.0 - frames_s)
    assert np.all((out < 1e-9) & (out > -0.0101))
    assert latency.stamp_latencies_s(since_s=0.5).size == np.count_nonzero(frames_s >= 0.5)

"""The overhead camera: all four markers detectable at home, pixel truth consistent with the
render, intrinsics from fovy, rendering in its own thread."""
import threading

import cv2
import numpy as np
import pytest

from ball_balance.plate_geometry import PlateGeometry
from ball_balance.sim.camera import CameraThread
from ball_balance.sim.config import CameraConfig, DomainKnobs, SimConfig, camera_intrinsics
from ball_balance.sim.world import SimWorld


def detect_markers(image):
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    detector = cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())
    corners, ids, _ = detector.detectMarkers(image)
    return {} if ids is None else {int(i): c.reshape(4, 2) for i, c in zip(ids.ravel(), corners, strict=True)}


@pytest.fixture(scope="module")
def world():
    world = SimWorld()
    yield world
    world.close()


@pytest.mark.parametrize("width,height", [(640, 480), (320, 240)])
def test_home_render_shows_all_four_markers_where_the_plate_puts_them(width, height):
    world = SimWorld(SimConfig(camera=CameraConfig(width_px=width, height_px=height)))
    image, _ = world.render()
    assert image.shape == (height, width, 3) and image.dtype == np.uint8
    markers = detect_markers(image)
    assert sorted(markers) == [0, 1, 2, 3]
    plate = PlateGeometry()
    for marker_id, corners in markers.items():
        expected = np.array([world.project_plate(x, y) for x, y in plate.marker_corners_m(marker_id)])
        assert np.abs(corners - expected).max() < 2.0, marker_id
    world.close()


def test_rendered_ball_is_where_the_frame_truth_says(world):
    world.reset(ball_xy=(0.08, -0.05))
    image, truth = world.render()
    orange = (image[:, :, 2] > 180) & (image[:, :, 1] < 170) & (image[:, :, 0] < 90)
    v, u = np.nonzero(orange)
    assert truth.visible and truth.ball.on_plate
    assert (truth.ball.x, truth.ball.y) == pytest.approx((0.08, -0.05), abs=1e-6)
    assert u.mean() == pytest.approx(truth.pixel_u, abs=1.0)
    assert v.mean() == pytest.approx(truth.pixel_v, abs=1.0)
    assert truth.pixel_u > 320 and truth.pixel_v > 240  # plate +x is right, +y is up


def test_intrinsics_follow_the_field_of_view():
    fx, fy, cx, cy = camera_intrinsics(CameraConfig(width_px=640, height_px=480, fovy_deg=90.0))
    assert fx == pytest.approx(240.0) and fy == fx and (cx, cy) == (319.5, 239.5)


def test_exposure_knob_darkens_the_image():
    bright, _ = SimWorld().render()
    dark, _ = SimWorld(knobs=DomainKnobs(exposure=0.5)).render()
    assert dark.mean() == pytest.approx(bright.mean() * 0.5, rel=0.05)


def test_camera_thread_renders_snapshots_off_the_calling_thread(world):
    world.reset()
    frames, threads, done = [], [], threading.Event()

    def on_frame(image, snapshot):
        frames.append((image.shape, snapshot.time_s))
        threads.append(threading.current_thread().name)
        done.set()

    camera = CameraThread(world.model, world.config.camera, 1.0, on_frame)
    camera.start()
    try:
        world.advance(0.1)
        camera.submit(world.snapshot())
        assert done.wait(10.0)
    finally:
        camera.stop()
    assert frames == [((480, 640, 3), pytest.approx(0.1))]
    assert threads == ["sim_camera"]


def test_light_knob_changes_the_lighting():
    dim, _ = SimWorld(knobs=DomainKnobs(light_scale=0.5)).render()
    bright, _ = SimWorld(knobs=DomainKnobs(light_scale=1.4)).render()
    assert bright.mean() > dim.mean() + 10


@pytest.mark.parametrize("light_scale", [0.4, 1.6])
def test_plate_face_shows_no_seam_around_the_markers_under_any_light(light_scale):
    """The markers are textured quads set into the plain face (cheaper to render): the face
    around them must look the same as one texture would, whatever the light."""
    from ball_balance.plate_geometry import MARKER_CENTRES_M, MARKER_SIDE_M, PLATE_SIDE_M

    world = SimWorld(knobs=DomainKnobs(light_scale=light_scale))
    image, _ = world.render()
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(int)
    half, reach = PLATE_SIDE_M / 2.0 - 0.003, MARKER_SIDE_M / 2.0 + 0.02
    for marker_id, (x, y) in MARKER_CENTRES_M.items():
        for offset in (0.004, 0.008, 0.012):       # lines through the quiet zone, across the quad's edge
            d = MARKER_SIDE_M / 2.0 + offset
            lines = [[(x + s, y + sign * d) for s in np.linspace(-reach, reach, 200)] for sign in (-1, 1)]
            lines += [[(x + sign * d, y + s) for s in np.linspace(-reach, reach, 200)] for sign in (-1, 1)]
            for line in lines:
                pixels = [tuple(np.round(world.project_plate(px, py)).astype(int)) for px, py in line
                          if abs(px) < half and abs(py) < half]
                values = np.array([gray[v, u] for u, v in dict.fromkeys(pixels)])
                assert np.abs(np.diff(values)).max() <= 2, (marker_id, offset, light_scale)
    world.close()

"""Tools around the simulation: the description CLI, the PNG/MP4 recorder, image conversion."""
import cv2
import numpy as np

from ball_balance import robot
from ball_balance.sim import record


def test_description_cli_prints_the_selected_hardware(capsys):
    assert robot.main(["--hardware", "mock"]) == 0
    assert robot.hardware_plugin(capsys.readouterr().out) == "mock_components/GenericSystem"


def test_description_cli_refuses_an_unknown_hardware(capsys):
    assert robot.main(["--hardware", "gazebo"]) == 2
    assert "unknown hardware 'gazebo'" in capsys.readouterr().err


def test_recorder_writes_a_still_and_a_video(tmp_path):
    png, mp4 = tmp_path / "still.png", tmp_path / "clip.mp4"
    assert record.main(["--png", str(png), "--mp4", str(mp4), "--duration", "0.5", "--width", "320",
                        "--height", "240"]) == 0
    assert cv2.imread(str(png)).shape == (240, 320, 3)
    capture = cv2.VideoCapture(str(mp4))
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert frames == 15


def test_recorder_refuses_a_zero_resolution(tmp_path, capsys):
    assert record.main(["--png", str(tmp_path / "x.png"), "--width", "0"]) == 2
    assert "width_px" in capsys.readouterr().err


def test_image_messages_convert_rgb8_and_bgr8_and_refuse_others():
    from sensor_msgs.msg import Image

    from ball_balance.ros.images import decode_image, encode_image

    bgr = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
    msg = Image(height=4, width=5, encoding="bgr8", step=15, data=bgr.tobytes())
    assert np.array_equal(decode_image(msg)[0], bgr)
    msg = Image(height=4, width=5, encoding="rgb8", step=15, data=bgr[:, :, ::-1].tobytes())
    assert np.array_equal(decode_image(msg)[0], bgr)
    assert np.array_equal(decode_image(encode_image(bgr, msg.header.stamp, "camera"))[0], bgr)
    image, problem = decode_image(Image(height=4, width=5, encoding="mono8", step=5, data=bytes(20)))
    assert image is None and "mono8" in problem

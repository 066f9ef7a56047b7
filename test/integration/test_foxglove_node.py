"""ball_balance_foxglove seen by an independent Foxglove client: the `@foxglove/ws-protocol`
client from npm, run with Node (test/integration/foxglove_client/client.js), decodes the
ball state and a MuJoCo-rendered camera frame from the CDR bytes and ros2msg schemas the node
serves, field for field as this test published them over DDS, stamped with the simulated
time of /clock that the node also sends as the server's time.

The npm packages are installed from the folder's package-lock.json into build/foxglove_client
(`npm ci`, once per lock file: test/foxglove_ws_client.py). Without `node` and `npm` the tests
are skipped.
"""
import hashlib
import json
import re
import socket

import pytest
from ball_tracker_msgs.msg import BallState
from geometry_msgs.msg import TransformStamped
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image
from tf2_msgs.msg import TFMessage

import foxglove_ws_client
from ball_balance.hardware.sim_ros import IMAGE_SENSOR_DATA
from ball_balance.ros.images import encode_image
from ball_balance.tf.ros import STATIC_BROADCASTER_QOS
from harness import DomainLease, Graph, Launcher, executable, ros_env, stop_groups

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(bool(foxglove_ws_client.missing_tools()),
                                 reason="needs Node.js (`node` and `npm`) for the independent Foxglove client")]
PUBLISH_PERIOD_S = 0.1
START_TIMEOUT_S = 60.0   # the node's first line on a loaded machine
CLIENT_TIMEOUT_S = 60    # the client's own deadline; it prints what it has by then


def expected_ball(i: int) -> dict:
    """The i-th BallState this test publishes, as the client prints it."""
    return {"header": {"stamp": {"sec": 1000 + i, "nanosec": 250_000_000}, "frame_id": "plate_center"},
            "x": 0.01 + 0.001 * i, "y": -0.02 + 0.0005 * i, "vx": 0.125, "vy": -0.0625, "ball_found": True,
            "tracking_valid": True, "markers_found": 4, "pixel_u": 320.5 + i, "pixel_v": 240.25}


def ball_msg(values: dict) -> BallState:
    msg = BallState(**{k: v for k, v in values.items() if k != "header"})
    msg.header.stamp.sec, msg.header.stamp.nanosec = values["header"]["stamp"].values()
    msg.header.frame_id = values["header"]["frame_id"]
    return msg


class Served:
    """The module's graph: this process publishes, the node serves, clients connect."""

    def __init__(self, launcher: Launcher, graph: Graph, node_modules: str):
        from ball_balance.sim.world import SimWorld

        world = SimWorld()   # a real rendered frame: the plate, its markers and the ball
        world.place_ball(0.05, -0.03)
        self.frame, _ = world.render()
        world.close()
        self.frame_sha256 = hashlib.sha256(self.frame.tobytes()).hexdigest()
        self.launcher, self.graph, self.node_modules = launcher, graph, node_modules
        node = graph.node
        self.ball_pub = node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
        self.image_pub = node.create_publisher(Image, "/camera/image_raw", IMAGE_SENSOR_DATA)
        self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))  # as the simulation's
        self.clocks_ns = set()
        static_pub = node.create_publisher(TFMessage, "/tf_static", STATIC_BROADCASTER_QOS)
        static_pub.publish(TFMessage(transforms=[self.static_transform()]))
        self.count = 0
        node.create_timer(PUBLISH_PERIOD_S, self.publish)
        self.node = launcher.start([executable("ball_balance_foxglove"), "--ros-args", "-p", "port:=0",
                                    "-p", "topics:=[/ball_state, /camera/image_raw, /tf_static]"],
                                   name="foxglove")
        found = []

        def started() -> bool:  # and following the simulated time of /clock
            found[:] = re.findall(r"ws://127\.0\.0\.1:(\d+)", self.node.output())
            assert self.node.running, self.node.output()
            return bool(found) and "following /clock" in self.node.output()

        graph.spin_until(started, START_TIMEOUT_S, "the node's start-up line and /clock")
        self.url = f"ws://127.0.0.1:{found[0]}"

    @staticmethod
    def static_transform() -> TransformStamped:
        transform = TransformStamped(child_frame_id="camera_optical_frame")
        transform.header.frame_id = "base_link"
        transform.header.stamp.sec = 7
        transform.transform.translation.z = 1.25
        transform.transform.rotation.x = 1.0
        return transform

    def publish(self) -> None:
        """The i-th tick: /clock, the ball state and the frame, all at the same simulated time."""
        i = self.count
        self.count += 1
        stamp = ball_msg(expected_ball(i)).header.stamp
        self.clocks_ns.add(stamp.sec * 1_000_000_000 + stamp.nanosec)
        self.clock_pub.publish(Clock(clock=stamp))
        self.ball_pub.publish(ball_msg(expected_ball(i)))
        self.image_pub.publish(encode_image(self.frame, stamp, "camera_optical_frame"))

    def start_client(self, *args: str, name: str = "client"):
        env = ros_env(self.launcher.domain_id, NODE_PATH=self.node_modules)
        return self.launcher.start(foxglove_ws_client.command(self.url, "--timeout", str(CLIENT_TIMEOUT_S), *args),
                                   name=name, env=env)

    def result(self, client) -> dict:
        """The client's JSON, once it printed it (spinning, so that this process keeps publishing)."""
        def json_lines():  # whole lines only: the client may be writing the last one
            return [line for line in client.output().split("\n")[:-1] if line.startswith("{")]

        self.graph.spin_until(lambda: json_lines() or not client.running, CLIENT_TIMEOUT_S + 30, "the client's JSON")
        self.graph.spin_until(json_lines, 5, f"the client's JSON (it printed: {client.output()!r})")
        return json.loads(json_lines()[-1])


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    node_modules = foxglove_ws_client.install()
    lease = DomainLease()
    launcher = Launcher(lease.domain_id, tmp_path_factory.mktemp("foxglove"))
    graph = Graph(lease.domain_id)
    try:
        yield Served(launcher, graph, node_modules)
    finally:
        launcher.stop_all()
        graph.close()
        lease.release()


def test_an_independent_client_decodes_the_ball_state_and_the_camera(served):
    client = served.start_client("--count", "3", "--topic", "/ball_state", "--topic", "/camera/image_raw")
    result = served.result(client)
    assert "error" not in result, result
    assert client.wait(timeout=10) == 0
    assert result["serverInfo"]["name"] == "ball_balance" and "time" in result["serverInfo"]["capabilities"]
    # the graph's simulated time, from /clock: the server's time and every message's log time
    assert int(result["time"]) in served.clocks_ns
    for topic, log_times in result["logTimes"].items():
        assert {int(t) for t in log_times} <= served.clocks_ns, topic
    assert result["channels"] == {
        "/ball_state": {"schemaName": "ball_tracker_msgs/msg/BallState", "encoding": "cdr",
                        "schemaEncoding": "ros2msg"},
        "/camera/image_raw": {"schemaName": "sensor_msgs/msg/Image", "encoding": "cdr", "schemaEncoding": "ros2msg"}}
    for ball in result["messages"]["/ball_state"]:
        assert ball == expected_ball(ball["header"]["stamp"]["sec"] - 1000)
    height, width = served.frame.shape[:2]
    for image in result["messages"]["/camera/image_raw"]:
        assert image["header"]["frame_id"] == "camera_optical_frame"
        assert image["header"]["stamp"]["nanosec"] == 250_000_000
        assert (image["width"], image["height"], image["encoding"], image["step"], image["is_bigendian"]) == \
            (width, height, "bgr8", 3 * width, 0)
        assert image["data"] == {"length": width * height * 3, "sha256": served.frame_sha256}


def test_a_client_joining_later_still_receives_the_latched_transforms(served):
    """/tf_static is published once: the second client gets it because the node subscribes anew."""
    first = served.start_client("--count", "1", "--topic", "/tf_static", "--topic", "/ball_state",
                                "--hold", "120", name="first_client")
    try:
        assert "error" not in served.result(first)
        second = served.result(served.start_client("--topic", "/tf_static:1", name="second_client"))
        assert "error" not in second, second
        (message,) = second["messages"]["/tf_static"]
        (transform,) = message["transforms"]
        assert transform["header"] == {"stamp": {"sec": 7, "nanosec": 0}, "frame_id": "base_link"}
        assert transform["child_frame_id"] == "camera_optical_frame"
        assert transform["transform"]["translation"] == {"x": 0.0, "y": 0.0, "z": 1.25}
        assert first.running  # the first client was still watching when the second joined
    finally:
        stop_groups([first.popen])


def test_a_port_in_use_stops_the_node_with_one_clear_line(served):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = served.launcher.run([executable("ball_balance_foxglove"), "--ros-args", "-p", f"port:={port}"],
                                     timeout=60)
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert f"cannot serve on 127.0.0.1:{port}" in result.stderr and "Traceback" not in result.stderr

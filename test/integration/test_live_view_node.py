"""ball_balance_live_view without a browser: a page's requests reach the robot manager's
services as lifecycle_msgs and std_srvs calls, and a robot manager that does not answer is
reported at the deadline while the server keeps serving. The robot manager here is this test's
own node (its services answer only while the test spins it). GET /api/state gives the newest
ball state whether or not a page is connected."""
import asyncio
import json
import threading
import time
import urllib.request

import aiohttp
import pytest
from ball_tracker_msgs.msg import BallState
from lifecycle_msgs.srv import ChangeState
from rclpy.qos import qos_profile_sensor_data
from std_srvs.srv import Trigger

from harness import executable

pytestmark = pytest.mark.integration
START_TIMEOUT_S = 60.0


def start_live_view(launcher, graph):
    node = launcher.start([executable("ball_balance_live_view"), "--ros-args", "-p", "port:=0",
                           "-p", "call_timeout_s:=1.0"], name="live_view")
    return graph.wait_for_output(node, r"live view on (http://127\.0\.0\.1:\d+/)", START_TIMEOUT_S,
                                 "the live view's start-up line"), node


async def ask(url: str, requests: list, timeout: float = 30.0) -> list:
    """Send the requests as a page does; their replies, in order of the requests."""
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url + "ws") as ws:
            for i, request in enumerate(requests):
                await ws.send_str(json.dumps(dict(request, id=i)))
            replies = {}
            while len(replies) < len(requests):
                message = await asyncio.wait_for(ws.receive(), timeout)
                if message.type == aiohttp.WSMsgType.TEXT and json.loads(message.data)["type"] == "reply":
                    reply = json.loads(message.data)
                    replies[reply["id"]] = reply
            return [replies[i] for i in range(len(requests))]


def run_while_spinning(graph, coroutine, timeout: float = 60.0):
    """Run the page's coroutine in a thread while this test's node answers its services."""
    import concurrent.futures

    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        future = pool.submit(asyncio.run, coroutine)
        graph.spin_until(future.done, timeout, "the page's replies")
        return future.result()


def test_lifecycle_and_emergency_stop_requests_reach_the_robot_manager(launcher, graph):
    calls = []

    def change_state(request, response):
        calls.append(("change_state", request.transition.id, request.transition.label))
        response.success = True
        return response

    def trigger(name):
        def answer(request, response):
            calls.append((name,))
            response.success, response.message = True, f"{name} done"
            return response
        return answer
    graph.node.create_service(ChangeState, "/robot_manager/change_state", change_state)
    graph.node.create_service(Trigger, "/robot_manager/emergency_stop", trigger("emergency_stop"))
    graph.node.create_service(Trigger, "/robot_manager/reset_emergency_stop", trigger("reset_emergency_stop"))
    url, node = start_live_view(launcher, graph)
    # the node sees the services once discovery has run: ask until the first answer is not "absent"
    graph.spin_for(1.0)
    replies = []
    for _ in range(30):
        replies = run_while_spinning(graph, ask(url, [{"op": "lifecycle", "transition": "activate"}]))
        if "not available" not in replies[0]["message"]:
            break
        graph.spin_for(1.0)
    assert replies[0] == {"type": "reply", "id": 0, "ok": True, "message": "activate: done"}
    replies = run_while_spinning(graph, ask(url, [{"op": "emergency_stop"}, {"op": "reset_emergency_stop"},
                                                  {"op": "lifecycle", "transition": "reboot"}]))
    assert [r["ok"] for r in replies] == [True, True, False]
    assert replies[0]["message"] == "emergency stop: emergency_stop done"
    assert "unknown transition" in replies[2]["message"]
    assert calls[-3:] == [("change_state", 3, "activate"), ("emergency_stop",), ("reset_emergency_stop",)]
    graph.spin_until(lambda: "refused a page's request: unknown transition 'reboot'" in node.output(),
                     30.0, "the refused request in the node's log")
    assert "(1 refused so far)" in node.output()
    # a flood of one request is carried out every time and logged once per few seconds (10: the
    # depth of this test's service queue)
    replies = run_while_spinning(graph, ask(url, [{"op": "lifecycle", "transition": "configure"}] * 10))
    assert all(r["ok"] for r in replies) and calls.count(("change_state", 1, "configure")) == 10
    assert node.output().count("page: configure") <= 2
    # bad input, a page's request that is not JSON and a malformed HTTP request: counted, one
    # line each, no traceback
    assert asyncio.run(bad_input(url)) == (400, False)
    graph.spin_until(lambda: "a page's request is not JSON" in node.output()
                     and "malformed HTTP request: LineTooLong" in node.output(), 30.0, "the bad input in the log")
    assert "(3 refused so far)" in node.output() and "Traceback" not in node.output()


async def bad_input(url: str) -> tuple:
    """A GET whose request line is too long (its status), and a page's request that is not JSON
    (its reply's ok)."""
    async with aiohttp.ClientSession() as session:
        async with session.get(url + "api/state?q=" + "x" * 9000) as response:
            status = response.status
        async with session.ws_connect(url + "ws") as ws:
            await ws.send_str("{not json")
            while True:
                message = json.loads((await asyncio.wait_for(ws.receive(), 30.0)).data)
                if message["type"] == "reply":
                    return status, message["ok"]


def test_a_robot_manager_that_does_not_answer_is_reported_at_the_deadline(launcher, graph):
    graph.node.create_service(Trigger, "/robot_manager/emergency_stop", lambda request, response: response)
    url, _ = start_live_view(launcher, graph)
    graph.spin_for(1.0)
    for _ in range(30):   # until discovered; then never spun while the page waits: no answer
        reply = asyncio.run(ask(url, [{"op": "emergency_stop"}]))[0]
        if "not available" not in reply["message"]:
            break
        graph.spin_for(1.0)
    assert reply["ok"] is False
    assert reply["message"] == "emergency stop: /robot_manager/emergency_stop did not answer within 1 s"
    # and the server still serves
    assert asyncio.run(ask(url, [{"op": "set_parameters", "values": {"kp": "x"}}]))[0]["ok"] is False


def test_api_state_is_the_newest_ball_state_with_or_without_a_page(launcher, graph):
    """A script's GET /api/state follows the ball with no page ever connected, and after a page has
    come and gone (it answered {} before any page, then stayed at the page's last state)."""
    url, node = start_live_view(launcher, graph)
    publisher = graph.node.create_publisher(BallState, "/ball_state", qos_profile_sensor_data)
    ball = {"x": 0.011}              # what the publisher sends now (replaced as a whole)
    stop = threading.Event()

    def publish() -> None:           # a tracker at 50 Hz: stamps advance 0.02 s a message
        for i in range(10 ** 9):
            if stop.wait(0.02):
                return
            msg = BallState(x=ball["x"], y=-0.02, tracking_valid=True, ball_found=True, markers_found=4)
            msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + i // 50, (i % 50) * 20_000_000
            publisher.publish(msg)

    def state_with(x: float, timeout: float = 60.0) -> dict:
        """GET /api/state until its ball is at x (discovery of a new subscription takes its time)."""
        deadline, state = time.monotonic() + timeout, {}
        while time.monotonic() < deadline:
            with urllib.request.urlopen(url + "api/state", timeout=30.0) as response:
                state = json.loads(response.read())
            if (state.get("ball") or {}).get("x") == x:
                return state
            time.sleep(0.1)
        raise AssertionError(f"/api/state did not show the ball at x={x} within {timeout:.0f} s: {state}")

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        first = state_with(0.011)                 # no page has ever connected
        assert first["type"] == "state" and first["t"] >= 100.0 and first["ball"]["y"] == -0.02
        ball = {"x": 0.022}
        second = state_with(0.022)
        assert second["t"] > first["t"]
        asyncio.run(ask(url, []))                 # a page comes and goes
        ball = {"x": 0.033}
        third = state_with(0.033)
        assert third["t"] > second["t"]
    finally:
        stop.set()
        thread.join(timeout=10.0)
    assert "asked for /api/state: following the ball and the arm" in node.output()

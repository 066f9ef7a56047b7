"""ball_balance_live_view without a browser: a page's requests reach the robot manager's
services as lifecycle_msgs and std_srvs calls, and a robot manager that does not answer is
reported at the deadline while the server keeps serving. The robot manager here is this test's
own node (its services answer only while the test spins it)."""
import asyncio
import json

import aiohttp
import pytest
from lifecycle_msgs.srv import ChangeState
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
    graph.spin_until(lambda: "refused a page's request (1 so far): unknown transition 'reboot'" in node.output(),
                     30.0, "the refused request in the node's log")


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

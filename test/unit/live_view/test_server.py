"""The live view's web server without ROS: the page and its files, the state and frames pushed
to a WebSocket, requests answered (or refused, or timed out) without holding the server, and
/api/state built on request with no page connected."""
import asyncio
import concurrent.futures
import json
import socket
import time
import urllib.request

import aiohttp
import pytest

from ball_balance.live_view.commands import CommandError
from ball_balance.live_view.server import LiveViewServer, state_json


@pytest.fixture
def server():
    answers = {}

    def handle(request):
        if request.get("op") == "bad":
            raise CommandError("unknown op 'bad'")
        future = concurrent.futures.Future()
        answers[request["op"]] = future
        if request["op"] == "ok":
            future.set_result((True, "done"))
        return future     # "never": nobody answers

    pages, refused = [], []
    srv = LiveViewServer("127.0.0.1", 0, handle, pages.append, reply_timeout_s=0.5, idle_timeout_s=0.5,
                         on_refused=lambda kind, why: refused.append((kind, why)))
    srv.start()
    srv.pages_seen, srv.refused = pages, refused
    yield srv
    srv.stop()


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, 20.0))


def test_the_page_and_its_files_are_served_from_the_package(server):
    async def get():
        async with aiohttp.ClientSession() as session:
            pages = {}
            for path in ("/", "/static/app.js", "/static/style.css"):
                async with session.get(server.url.rstrip("/") + path) as response:
                    pages[path] = (response.status, await response.text())
            return pages
    pages = run(get())
    assert all(status == 200 for status, _ in pages.values())
    assert '<script src="/static/app.js">' in pages["/"][1]
    for _, text in pages.values():    # nothing from elsewhere
        assert "http://" not in text and "https://" not in text


def test_a_page_gets_state_and_frames_and_answers_to_its_requests(server):
    async def session_run():
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(server.url + "ws") as ws:
                server.push_state({"ball": {"x": 0.01}})
                server.push_frame(b"\xff\xd8jpeg")
                got = {}
                while "state" not in got or "frame" not in got:
                    message = await ws.receive()
                    if message.type == aiohttp.WSMsgType.BINARY:
                        got["frame"] = message.data
                    elif json.loads(message.data).get("ball"):
                        got["state"] = json.loads(message.data)
                replies = []
                for i, op in enumerate(("ok", "bad", "never")):
                    await ws.send_str(json.dumps({"id": i, "op": op}))
                await ws.send_str("{not json")
                while len(replies) < 4:
                    message = json.loads((await ws.receive()).data)
                    if message["type"] == "reply":
                        replies.append(message)
                return got, sorted(replies, key=lambda r: (r["id"] is None, r["id"] or 0))
    got, replies = run(session_run())
    assert got["frame"] == b"\xff\xd8jpeg" and got["state"]["type"] == "state"
    assert replies[0] == {"type": "reply", "id": 0, "ok": True, "message": "done"}
    assert replies[1]["ok"] is False and "unknown op" in replies[1]["message"]
    assert replies[2]["ok"] is False and "no answer within 0.5 s" in replies[2]["message"]
    assert replies[3]["ok"] is False and replies[3]["id"] is None
    assert server.pages_seen[0] == 1 and server.pages_seen[-1] in (0, 1)
    # the request that is not JSON is handed to the ROS side to count and log (a refused
    # command, "bad", is the ROS side's own to count)
    assert [kind for kind, _ in server.refused] == ["json"] and "not JSON" in server.refused[0][1]


def test_a_malformed_http_request_is_one_line_to_count_not_a_traceback(server, capfd, caplog):
    async def get():
        async with aiohttp.ClientSession() as session:
            statuses = []
            for _ in range(3):
                async with session.get(server.url + "api/state?q=" + "x" * 9000) as response:
                    statuses.append(response.status)
            async with session.get(server.url + "api/state") as response:   # the server goes on
                statuses.append(response.status)
            return statuses
    assert run(get()) == [400, 400, 400, 200]
    assert [kind for kind, _ in server.refused] == ["http"] * 3
    assert "LineTooLong" in server.refused[0][1] and "\n" not in server.refused[0][1]
    assert "Traceback" not in capfd.readouterr().err and not caplog.records


def test_a_connection_without_a_whole_request_is_closed_and_a_page_is_not(server):
    with socket.create_connection(("127.0.0.1", server.port), timeout=10.0) as slow:
        slow.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")     # never finished (slowloris)
        started = time.monotonic()
        assert slow.recv(1024) == b""                                  # closed by the server
        assert time.monotonic() - started < 5.0

    async def page_stays():
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(server.url + "ws") as ws:
                await asyncio.sleep(1.0)                                # twice the idle timeout
                await ws.send_str(json.dumps({"id": 1, "op": "ok"}))
                while True:
                    message = json.loads((await ws.receive()).data)
                    if message["type"] == "reply":
                        return message
    assert run(page_stays())["ok"] is True


def test_a_websocket_from_another_origin_is_refused(server):
    async def connect():
        async with aiohttp.ClientSession() as session:
            with pytest.raises(aiohttp.WSServerHandshakeError) as error:
                await session.ws_connect(server.url + "ws", headers={"Origin": "http://evil.example"})
            return error.value.status
    assert run(connect()) == 403


def test_a_busy_port_is_one_clear_error(server):
    other = LiveViewServer("127.0.0.1", server.port, lambda request: None)
    with pytest.raises(OSError):
        other.start()


def get_state(server) -> dict:
    with urllib.request.urlopen(server.url + "api/state", timeout=20.0) as response:
        return json.loads(response.read())


def test_api_state_is_built_on_request_without_a_page():
    """No page, nothing pushed: each GET /api/state gets the state the ROS side has then."""
    asked = []

    def state():
        asked.append(len(asked))
        future = concurrent.futures.Future()
        future.set_result({"t": 43.68 + len(asked), "ball": {"x": 0.001 * len(asked)}})
        return future
    server = LiveViewServer("127.0.0.1", 0, lambda request: None, state=state)
    server.start()
    try:
        first, second = get_state(server), get_state(server)
    finally:
        server.stop()
    assert not server.pages and server.latest_state is None
    assert first == {"t": 44.68, "ball": {"x": 0.001}, "type": "state"}
    assert second["t"] > first["t"] and second["ball"] == {"x": 0.002}


def test_api_state_falls_back_to_the_last_state_sent_when_the_ros_side_does_not_answer():
    logged = []
    server = LiveViewServer("127.0.0.1", 0, lambda request: None, reply_timeout_s=0.2, log=logged.append,
                            state=concurrent.futures.Future)     # never answered
    server.start()
    try:
        assert get_state(server) == {}
        server.push_state({"t": 1.5})
        deadline = time.monotonic() + 20.0
        while server.latest_state is None and time.monotonic() < deadline:   # through the server's loop
            time.sleep(0.02)
        assert get_state(server) == {"t": 1.5, "type": "state"}
    finally:
        server.stop()
    assert "the newest state was not built" in logged[0]


def test_the_state_is_strict_json_whatever_its_values():
    # JSON.parse refuses Infinity and NaN, and a page would then show nothing at all
    text = state_json({"controller": {"parameters": {"max_ball_speed_m_s": float("inf")}},
                       "errors": [[0.0, float("nan"), 0.001]], "t": 1.5})
    assert json.loads(text) == {"controller": {"parameters": {"max_ball_speed_m_s": None}},
                                "errors": [[0.0, None, 0.001]], "t": 1.5, "type": "state"}
    assert "Infinity" not in text and "NaN" not in text

"""The live view's web server: aiohttp on an asyncio loop in a thread of its own.

  GET /            the page (static/index.html; its script and style from /static/, nothing
                   from the internet)
  GET /api/state   the newest state as JSON (for scripts and curl), whether or not a page is
                   connected: built on request by `state()` (the ROS side), which returns a
                   concurrent.futures.Future of the state dict; without `state` (or when it
                   does not answer within `reply_timeout_s`), the last state pushed
  GET /ws          WebSocket: the server sends the state as JSON text messages
                   ({"type": "state", ...}; strict JSON, a value that is not finite is null)
                   and camera frames as binary messages (JPEG); the page sends requests
                   ({"id": n, "op": ...}, live_view.commands) and gets one
                   {"type": "reply", "id": n, "ok": bool, "message": str} for each.

Threads: the ROS side calls `push_state()` and `push_frame()` from its own threads; they hand
the data to the loop with call_soon_threadsafe and return at once. Each page has one sender
task holding only the newest state and the newest frame: a slow page gets fewer updates, the
ROS side never waits for it. A request goes to `handle(request)`, which returns a
concurrent.futures.Future that the ROS side completes with (ok, message); the server waits for
it at most `reply_timeout_s` and then answers the page itself, so that no request can hold the
server or the page.

WebSocket connections are accepted only from the page's own origin (a page of another site
open in the same browser must not press the emergency stop or activate the arm).

Bad input costs one line at most: a page's request that is not JSON, and a malformed HTTP
request (a request line or header too long, not HTTP), go to `on_refused(kind, why)` for the
ROS side to count and log throttled; aiohttp's own traceback for the latter is not logged. A
connection that sends no complete request for IDLE_TIMEOUT_S is closed (slow or idle clients).
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import json
import logging
import math
import threading
from pathlib import Path
from typing import Callable, Optional, Set
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web
from aiohttp.http_exceptions import HttpProcessingError

STATIC_DIR = Path(__file__).resolve().parent / "static"
START_TIMEOUT_S = 10.0
MAX_MESSAGE_BYTES = 4096    # a page's request is small; anything bigger closes its connection
# A connection is closed when no complete request arrived for this long (aiohttp's keep-alive
# timeout, which also runs from the connection's start): a request's header comes in one packet
# from a browser or a script, and a browser opens a new connection when it needs one, so only a
# client that holds connections open without asking (slowloris) notices.
IDLE_TIMEOUT_S = 15.0


def state_json(snapshot: dict) -> str:
    """The state message as strict JSON: a page parses it with JSON.parse, which refuses
    Infinity and NaN and would then show nothing at all, so a value that is not finite (a
    parameter set to .inf, an age before anything arrived) is sent as null."""
    return json.dumps(_finite(dict(snapshot, type="state")), allow_nan=False)


def _finite(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


class _Page:
    """One connected page: the newest state and frame waiting to be sent, and replies."""

    def __init__(self, ws: web.WebSocketResponse):
        self.ws = ws
        self.state: Optional[str] = None
        self.frame: Optional[bytes] = None
        self.replies: list = []
        self.wake = asyncio.Event()

    async def send_forever(self) -> None:
        while not self.ws.closed:
            await self.wake.wait()
            self.wake.clear()
            replies, self.replies = self.replies, []
            state, self.state = self.state, None
            frame, self.frame = self.frame, None
            for reply in replies:
                await self.ws.send_str(reply)
            if state is not None:
                await self.ws.send_str(state)
            if frame is not None:
                await self.ws.send_bytes(frame)


class _ProtocolErrors(logging.Handler):
    """aiohttp's server log: a malformed request (its exception an HttpProcessingError) becomes one
    line to `on_refused`, without the traceback; anything else goes on to aiohttp's own logger."""

    def __init__(self, on_refused: Callable[[str, str], None]):
        super().__init__()
        self.on_refused = on_refused

    def emit(self, record: logging.LogRecord) -> None:
        error = record.exc_info[1] if record.exc_info else None
        if isinstance(error, HttpProcessingError):
            self.on_refused("http", f"malformed HTTP request: {type(error).__name__}: {error.message}")
        else:
            logging.getLogger("aiohttp.server").handle(record)


class LiveViewServer:
    def __init__(self, host: str, port: int, handle: Callable[[dict], concurrent.futures.Future],
                 on_pages: Callable[[int], None] = lambda count: None, reply_timeout_s: float = 5.0,
                 log: Callable[[str], None] = print,
                 state: Optional[Callable[[], concurrent.futures.Future]] = None,
                 on_refused: Callable[[str, str], None] = lambda kind, why: print(why),
                 idle_timeout_s: float = IDLE_TIMEOUT_S):
        self.host, self.requested_port = host, port
        self.handle, self.on_pages, self.reply_timeout_s, self.log = handle, on_pages, reply_timeout_s, log
        self.state, self.on_refused, self.idle_timeout_s = state, on_refused, idle_timeout_s
        self.port: Optional[int] = None
        self.pages: Set[_Page] = set()
        self.latest_state: Optional[str] = None    # JSON, once the ROS side has pushed a state
        self._loop = asyncio.new_event_loop()
        self._runner: Optional[web.AppRunner] = None
        self._started = threading.Event()
        self._error: Optional[BaseException] = None
        self._thread = threading.Thread(target=self._run, name="live-view-http", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    # ---- life ------------------------------------------------------------------------------
    def start(self) -> None:
        """Listen; raises OSError when the address cannot be served."""
        self._thread.start()
        if not self._started.wait(START_TIMEOUT_S):
            raise OSError(f"the web server did not start in {START_TIMEOUT_S:.0f} s")
        if self._error is not None:
            raise OSError(str(self._error))

    def stop(self) -> None:
        if self._loop.is_running():
            asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop)
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as error:  # noqa: BLE001 - reported by start()
            self._error = error
            self._started.set()
            return
        self._started.set()
        self._loop.run_forever()
        self._loop.close()

    async def _serve(self) -> None:
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/api/state", self._state)
        app.router.add_get("/ws", self._websocket)
        app.router.add_static("/static/", STATIC_DIR)
        # this server's own logger for aiohttp's (Logger(): not aiohttp.server's, shared by every server)
        errors = logging.Logger(f"{__name__}.http", logging.WARNING)
        errors.addHandler(_ProtocolErrors(self.on_refused))
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, logger=errors,
                                     keepalive_timeout=self.idle_timeout_s)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.requested_port)
        await site.start()
        self.port = self._runner.addresses[0][1]

    async def _shutdown(self) -> None:
        for page in list(self.pages):
            await page.ws.close()
        if self._runner is not None:
            await self._runner.cleanup()
        self._loop.stop()

    # ---- from the ROS side (any thread) --------------------------------------------------------
    def push_state(self, snapshot: dict) -> None:
        if self._loop.is_running():
            self._loop.call_soon_threadsafe(self._broadcast_state, snapshot)

    def push_frame(self, jpeg: bytes) -> None:
        if self._loop.is_running():
            self._loop.call_soon_threadsafe(self._broadcast_frame, jpeg)

    def _broadcast_state(self, snapshot: dict) -> None:
        self.latest_state = state_json(snapshot)
        for page in self.pages:
            page.state = self.latest_state
            page.wake.set()

    def _broadcast_frame(self, jpeg: bytes) -> None:
        for page in self.pages:
            page.frame = jpeg
            page.wake.set()

    # ---- handlers (the loop's thread) ---------------------------------------------------------
    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC_DIR / "index.html")

    async def _state(self, request: web.Request) -> web.Response:
        """The newest state: asked of the ROS side for this request, not kept up to date for nobody."""
        text = None
        if self.state is not None:
            try:
                snapshot = await asyncio.wait_for(asyncio.wrap_future(self.state()), self.reply_timeout_s)
                text = state_json(snapshot)
            except Exception as error:  # noqa: BLE001 - no answer in time, shutting down: the last state
                self.log(f"GET /api/state: the newest state was not built ({type(error).__name__}: {error}); "
                         f"answered with the last one sent to the pages")
        return web.Response(text=text or self.latest_state or "{}", content_type="application/json")

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.host:
            return web.Response(status=403, text=f"WebSocket from another origin ({origin}) refused\n")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=MAX_MESSAGE_BYTES)
        await ws.prepare(request)
        page = _Page(ws)
        self.pages.add(page)
        self.on_pages(len(self.pages))
        if self.latest_state is not None:
            page.state = self.latest_state
            page.wake.set()
        sender = asyncio.ensure_future(page.send_forever())
        try:
            async for message in ws:
                if message.type == WSMsgType.TEXT:
                    asyncio.ensure_future(self._answer(page, message.data))
                elif message.type == WSMsgType.ERROR:
                    break
        finally:
            self.pages.discard(page)
            sender.cancel()
            self.on_pages(len(self.pages))
        return ws

    async def _answer(self, page: _Page, text: str) -> None:
        request_id = None
        try:
            request = json.loads(text)
            request_id = request.get("id") if isinstance(request, dict) else None
            ok, message = await asyncio.wait_for(asyncio.wrap_future(self.handle(request)), self.reply_timeout_s)
        except TimeoutError:
            ok, message = False, f"no answer within {self.reply_timeout_s:g} s"
        except json.JSONDecodeError as error:  # not JSON: the ROS side counts it
            ok, message = False, str(error)
            self.on_refused("json", f"a page's request is not JSON: {error}")
        except ValueError as error:  # a refused command (CommandError)
            ok, message = False, str(error)
        except Exception as error:  # noqa: BLE001 - the page gets the reason, the server goes on
            ok, message = False, f"{type(error).__name__}: {error}"
        page.replies.append(json.dumps({"type": "reply", "id": request_id, "ok": bool(ok), "message": message}))
        page.wake.set()

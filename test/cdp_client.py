"""A small client for a real browser in tests: Debian's Chromium, headless, driven over the
Chrome DevTools Protocol (a WebSocket on its --remote-debugging-port) with aiohttp, which our
requirements already have. What the live view's browser test needs: open a page, evaluate
JavaScript in it, click, take a screenshot. Every call has a deadline; `close()` always ends the
browser's process group.

`scripts/tools/install_test_browser.sh` installs Chromium (scripts/test.sh calls it).
"""
from __future__ import annotations

import asyncio
import base64
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

import aiohttp

# as root, without a sandbox; the background-networking flags keep it from reaching for the
# internet (this machine has none, and the page must need none)
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--disable-extensions", "--mute-audio", "--window-size=1400,1100"]
START_TIMEOUT_S = 60.0
CALL_TIMEOUT_S = 30.0


def browser_path() -> Optional[str]:
    return shutil.which("chromium") or shutil.which("chromium-browser")


class CdpError(RuntimeError):
    pass


class Browser:
    def __init__(self, log_path: Path):
        executable = browser_path()
        if executable is None:
            raise CdpError("chromium is not installed (scripts/tools/install_test_browser.sh)")
        self.profile = tempfile.mkdtemp(prefix="ball_balance_chromium_")
        self.log = open(log_path, "wb")
        self.process = subprocess.Popen([executable, *FLAGS, f"--user-data-dir={self.profile}",
                                         "--remote-debugging-port=0", "about:blank"],
                                        stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.loop = asyncio.new_event_loop()
        self.session: Optional[aiohttp.ClientSession] = None
        self.ws = None
        self.next_id = 0
        try:
            self._run(self._connect(), START_TIMEOUT_S)
        except BaseException:
            self.close()
            raise

    def _run(self, coroutine, timeout: float):
        return self.loop.run_until_complete(asyncio.wait_for(coroutine, timeout))

    async def _connect(self) -> None:
        port_file = Path(self.profile) / "DevToolsActivePort"
        while not port_file.exists() or not port_file.read_text().strip():
            if self.process.poll() is not None:
                raise CdpError(f"chromium exited with {self.process.returncode}")
            await asyncio.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        self.session = aiohttp.ClientSession()
        while True:
            async with self.session.get(f"http://127.0.0.1:{port}/json/list") as response:
                pages = [t for t in await response.json() if t.get("type") == "page"]
            if pages:
                break
            await asyncio.sleep(0.1)
        self.ws = await self.session.ws_connect(pages[0]["webSocketDebuggerUrl"], max_msg_size=0)

    async def _call(self, method: str, **params) -> dict:
        self.next_id += 1
        call_id = self.next_id
        await self.ws.send_str(json.dumps({"id": call_id, "method": method, "params": params}))
        while True:
            message = await self.ws.receive()
            if message.type != aiohttp.WSMsgType.TEXT:
                raise CdpError(f"DevTools connection closed during {method}")
            data = json.loads(message.data)
            if data.get("id") == call_id:
                if "error" in data:
                    raise CdpError(f"{method}: {data['error']}")
                return data.get("result", {})

    def call(self, method: str, timeout: float = CALL_TIMEOUT_S, **params) -> dict:
        return self._run(self._call(method, **params), timeout)

    def open(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (JSON-serialisable values)."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise CdpError(f"{expression}: {result['exceptionDetails'].get('text')} "
                           f"{result['exceptionDetails'].get('exception', {}).get('description', '')}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float, what: str = "") -> Any:
        """Evaluate until the value is truthy; CdpError with the last value at the deadline."""
        end, value = time.monotonic() + timeout, None
        while time.monotonic() < end:
            try:
                value = self.evaluate(expression)
            except CdpError as error:    # the page is still loading
                value = str(error)
            else:
                if value:
                    return value
            time.sleep(0.2)
        raise CdpError(f"{what or expression}: not true within {timeout:g} s (last: {value!r})")

    def click(self, selector: str) -> None:
        if not self.evaluate(f"(() => {{ const e = document.querySelector({json.dumps(selector)});"
                             " if (!e) return false; e.click(); return true; })()"):
            raise CdpError(f"no element {selector} to click")

    def text(self, selector: str) -> Optional[str]:
        return self.evaluate(f"(() => {{ const e = document.querySelector({json.dumps(selector)});"
                             " return e ? e.textContent : null; })()")

    def screenshot(self, path: Path) -> None:
        path.write_bytes(base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"]))

    def close(self) -> None:
        async def disconnect():
            if self.ws is not None:
                await self.ws.close()
            if self.session is not None:
                await self.session.close()
        try:
            self._run(disconnect(), 5.0)
        except Exception:  # noqa: BLE001 - best effort; the process goes below
            pass
        self.loop.close()
        if self.process.poll() is None:
            try:
                os.killpg(self.process.pid, signal.SIGTERM)
                self.process.wait(timeout=10)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(self.process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.process.wait(timeout=10)
        self.log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

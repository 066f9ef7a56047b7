"""The independent Foxglove WebSocket client (test/integration/foxglove_client/client.js, Node.js)
for the Foxglove node's test and benchmark: its npm packages installed from the folder's
package-lock.json into build/foxglove_client (`npm ci`, once per lock file), and its command."""
from __future__ import annotations

import fcntl
import hashlib
import shutil
import subprocess
from typing import List

from harness import ROOT

CLIENT = ROOT / "test" / "integration" / "foxglove_client"
CLIENT_BUILD = ROOT / "build" / "foxglove_client"


def missing_tools() -> List[str]:
    """The Node.js tools the client needs that are not on PATH."""
    return [tool for tool in ("node", "npm") if shutil.which(tool) is None]


def install() -> str:
    """`npm ci` of the client's lock file into build/foxglove_client; returns its node_modules
    (the client's NODE_PATH). Parallel runs install once (a lock file)."""
    CLIENT_BUILD.mkdir(parents=True, exist_ok=True)
    sources = [CLIENT / "package.json", CLIENT / "package-lock.json"]
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()
    stamp = CLIENT_BUILD / ".installed"
    with open(CLIENT_BUILD / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (stamp.exists() and stamp.read_text() == digest):
            for source in sources:
                shutil.copy(source, CLIENT_BUILD / source.name)
            result = subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--prefix", str(CLIENT_BUILD)],
                                    capture_output=True, text=True, timeout=300)
            if result.returncode != 0:
                raise RuntimeError(f"npm ci in {CLIENT_BUILD} failed:\n{result.stdout}\n{result.stderr}")
            stamp.write_text(digest)
    return str(CLIENT_BUILD / "node_modules")


def command(url: str, *args: str) -> List[str]:
    """The client's command line (run it with NODE_PATH = install()'s folder)."""
    return ["node", str(CLIENT / "client.js"), "--url", url, *args]

"""A headless Chromium for the tests, driven over the DevTools protocol.

Starts Debian's ``chromium`` with a software GL (SwiftShader) and, offline, every host name
unresolvable and every request sent to a dead proxy (loopback stays reachable, for a local
server). Collects what a person would see in the console: uncaught exceptions,
``console.error`` and failed loads. ``CHROMIUM`` is None where it is not installed.
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request

import numpy as np

CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser"))), None)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Browser:
    """One headless Chromium with one page, closed by :meth:`close` (or ``with``)."""

    def __init__(self, width: int = 1100, height: int = 900, offline: bool = True) -> None:
        from websockets.sync.client import connect

        self.profile = tempfile.TemporaryDirectory(ignore_cleanup_errors=True)
        port = free_port()
        args = [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu",
                "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
                f"--remote-debugging-port={port}", f"--window-size={width},{height}",
                f"--user-data-dir={self.profile.name}", "--no-first-run", "about:blank"]
        if offline:
            args += ["--proxy-server=127.0.0.1:9",
                     "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        base = f"http://127.0.0.1:{port}"
        for _ in range(200):
            try:
                with urllib.request.urlopen(f"{base}/json/list", timeout=1) as r:
                    pages = [t for t in json.load(r) if t["type"] == "page"]
                if pages:
                    break
            except OSError:
                pass
            time.sleep(0.1)
        else:
            self.close()
            raise RuntimeError("Chromium did not start")
        self.ws = connect(pages[0]["webSocketDebuggerUrl"], max_size=None,
                          proxy=None)
        self.n = 0
        self.events: list[dict] = []
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")

    def call(self, method: str, **params) -> dict:
        self.n += 1
        self.ws.send(json.dumps({"id": self.n, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=120))
            if msg.get("id") == self.n:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def wait(self, seconds: float) -> None:
        """Let the page run, collecting its events."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                self.events.append(json.loads(self.ws.recv(timeout=left)))
            except TimeoutError:
                return

    def goto(self, url: str, settle: float = 6.0) -> None:
        """Open ``url`` and let it run ``settle`` seconds; a page that cannot be loaded counts
        as an error."""
        res = self.call("Page.navigate", url=url)
        if res.get("errorText"):
            self.events.append({"method": "Log.entryAdded", "params": {"entry": {
                "level": "error", "text": f"{url}: {res['errorText']}"}}})
        self.wait(settle)

    def errors(self) -> list[str]:
        """Uncaught exceptions, console errors and failed loads so far."""
        out = []
        for e in self.events:
            p = e.get("params", {})
            if e.get("method") == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                out.append(d.get("exception", {}).get("description") or d.get("text", ""))
            elif e.get("method") == "Runtime.consoleAPICalled" and p.get("type") == "error":
                out.append(" ".join(str(a.get("value", a.get("description", "")))
                                    for a in p.get("args", [])))
            elif e.get("method") == "Log.entryAdded" and p["entry"]["level"] == "error":
                out.append(p["entry"]["text"])
        return out

    def screenshot(self) -> np.ndarray:
        """The page as grey levels (0-255), rows x columns."""
        import imageio.v3 as iio

        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return iio.imread(io.BytesIO(data))[..., :3].astype(float).mean(-1)

    def save_screenshot(self, path) -> None:
        """The page as a colour PNG at ``path`` (the docs' screenshots)."""
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        with open(path, "wb") as fh:
            fh.write(data)

    def settle(self, ready, timeout: float = 90.0) -> np.ndarray:
        """Screenshots every second until ``ready(screenshot)`` holds (a loaded machine draws
        slowly); returns the last one, which the caller asserts on."""
        end = time.monotonic() + timeout
        shot = self.screenshot()
        while not ready(shot) and time.monotonic() < end:
            self.wait(1.0)
            shot = self.screenshot()
        return shot

    def drag(self, x0: float, y0: float, x1: float, y1: float, steps: int = 12) -> None:
        """Press the left button at (x0, y0), move to (x1, y1), release (CSS pixels)."""
        mouse = "Input.dispatchMouseEvent"
        self.call(mouse, type="mouseMoved", x=x0, y=y0)
        self.call(mouse, type="mousePressed", x=x0, y=y0, button="left", clickCount=1)
        for k in range(1, steps + 1):
            f = k / steps
            self.call(mouse, type="mouseMoved", x=x0 + f * (x1 - x0), y=y0 + f * (y1 - y0),
                      button="left", buttons=1)
        self.call(mouse, type="mouseReleased", x=x1, y=y1, button="left", clickCount=1)

    def close(self) -> None:
        ws = getattr(self, "ws", None)
        if ws is not None:
            ws.close()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.profile.cleanup()

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""Headless Chromium driven over the DevTools protocol on a pipe (no network port, no extra packages).

Used to take screenshots of viewer pages (``proteo view --screenshot``), by the browser tests
and by ``benchmarks/viewer_speed.py``. Chromium is started with ``--remote-debugging-pipe``:
it reads commands from file descriptor 3 and writes replies and events to descriptor 4, each
a JSON message ended by a NUL byte. WebGL runs on SwiftShader (software), so no display or GPU
is needed.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--use-gl=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
    "--disable-extensions",
    "--mute-audio",
    "--hide-scrollbars",
)


class BrowserError(RuntimeError):
    """Chromium is missing, failed to start, or a page did something the caller did not expect."""


def find_chromium() -> str:
    """The path of a Chromium executable (``$PROTEO_CHROMIUM`` first, then ``chromium`` and kin on ``PATH``)."""
    path = os.environ.get("PROTEO_CHROMIUM") or next((p for p in map(shutil.which, CANDIDATES) if p), None)
    if not path:
        raise BrowserError(
            "headless Chromium is needed and none was found (looked for $PROTEO_CHROMIUM, "
            f"{', '.join(CANDIDATES)} on PATH); install it, e.g. on Debian or Ubuntu: "
            "apt-get update && apt-get install -y chromium"
        )
    return path


def _high_fd(fd: int) -> int:
    """A duplicate of ``fd`` numbered 10 or more (so moving it to 3 or 4 in the child clobbers nothing)."""
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high


class Chromium:
    """One headless Chromium with one page; use as a context manager.

    Args:
        width, height: the window size in CSS pixels.
        executable: the browser (default: :func:`find_chromium`).
        timeout: seconds any one command may take.
    """

    def __init__(self, *, width: int = 1280, height: int = 800, executable: str | None = None, timeout: float = 60.0):
        self.timeout = timeout
        self._profile = tempfile.TemporaryDirectory(prefix="proteo-chromium-")
        to_browser_r, to_browser_w = (_high_fd(fd) for fd in os.pipe())
        from_browser_r, from_browser_w = (_high_fd(fd) for fd in os.pipe())

        def wire():  # in the child: the pipe ends chromium expects as descriptors 3 and 4
            os.dup2(to_browser_r, 3)
            os.dup2(from_browser_w, 4)

        command = [
            executable or find_chromium(),
            *FLAGS,
            f"--window-size={width},{height}",
            f"--user-data-dir={self._profile.name}",
            "--remote-debugging-pipe",
            "about:blank",
        ]
        self._log = open(Path(self._profile.name) / "chromium.log", "w+b")
        self.process = subprocess.Popen(
            command, preexec_fn=wire, pass_fds=(3, 4), stdin=subprocess.DEVNULL, stdout=self._log, stderr=self._log
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._out = os.fdopen(to_browser_w, "wb", buffering=0)
        self._in = os.fdopen(from_browser_r, "rb", buffering=0)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict] = []
        self.session = None
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next((t for t in targets if t["type"] == "page"), None)
        if page is None:
            page = {"targetId": self.call("Target.createTarget", url="about:blank")["targetId"]}
        self.session = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")

    # ------------------------------------------------------------------ protocol
    def _read_message(self, deadline: float) -> dict:
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._in], [], [], left)[0]:
                raise BrowserError(f"Chromium did not answer within {self.timeout:g} s")
            chunk = self._in.read(1 << 16)
            if not chunk:
                self.process.wait(timeout=10)
                self._log.seek(0)
                log = self._log.read().decode(errors="replace")[-2000:]
                raise BrowserError(f"Chromium closed the DevTools pipe (exit code {self.process.poll()}): {log}")
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        return json.loads(message)

    def call(self, method: str, **params):
        """Send one DevTools command (to the page once attached) and return its result."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params}
        if self.session is not None and not method.startswith(("Target.", "Browser.")):
            message["sessionId"] = self.session
        self._out.write(json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method} failed: {reply['error'].get('message')}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    # ------------------------------------------------------------------ page
    def open(
        self,
        url_or_path,
        *,
        ready: str = "document.body && document.body.dataset.ready === '1'",
        timeout: float | None = None,
    ) -> None:
        """Load a URL (or a local file) and wait until the JavaScript expression ``ready`` is true or an error shows."""
        url = url_or_path if "://" in str(url_or_path) else Path(url_or_path).resolve().as_uri()
        self.events.clear()
        self.call("Page.navigate", url=url)
        self.wait_for(
            f"({ready}) || (document.body && document.body.dataset.errors > 0) || "
            "(document.readyState === 'complete' && !document.getElementById('proteo-data'))",
            timeout=timeout,
        )

    def wait_for(self, expression: str, *, timeout: float | None = None, interval: float = 0.05) -> None:
        """Poll the page until ``expression`` is truthy (raises :class:`BrowserError` after ``timeout`` s)."""
        deadline = time.monotonic() + (timeout or self.timeout)
        while not self.evaluate(expression):
            if time.monotonic() > deadline:
                raise BrowserError(
                    f"the page did not reach {expression!r} within {timeout or self.timeout:g} s; "
                    f"errors: {self.errors()}"
                )
            time.sleep(interval)

    def evaluate(self, expression: str, *, await_promise: bool = False):
        """The JSON value of a JavaScript expression in the page (raises :class:`BrowserError` if it throws)."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=await_promise)
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            raise BrowserError(
                f"{expression[:80]!r} threw: {details.get('exception', {}).get('description') or details.get('text')}"
            )
        return result["result"].get("value")

    def errors(self) -> list[str]:
        """JavaScript exceptions, console errors and error log entries seen since the page was opened."""
        self.call("Runtime.evaluate", expression="0")  # collect the events that arrived meanwhile
        found = []
        for event in self.events:
            method, params = event.get("method"), event.get("params", {})
            if method == "Runtime.exceptionThrown":
                details = params["exceptionDetails"]
                found.append(details.get("exception", {}).get("description") or details.get("text", "exception"))
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                found.append(" ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
            elif method == "Log.entryAdded" and params["entry"].get("level") == "error":
                found.append(params["entry"].get("text", ""))
        return found

    def click(self, x: float, y: float) -> None:
        """A left click at page coordinates ``(x, y)`` (CSS pixels)."""
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)

    def screenshot(self, path=None) -> bytes:
        """A PNG of the page as it is now (written to ``path`` too when given)."""
        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Path(path).write_bytes(png)
        return png

    def close(self) -> None:
        """Close the browser and remove its profile."""
        if self.process.poll() is None:
            try:
                self.call("Browser.close")
            except BrowserError:
                pass
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        for stream in (self._out, self._in, self._log):
            stream.close()
        self._profile.cleanup()

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

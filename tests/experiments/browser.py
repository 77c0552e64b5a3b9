"""A real headless Chromium (Debian's package), driven over the DevTools protocol on a pipe.

``--remote-debugging-pipe`` makes Chromium read commands from fd 3 and write replies and events to
fd 4, each a JSON message ended by a NUL byte: no port, no websocket library. Every wait is for a
reply or an event, bounded by :data:`TIMEOUT_S` (never a fixed sleep). .ci/run installs Chromium;
on a machine without it the tests using this skip, except under CI (``CI`` set), where they fail.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import queue
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from types import TracebackType
from typing import Any

import pytest

TIMEOUT_S = 60.0
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--remote-debugging-pipe",
)


def chromium() -> str:
    """The Chromium binary; skips the test where there is none (fails under CI)."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is not installed: .ci/run installs it (apt-get install chromium)")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    return found


def _high(fd: int) -> int:
    """A copy of ``fd`` numbered ≥ 10, so placing the pipes at 3 and 4 in the child is safe."""
    return fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10)


class Browser:
    """One headless Chromium with one page; use as a context manager."""

    def __init__(self, width: int = 1280, height: int = 900) -> None:
        self.width, self.height = width, height
        self._profile = tempfile.TemporaryDirectory(prefix="chromium-profile-")
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        child_in, child_out = _high(to_child_r), _high(from_child_w)
        for fd in (to_child_r, from_child_w):
            os.close(fd)

        def place_pipes() -> None:  # in the child, before exec
            os.dup2(child_in, 3)
            os.dup2(child_out, 4)

        self._proc = subprocess.Popen(
            [chromium(), *FLAGS, f"--user-data-dir={self._profile.name}", "about:blank"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            close_fds=False,
            preexec_fn=place_pipes,
        )
        os.close(child_in)
        os.close(child_out)
        self._write = os.fdopen(to_child_w, "wb", buffering=0)
        self._read = os.fdopen(from_child_r, "rb", buffering=0)
        self._next_id = 0
        self._replies: dict[int, queue.Queue[dict[str, Any]]] = {}
        self._events: queue.Queue[dict[str, Any]] = queue.Queue()
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._pump, daemon=True)
        self._reader.start()
        self.errors: list[str] = []
        target = self.send("Target.createTarget", url="about:blank")["targetId"]
        self.session = self.send("Target.attachToTarget", targetId=target, flatten=True)[
            "sessionId"
        ]
        for domain in ("Page", "Runtime", "Log"):
            self.send(f"{domain}.enable", session=True)
        self.send(
            "Emulation.setDeviceMetricsOverride",
            session=True,
            width=width,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )

    def _pump(self) -> None:
        buffer = b""
        while chunk := self._read.read(65536):
            buffer += chunk
            *messages, buffer = buffer.split(b"\0")
            for raw in messages:
                message = json.loads(raw)
                if "id" in message:
                    with self._lock:
                        self._replies.setdefault(message["id"], queue.Queue()).put(message)
                else:
                    self._note(message)
                    self._events.put(message)

    def _note(self, event: dict[str, Any]) -> None:
        """Console errors, uncaught exceptions and error log entries (network failures too)."""
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.exceptionThrown":
            self.errors.append(json.dumps(params["exceptionDetails"])[:500])
        elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            self.errors.append(json.dumps(params.get("args"))[:500])
        elif method == "Log.entryAdded" and params["entry"].get("level") == "error":
            self.errors.append(params["entry"].get("text", "")[:500])

    def send(self, method: str, *, session: bool = False, **params: Any) -> dict[str, Any]:
        with self._lock:
            self._next_id += 1
            ident = self._next_id
            replies = self._replies.setdefault(ident, queue.Queue())
        message: dict[str, Any] = {"id": ident, "method": method, "params": params}
        if session:
            message["sessionId"] = self.session
        self._write.write(json.dumps(message).encode() + b"\0")
        try:
            reply = replies.get(timeout=TIMEOUT_S)
        except queue.Empty:
            raise TimeoutError(f"no reply to {method} in {TIMEOUT_S} s") from None
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        result: dict[str, Any] = reply.get("result", {})
        return result

    def wait_for(self, method: str) -> dict[str, Any]:
        while True:
            try:
                event = self._events.get(timeout=TIMEOUT_S)
            except queue.Empty:
                raise TimeoutError(f"no {method} in {TIMEOUT_S} s") from None
            if event.get("method") == method:
                return event

    def _drain(self) -> None:
        while not self._events.empty():
            self._events.get_nowait()

    def open(self, page: Path) -> None:
        """Load ``page`` and wait for its load event (every inline image decoded by then)."""
        self._drain()
        self.send("Page.navigate", session=True, url=page.resolve().as_uri())
        self.wait_for("Page.loadEventFired")

    def follow(self, selector: str) -> None:
        """Click the link ``selector`` names, as a reader would, and wait for the new page."""
        self._drain()
        self.evaluate(f"document.querySelector({json.dumps(selector)}).click()")
        self.wait_for("Page.loadEventFired")

    def evaluate(self, expression: str) -> Any:
        result = self.send(
            "Runtime.evaluate",
            session=True,
            expression=expression,
            returnByValue=True,
            awaitPromise=True,
        )
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, path: Path) -> Path:
        data = self.send("Page.captureScreenshot", session=True, format="png")["data"]
        path.write_bytes(base64.b64decode(data))
        return path

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except (OSError, RuntimeError, TimeoutError):
            self._proc.kill()
        self._proc.wait(timeout=TIMEOUT_S)
        self._write.close()
        self._reader.join(timeout=TIMEOUT_S)
        self._read.close()
        self._profile.cleanup()

    def __enter__(self) -> Browser:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


#: Every figure on the page drawn: inline SVGs with a size, <img> decoded with pixels.
IMAGES_RENDERED = """(() => {
  const svgs = [...document.querySelectorAll("figure svg")];
  const imgs = [...document.images];
  const bad = svgs.filter(s => { const r = s.getBoundingClientRect();
                                 return r.width < 50 || r.height < 50 || !s.querySelector("path"); })
    .map(s => s.getAttribute("aria-label"))
    .concat(imgs.filter(i => !i.complete || i.naturalWidth === 0).map(i => i.alt));
  return {svgs: svgs.length, imgs: imgs.length, bad: bad};
})()"""


def check_screenshot(path: Path, width: int, height: int) -> None:
    """The screenshot is the viewport's size and shows something (not one flat colour)."""
    import matplotlib.image

    pixels = matplotlib.image.imread(path)
    assert pixels.shape[:2] == (height, width)
    assert float(pixels[..., :3].std()) > 0.05  # text, tables and figures, not a blank page


__all__ = ["IMAGES_RENDERED", "Browser", "check_screenshot", "chromium"]

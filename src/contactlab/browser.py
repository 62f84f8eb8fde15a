"""A headless Chromium page driven over its DevTools protocol on 127.0.0.1: how the viewer's
pictures (docs/figures/viewer.png) and its browser tests see what a user sees.

    with Page("http://127.0.0.1:8080") as page:
        picture = page.screenshot("shot.png")      # (h, w, 3) floats in [0, 1]

WebGL runs in software (SwiftShader), so no display or GPU is needed. Chromium is Debian's
``chromium`` (or ``chromium-browser``, ``google-chrome`` on PATH): :func:`chromium` says which,
None when there is none. The websocket client is the ``websockets`` package viser brings.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from matplotlib.image import imread

if TYPE_CHECKING:
    import numpy as np

FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--no-first-run",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
)
START_SECONDS = 30  # s: Chromium's DevTools server is up within this, or it failed
STOP_SECONDS = 10  # s: Chromium's processes are gone and its profile removed within this


def chromium() -> str | None:
    """The path of a Chromium executable on PATH, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


class Page:
    """Chromium showing ``url`` in a ``width`` × ``height`` [px] window, until :meth:`close`
    (or the end of a ``with`` block). RuntimeError when no Chromium starts. ``requests``: the
    address of every request the page has made (its loads, scripts, websockets), as far as
    the replies read so far tell."""

    def __init__(self, url: str, width: int = 1000, height: int = 700) -> None:
        from websockets.sync.client import connect

        browser = chromium()
        if browser is None:
            raise RuntimeError("no chromium, chromium-browser or google-chrome on PATH (apt-get install chromium)")
        self.profile = tempfile.mkdtemp(prefix="contactlab-chromium-")
        # A session of its own: Chromium's helpers (renderer, GPU, crash handler) join its
        # process group, so closing the page can stop them all, not just the first.
        self.process = subprocess.Popen(
            [browser, *FLAGS, f"--window-size={width},{height}", f"--user-data-dir={self.profile}", "about:blank"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        try:
            self.socket = connect(self._page_socket(), max_size=None)
        except BaseException:
            self._end_process()
            raise
        self.calls, self.requests = 0, []
        self.call("Network.enable")  # every request from here on is seen
        self.call("Page.enable")
        self.call("Page.navigate", url=url)
        self._read_until("Page.loadEventFired")

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """Call DevTools' ``method`` with ``params``; returns its result (dict). Network events
        read on the way are noted in ``requests``."""
        self.calls += 1
        self.socket.send(json.dumps({"id": self.calls, "method": method, "params": params}))
        reply = self._read_until(None)
        if "error" in reply:
            raise RuntimeError(f"DevTools {method}: {reply['error'].get('message')}")
        return reply.get("result", {})

    def _read_until(self, event):
        """Read DevTools messages, noting requests, until ``event`` (a method name) or, for None,
        the reply to the last call; returns that message."""
        while True:
            message = json.loads(self.socket.recv(timeout=30))
            if message.get("method") in ("Network.requestWillBeSent", "Network.webSocketCreated"):
                self.requests.append(message["params"].get("request", message["params"]).get("url", ""))
            if (event is None and message.get("id") == self.calls) or (event and message.get("method") == event):
                return message

    def _page_socket(self):
        """The DevTools websocket address of the page, once Chromium has written its port."""
        port_file = os.path.join(self.profile, "DevToolsActivePort")
        deadline = time.monotonic() + START_SECONDS
        while True:
            if time.monotonic() > deadline or self.process.poll() is not None:
                raise RuntimeError("Chromium did not start its DevTools server")
            if os.path.isfile(port_file) and open(port_file).read().count("\n") >= 1:
                port = int(open(port_file).read().split()[0])
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as listing:
                    pages = [target for target in json.load(listing) if target["type"] == "page"]
                if pages:
                    return pages[0]["webSocketDebuggerUrl"]
            time.sleep(0.1)

    def click(self, text: str) -> bool:
        """Click the page's button that reads ``text``; returns whether there was one."""
        found = self.call(
            "Runtime.evaluate",
            expression=(
                f"(() => {{ const b = [...document.querySelectorAll('button')].find(b => b.textContent.trim() === "
                f"{json.dumps(text)}); if (b) b.click(); return !!b; }})()"
            ),
            returnByValue=True,
        )
        return bool(found.get("result", {}).get("value"))

    def screenshot(self, path: str) -> np.ndarray:
        """Write the page as a PNG to ``path``; returns the picture (h, w, 3) in [0, 1]."""
        data = self.call("Page.captureScreenshot", format="png")["data"]
        with open(path, "wb") as stream:
            stream.write(base64.b64decode(data))
        return imread(path)[..., :3]

    def wait_for(
        self, path: str, ready: Callable[[np.ndarray], bool], seconds: float = 40.0, what: str = "the page"
    ) -> np.ndarray:
        """Screenshots to ``path`` every half second until ``ready(picture)``; returns that
        picture, or raises TimeoutError after ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            picture = self.screenshot(path)
            if ready(picture):
                return picture
            if time.monotonic() > deadline:
                raise TimeoutError(f"{what} did not come within {seconds:g} s")
            time.sleep(0.5)

    def _end_process(self):
        """Stop Chromium and its helpers, then remove the profile folder. A helper that outlives
        the main process can still be writing into the profile (CI once saw ``Directory not empty:
        'Default'``), so the whole process group is killed and the removal retried until it holds."""
        group = self.process.pid  # the session leader's pid is its group's id
        self._signal(group, signal.SIGTERM)
        try:
            self.process.wait(timeout=STOP_SECONDS)
        except subprocess.TimeoutExpired:
            self._signal(group, signal.SIGKILL)
            self.process.wait(timeout=STOP_SECONDS)
        deadline = time.monotonic() + STOP_SECONDS
        while self._signal(group, signal.SIGKILL) and time.monotonic() < deadline:
            time.sleep(0.05)  # a helper still running, or killed and not yet reaped
        while True:
            try:
                shutil.rmtree(self.profile)
                return
            except FileNotFoundError:
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    @staticmethod
    def _signal(group, number):
        """Send signal ``number`` to process group ``group``; returns whether any process of the
        group was there to receive it."""
        try:
            os.killpg(group, number)
        except ProcessLookupError:
            return False
        return True

    def close(self) -> None:
        self.socket.close()
        self._end_process()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def scene_part(picture: np.ndarray, share: float = 0.62) -> np.ndarray:
    """The 3-D view's pixels of a viewer page, left of viser's control panel (its right 35 %)."""
    return picture[:, : int(share * picture.shape[1])]


def coloured(picture: np.ndarray) -> float:
    """Share of the pixels of ``picture`` that are clearly coloured (the page is white and grey)."""
    return float(((picture.max(axis=-1) - picture.min(axis=-1)) > 0.25).mean())

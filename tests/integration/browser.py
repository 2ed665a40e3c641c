"""Headless Chromium driven over the Chrome DevTools Protocol (CDP), for tests of the
dashboard in a real browser: load a page, evaluate JavaScript, take screenshots.

Chromium listens for DevTools on a port it picks itself (``--remote-debugging-port=0``)
and writes it into ``DevToolsActivePort`` of its private profile folder, so two tests
never race for a port. Every wait has a deadline.
"""

from __future__ import annotations

import base64
import contextlib
import itertools
import json
import os
import shutil
import signal
import subprocess
import time
import urllib.request
from pathlib import Path

from websockets.sync.client import connect

BROWSERS = ("chromium", "chromium-browser")
START_TIMEOUT_S = 30.0
COMMAND_TIMEOUT_S = 30.0
WINDOW = (1280, 900)


def find_chromium() -> str | None:
    return next(filter(None, map(shutil.which, BROWSERS)), None)


class Browser:
    """One headless Chromium with a private profile under ``folder``; a context manager
    that kills it (and its helpers: it leads a process group of its own) on exit."""

    def __init__(self, folder: Path, executable: str):
        self.folder = folder
        profile = folder / "profile"
        profile.mkdir(parents=True, exist_ok=True)
        self.log = open(folder / "chromium.log", "w")
        self.proc = subprocess.Popen(
            [
                executable,
                "--headless",
                "--no-sandbox",  # --no-sandbox: tests may run as root
                "--disable-gpu",
                "--no-first-run",
                "--no-default-browser-check",
                "--disable-extensions",
                "--disable-background-networking",
                "--mute-audio",
                f"--user-data-dir={profile}",
                "--remote-debugging-address=127.0.0.1",
                "--remote-debugging-port=0",
                f"--window-size={WINDOW[0]},{WINDOW[1]}",
                "about:blank",
            ],
            stdin=subprocess.DEVNULL,
            stdout=self.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self._ids = itertools.count(1)
        self._socket = contextlib.ExitStack()
        try:
            self._ws = self._socket.enter_context(
                connect(self._page_socket(profile / "DevToolsActivePort"), open_timeout=START_TIMEOUT_S, max_size=None)
            )
        except BaseException:
            self.close()
            raise

    def _page_socket(self, port_file: Path) -> str:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"chromium exited with {self.proc.returncode}; see {self.log.name}")
            text = port_file.read_text() if port_file.exists() else ""
            if "\n" in text:  # the port, a newline, the browser's path
                port = int(text.split("\n")[0])
                try:
                    with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as answer:
                        pages = [t for t in json.load(answer) if t["type"] == "page"]
                    if pages:
                        return pages[0]["webSocketDebuggerUrl"]
                except OSError:
                    pass  # not listening yet
            if time.monotonic() > deadline:
                raise RuntimeError(f"chromium gave no DevTools page within {START_TIMEOUT_S} s")
            time.sleep(0.1)

    def send(self, method: str, timeout: float = COMMAND_TIMEOUT_S, **params) -> dict:
        """One CDP command; its result (events that arrive meanwhile are passed over)."""
        number = next(self._ids)
        self._ws.send(json.dumps({"id": number, "method": method, "params": params}))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no answer to {method} within {timeout} s")
            message = json.loads(self._ws.recv(timeout=left))
            if message.get("id") == number:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message["result"]

    def open(self, url: str) -> None:
        self.send("Page.enable")
        self.send("Page.navigate", url=url)

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (JSON-able values)."""
        result = self.send("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression!r} threw: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, clip: dict | None = None) -> bytes:
        """A PNG of the page, or of ``clip`` ({x, y, width, height} in CSS px)."""
        params = {"format": "png"}
        if clip:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.send("Page.captureScreenshot", **params)["data"])

    def close(self) -> None:
        self._socket.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(10)
        self.log.close()

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

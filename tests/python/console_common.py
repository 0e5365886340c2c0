"""Shared helpers of the console's browser tests: start `handeye` with the console on a free
loopback port, read its URL, and drive headless Chromium (the Debian package, through
Playwright; no browser download)."""

import os
import queue
import re
import subprocess
import threading

from playwright.sync_api import sync_playwright  # noqa: F401  (re-exported for the tests)

CHROMIUM = os.environ.get("HANDEYE_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


class Handeye:
    """A running `handeye` process whose output is collected line by line."""

    def __init__(self, args, cwd):
        self.proc = subprocess.Popen(
            [os.environ["HANDEYE_BIN"], *args],
            cwd=cwd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines = []
        self._queue = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line)
            self._queue.put(line)
        self._queue.put(None)

    def url(self, timeout=120):
        """The console URL the process prints."""
        while True:
            line = self._queue.get(timeout=timeout)
            if line is None:
                raise AssertionError("handeye ended before printing the console URL:\n" + self.output())
            m = re.search(r"console: (http://\S+)", line)
            if m:
                return m.group(1)

    def wait(self, timeout=180):
        """The exit code, once the process has ended and everything it printed is read (the
        reader may still be behind when the process exits)."""
        code = self.proc.wait(timeout=timeout)
        self._reader.join(timeout=30)
        return code

    def enter(self):
        """Presses Enter on its stdin (ends a `--wait` / `--wait` linger)."""
        try:
            self.proc.stdin.write("\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass

    def output(self):
        return "".join(self.lines)

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()


def launch(playwright):
    return playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)


def js_count(selector):
    return f"document.querySelectorAll({selector!r}).length"

"""Other programs beside a benchmark's session: the project's test suite (what ``make test``
runs), and a trainee's browser on the view's page (a headless chromium).

    from _beside import TestSuite, browser_when_up   # bench/ is sys.path[0]
    suite = TestSuite(); suite.ensure()      # running until suite.stop(), restarted when it ends
    stop = threading.Event()
    t = browser_when_up(8080, stop)          # chromium on the page once it answers, until stop
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

__all__ = ['TestSuite', 'browser_when_up']

ROOT = Path(__file__).resolve().parents[1]


class TestSuite:
    """The project's test suite running beside the runs (``--beside-tests``): restarted when it
    ends, so every run has it beside it; its output is discarded."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.starts = 0

    def ensure(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, '-m', 'pytest', 'test', '-q', '-p', 'no:cacheprovider'],
                cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                env=dict(os.environ, PYTHONPATH=str(ROOT)), start_new_session=True)
            self.starts += 1

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


def browser_when_up(port: int, stop) -> threading.Thread:
    """A thread that waits until the page on ``port`` answers, then keeps a headless chromium
    on it (bench_view's, niced: it stands for the trainee's browser) until ``stop`` is set."""
    from bench_view import close_browser, open_browser

    def run() -> None:
        while not stop.is_set():
            # an HTTP request, as the browser's: a bare connect that closes unanswered leaves a
            # websocket handshake traceback in the view's log
            try:
                with urllib.request.urlopen(f'http://127.0.0.1:{port}/', timeout=2.0):
                    break
            except OSError:
                pass
            time.sleep(0.5)
        else:
            return
        t.started = time.monotonic()
        b = open_browser(f'http://127.0.0.1:{port}/')
        stop.wait()
        close_browser(b)

    t = threading.Thread(target=run, daemon=True)
    t.started = None   # when chromium was started (time.monotonic(): the trace's clock)
    t.start()
    return t


"""Headless chromium for the view's tests, benchmark and screenshots: a screenshot of a page
(no ROS).

Debian's ``chromium`` renders viser's WebGL page headless with software rendering (SwiftShader);
without the ``--use-angle=swiftshader --enable-unsafe-swiftshader`` flags it says "WebGL
unavailable". A screenshot is taken over the DevTools protocol from a chromium that keeps the page
open, in real time, once the page connected and is ready: chromium's own ``--screenshot`` runs the
page on a virtual clock (``--virtual-time-budget``) that, on a loaded machine, can run out before
the page's websocket has connected, whatever the budget.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

__all__ = ['CHROMIUM_FLAGS', 'Page', 'chromium', 'close_chromium', 'free_port', 'open_chromium',
           'screenshot']

CHROMIUM_FLAGS = ('--headless=new', '--no-sandbox', '--use-angle=swiftshader',
                  '--enable-unsafe-swiftshader', '--disable-gpu-sandbox',
                  '--disable-background-networking', '--disable-component-update',
                  '--disable-sync', '--no-first-run', '--hide-scrollbars')


def chromium() -> str | None:
    """Path of the chromium executable (``$CHROMIUM`` or on PATH), or None."""
    env = os.environ.get('CHROMIUM')
    if env:
        return env if Path(env).is_file() else None
    for name in ('chromium', 'chromium-browser', 'google-chrome'):
        p = shutil.which(name)
        if p:
            return p
    return None


def free_port(host: str = '127.0.0.1') -> int:
    """A TCP port free on ``host`` now (the OS's choice)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def open_chromium(url: str, size: tuple[int, int] = (1280, 800),
                  nice: int = 0) -> subprocess.Popen:
    """A headless chromium keeping ``url`` open, in a session of its own (close it with
    :func:`close_chromium`: its zygote, GPU and renderer processes outlive a killed browser
    process), with the DevTools protocol on a port of its choosing (written to
    ``<profile>/DevToolsActivePort``), niced by ``nice``. Timers run in the background page as
    in a shown one.

    Raises:
        FileNotFoundError: no chromium.
    """
    exe = chromium()
    if exe is None:
        raise FileNotFoundError('chromium: not installed (apt-get install chromium)')
    profile = tempfile.mkdtemp(prefix='haptic-anfis-chromium-')
    cmd = [exe, *CHROMIUM_FLAGS, f'--user-data-dir={profile}',
           f'--window-size={size[0]},{size[1]}', '--remote-debugging-port=0',
           '--disable-renderer-backgrounding', '--disable-background-timer-throttling',
           '--disable-backgrounding-occluded-windows', url]
    if nice:
        cmd = ['nice', '-n', str(int(nice)), *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    proc.profile = profile
    return proc


def close_chromium(proc: subprocess.Popen) -> None:
    """Kill a chromium of :func:`open_chromium` with every process it started."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()
    shutil.rmtree(proc.profile, ignore_errors=True)


class Page:
    """The page a chromium of :func:`open_chromium` holds, over the DevTools protocol (its
    websocket, through the ``websockets`` package that viser brings).

    Raises:
        TimeoutError: chromium did not open its DevTools port, or did not answer a command,
            within ``timeout`` s (a hung chromium).
    """

    def __init__(self, proc: subprocess.Popen, size: tuple[int, int], timeout: float) -> None:
        from websockets.sync.client import connect
        self.timeout = float(timeout)
        end = time.monotonic() + self.timeout
        port_file = Path(proc.profile) / 'DevToolsActivePort'
        ws_url = None
        while ws_url is None:
            if proc.poll() is not None:
                raise RuntimeError(f'chromium exited ({proc.returncode}) before opening the page')
            if time.monotonic() > end:
                raise TimeoutError(f'chromium opened no DevTools port in {timeout:g} s')
            try:
                port = int(port_file.read_text().split()[0])
                with urllib.request.urlopen(f'http://127.0.0.1:{port}/json/list',
                                            timeout=5) as r:
                    pages = [t for t in json.load(r) if t.get('type') == 'page']
                ws_url = pages[0]['webSocketDebuggerUrl'] if pages else None
            except (OSError, ValueError, IndexError):
                pass
            if ws_url is None:
                time.sleep(0.1)
        self._ws = connect(ws_url, max_size=None, open_timeout=self.timeout)
        self._id = 0
        self.call('Emulation.setDeviceMetricsOverride',
                  width=int(size[0]), height=int(size[1]), deviceScaleFactor=1, mobile=False)

    def call(self, method: str, **params) -> dict:
        """Send one DevTools command; its result (events in between are dropped)."""
        self._id += 1
        self._ws.send(json.dumps({'id': self._id, 'method': method, 'params': params}))
        end = time.monotonic() + self.timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f'chromium did not answer {method} in {self.timeout:g} s')
            msg = json.loads(self._ws.recv(timeout=left))
            if msg.get('id') == self._id:
                if 'error' in msg:
                    raise RuntimeError(f'chromium: {method}: {msg["error"]}')
                return msg.get('result', {})

    def capture(self, out: Path) -> Path:
        """Write a PNG of the page's viewport to ``out``."""
        data = self.call('Page.captureScreenshot', format='png')['data']
        out.write_bytes(base64.b64decode(data))
        return out

    def close(self) -> None:
        self._ws.close()


def _capture_when_ready(url, out: Path, size, timeout: float, settle: float, app, ready,
                        before: int) -> bool:
    """One chromium: capture until the page connected (``app``) and is ``ready``, twice
    ``settle`` s apart (a scene still arriving is not captured half-drawn); False at
    ``timeout``."""
    proc = open_chromium(url, size)
    page = None
    try:
        page = Page(proc, size, timeout)
        end = time.monotonic() + timeout
        t_load = time.monotonic()
        seen = False
        while time.monotonic() < end:
            time.sleep(0.25)
            if time.monotonic() - t_load < settle:
                continue
            if app is not None and app.n_connects <= before:   # not connected yet
                continue
            png = page.capture(out)   # without a ``ready`` too: the file is the result
            ok = ready is None or ready(png)
            if ok and seen:
                return True
            if ok:
                seen = True
                time.sleep(settle)
        return False
    finally:
        if page is not None:
            page.close()
        close_chromium(proc)


def screenshot(url: str, out: str | os.PathLike, size: tuple[int, int] = (1280, 800),
               timeout: float = 90.0, app=None, tries: int = 2, ready=None,
               settle: float = 1.0) -> Path:
    """Load ``url`` in a headless chromium and write a PNG of it to ``out`` once it is ready:
    with ``app`` (the :class:`~haptic_anfis.view.app.ViewApp` serving ``url``) once a page
    connected to it, with ``ready(png_path) -> bool`` (e.g. "the breast is drawn") once that holds
    on two captures ``settle`` s apart; with neither, ``settle`` s after the page opened. A
    chromium that does not answer, or a page not ready after ``timeout`` s, is closed and another
    one tried, ``tries`` in all.

    Raises:
        FileNotFoundError: no chromium; RuntimeError: no capture was ready in ``tries``.
    """
    out = Path(out).resolve()
    hung = 0
    for _ in range(max(int(tries), 1)):
        out.unlink(missing_ok=True)
        before = None if app is None else app.n_connects
        try:
            if _capture_when_ready(url, out, size, timeout, settle, app, ready, before):
                return out
        except TimeoutError:
            hung += 1
    raise RuntimeError(f'the page at {url} did not connect, or was not ready, in {tries} '
                       f'chromiums of {timeout:g} s ({hung} of them hung and were killed)')

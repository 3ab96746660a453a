"""Headless chromium for the view's tests, benchmark and screenshots: a screenshot of a page
(no ROS).

Debian's ``chromium`` renders viser's WebGL page headless with software rendering (SwiftShader);
without the ``--use-angle=swiftshader --enable-unsafe-swiftshader`` flags it says "WebGL
unavailable". ``--virtual-time-budget`` lets the page run that long (ms) before the capture.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

__all__ = ['CHROMIUM_FLAGS', 'chromium', 'free_port', 'screenshot']

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
    import socket
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _run(url: str, extra: list[str], budget_ms: int, size: tuple[int, int],
         timeout: float) -> subprocess.CompletedProcess:
    exe = chromium()
    if exe is None:
        raise FileNotFoundError('chromium: not installed (apt-get install chromium)')
    with tempfile.TemporaryDirectory(prefix='haptic-anfis-chromium-') as profile:
        return subprocess.run(
            [exe, *CHROMIUM_FLAGS, f'--user-data-dir={profile}',
             f'--window-size={size[0]},{size[1]}', f'--virtual-time-budget={int(budget_ms)}',
             *extra, url], capture_output=True, text=True, timeout=timeout)


def screenshot(url: str, out: str | os.PathLike, budget_ms: int = 5000,
               size: tuple[int, int] = (1280, 800), timeout: float = 90.0, app=None,
               tries: int = 4, ready=None) -> Path:
    """Load ``url`` and write a PNG of it to ``out``. With ``app`` (the
    :class:`~haptic_anfis.view.app.ViewApp` serving ``url``) the capture is repeated, up to
    ``tries`` times, until the page connected to it during the capture: chromium's virtual time
    runs ahead of a websocket connecting on a loaded machine, and the page then shows only its
    empty shell ("Inactive"); ``ready(png_path) -> bool`` (e.g. "the breast is drawn") also
    repeats a capture taken before the scene arrived. Each retry doubles the budget. Meant for
    a page whose scene stands still while it is captured (a page streaming frames keeps
    chromium's virtual time from running out). A chromium still running after ``timeout`` s
    (one hung now and then) is killed and counts as one of the tries.

    Raises:
        FileNotFoundError: no chromium; RuntimeError: it wrote no picture (its stderr's end), or
        the page never connected.
    """
    out = Path(out).resolve()
    hung = 0
    for _ in range(max(int(tries), 1)):
        out.unlink(missing_ok=True)
        before = None if app is None else app.n_connects
        try:
            r = _run(url, [f'--screenshot={out}'], budget_ms, size, timeout)
        except subprocess.TimeoutExpired:
            # now and then a headless chromium hangs (seen once in CI, in a capture that takes
            # seconds): subprocess.run killed it; another one is tried
            hung += 1
            continue
        if not out.is_file():
            raise RuntimeError(f'chromium wrote no screenshot of {url}: {r.stderr[-500:]}')
        if (app is None or app.n_connects > before) and (ready is None or ready(out)):
            return out
        budget_ms *= 2
    raise RuntimeError(f'the page at {url} did not connect, or was not ready, in {tries} '
                       f'captures ({hung} of them chromium hung past {timeout:g} s and was '
                       'killed)')

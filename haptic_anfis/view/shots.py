"""``make screenshots``: the live page and the debrief of an exam, as PNGs for the docs.

Runs ``haptic-anfis exam run --trainee systematic --duration S --view`` (the simulated trainee
palpates, the web_view node shows it live), captures the live page mid-exam, then the debrief the
same URL turns into when the exam ends. Needs chromium (``apt-get install chromium``).

    python -m haptic_anfis.view.shots [--out docs] [--port 8093] [--duration 30]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from .browser import chromium, screenshot

__all__ = ['main']


def _wait_for(proc, log: Path, text: str, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if text in log.read_text(errors='replace'):
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.5)
    return False


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--out', default='docs', help='directory for view_live.png, view_debrief.png')
    ap.add_argument('--port', type=int, default=8093)
    ap.add_argument('--duration', type=float, default=30.0, help='exam length [s]')
    a = ap.parse_args(argv)
    if chromium() is None:
        print('screenshots: chromium is not installed (apt-get install chromium)', file=sys.stderr)
        return 1
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / '.view_shots.log'
    cmd = [sys.executable, '-m', 'haptic_anfis.cli', 'exam', 'run', '--trainee', 'systematic',
           '--duration', str(a.duration), '--view', '--view-port', str(a.port),
           '--view-hold', '120']
    url = f'http://127.0.0.1:{a.port}/'
    with open(log, 'w') as f:
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=os.environ.copy())
    try:
        if not _wait_for(proc, log, 'view: open', 400):
            print(f'screenshots: the exam did not open its page (see {log})', file=sys.stderr)
            return 1
        time.sleep(0.4 * a.duration)   # mid-exam: probe on the skin, coverage painted
        print('live     ', screenshot(url, out / 'view_live.png', budget_ms=4000, timeout=300),
              flush=True)
        if not _wait_for(proc, log, 'debrief at', a.duration + 200):
            print(f'screenshots: no debrief (see {log})', file=sys.stderr)
            return 1
        time.sleep(2.0)
        print('debrief  ', screenshot(url, out / 'view_debrief.png', budget_ms=6000, timeout=300),
              flush=True)
    finally:
        if proc.poll() is None:
            proc.send_signal(2)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
    log.unlink(missing_ok=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

"""``make screenshots``: the live page and the debrief of an exam, as PNGs for the docs.

Records ``haptic-anfis exam run --trainee systematic --duration S`` (the simulated trainee
palpates the default case), then serves two pages from that bag and captures them with headless
chromium: the live page as it was halfway through the exam (the probe, its dent, force and gauge
at that moment, the coverage painted so far — drawn by the same calls the web_view node makes
each frame, held still for the capture, so that two captures a second apart agree), and the
debrief (``haptic-anfis view BAG``). Then records the same trainee on the nodular case
:data:`NODULAR_CASE` and captures its debrief, which draws the normal background (lobules, ribs).
Needs chromium.

    python -m haptic_anfis.view.shots [--out docs] [--duration 30]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..cases.force_mapping import tissue_clamp
from .app import ViewApp, coverage_fractions
from .browser import chromium, free_port, screenshot
from .build import bag_debrief, case_view, open_bag_view

__all__ = ['NODULAR_CASE', 'live_at', 'main']

#: A graded nodular case without a lesion: its debrief shows the normal lobules and ribs.
NODULAR_CASE = 'nod_s_fatty_free'


def _drawn(png) -> bool:
    from PIL import Image
    a = np.asarray(Image.open(png).convert('RGB')).astype(int)[100:700, 150:900]
    return ((a < 225).any(axis=2)).mean() > 0.2


def live_at(app, debrief, t: float) -> None:
    """Draw on ``app`` the live page of ``debrief``'s session at ``t`` [s]: the newest contact,
    pose and force command by then, the coverage so far, the clock."""
    s = debrief.session
    t_abs = debrief.t0 + t
    c = debrief.contacts
    c = c[c[:, 0] <= t_abs]
    contact = None
    if len(c) and c[-1, 5] > 0.5:
        contact = (c[-1, 1:4], np.array([-1.0, 0.0, 0.0]), float(c[-1, 4]))
    p = np.array(s.poses, float).reshape(-1, 4)
    p = p[p[:, 0] <= t_abs]
    f = np.array(s.forces, float).reshape(-1, 4)
    f = f[f[:, 0] <= t_abs]
    lv = debrief.face_levels(t)
    app.set_coverage(lv, coverage_fractions(s.grid, lv))
    app.show_live(p[-1, 1:4] if len(p) else None, contact, f[-1, 1:4] if len(f) else None, t)


def _record(bag: Path, duration: float, case: str | None) -> str | None:
    """Record the systematic trainee's exam of ``case`` (None = the default) for ``duration``
    [s] into ``bag``; the failure's last lines, or None."""
    cmd = [sys.executable, '-m', 'haptic_anfis.cli', 'exam', 'run', '--trainee', 'systematic',
           '--duration', str(duration), '--record', str(bag)]
    if case is not None:
        cmd += ['--case', case]
    r = subprocess.run(cmd, capture_output=True, text=True)
    return None if r.returncode == 0 else r.stderr.strip()[-500:]


def _shoot_debrief(bag: Path, png: Path) -> None:
    """Capture the debrief page of ``bag`` into ``png``."""
    app = open_bag_view(bag, port=free_port())
    try:
        print(f'{png.stem:<20}', screenshot(app.url, png, app=app, ready=_drawn, timeout=300),
              flush=True)
    finally:
        app.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--out', default='docs',
                    help='directory for view_live.png, view_debrief.png, view_debrief_nodular.png')
    ap.add_argument('--duration', type=float, default=30.0, help='exam length [s]')
    a = ap.parse_args(argv)
    if chromium() is None:
        print('screenshots: chromium is not installed (apt-get install chromium)', file=sys.stderr)
        return 1
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix='haptic-anfis-shots-') as tmp:
        bag = Path(tmp) / 'exam'
        err = _record(bag, a.duration, None)
        if err is not None:
            print(f'screenshots: the exam failed: {err}', file=sys.stderr)
            return 1
        d = bag_debrief(bag)
        cv = case_view(None)
        app = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds,
                      port=free_port(), deformation=cv.deformation, max_force=tissue_clamp(None))
        try:
            app.set_exam_running(True)
            # the first moment past the middle with the probe pressing (the dent shows)
            c = d.contacts
            rel = c[:, 0] - d.t0
            pressing = np.flatnonzero((rel >= 0.5 * d.duration) & (c[:, 5] > 0.5)
                                      & (c[:, 4] > cv.config.medium))
            t = float(rel[pressing[0]]) if len(pressing) else 0.5 * d.duration
            live_at(app, d, t)
            print(f'{"view_live":<20}', screenshot(app.url, out / 'view_live.png', app=app,
                                                   ready=_drawn, timeout=300), flush=True)
        finally:
            app.close()
        _shoot_debrief(bag, out / 'view_debrief.png')
        nodular = Path(tmp) / 'exam_nodular'
        err = _record(nodular, a.duration, NODULAR_CASE)
        if err is not None:
            print(f'screenshots: the exam of {NODULAR_CASE} failed: {err}', file=sys.stderr)
            return 1
        _shoot_debrief(nodular, out / 'view_debrief_nodular.png')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

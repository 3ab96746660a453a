"""Examination mode timings (printed, never asserted): the simulated trainees' full exams through
the one-process graph, and the examiner's per-update cost.

1. ``haptic-anfis exam run --trainee systematic|careless --json`` in a child process: wall time
   (start-up included), the session's duration, deep coverage, hits / misses / false marks, score.
2. The examiner's core, ROS-free: folding 200 ms of 1 kHz contact samples into the coverage grid
   (what one 5 Hz heat-map tick does) and the end-of-session report, on the shipped mesh.

Run: ``.venv/bin/python bench/bench_exam.py [--quick]`` (``--quick`` skips the full exams);
``--cases [NAME ...]``: the systematic trainee on every ready case of the library (or those named)
and the careless one on the default case, one exam after the other, ending with the README's
per-case Markdown table.
The machine's load is printed with every figure: on a shared 2-core machine it dominates.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]


def load() -> str:
    return Path('/proc/loadavg').read_text().split()[0] if Path('/proc/loadavg').exists() else '?'


def full_exam(trainee: str, case: str | None = None) -> dict | None:
    """One ``exam run`` in a child process; prints a line and returns the report (+ ``wall_s``,
    ``load``), or None when it failed."""
    cmd = [sys.executable, '-m', 'haptic_anfis.cli', 'exam', 'run', '--trainee', trainee, '--json']
    if case:
        cmd += ['--case', case]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=dict(os.environ),
                       timeout=900)
    wall = time.perf_counter() - t0
    name = f'{trainee}@{case or "default"}'
    if p.returncode != 0:
        print(f'{name:32s} FAILED ({p.returncode}): {p.stderr.strip()[-300:]}', flush=True)
        return None
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r['wall_s'], r['load'] = wall, load()
    c = r['coverage_pct']
    print(f"{name:32s} wall {wall:6.1f} s (session {r['duration_s']:.1f} s, in contact "
          f"{r['contact_s']:.1f} s) | coverage light/medium/deep {c['light']:.0f}/{c['medium']:.0f}/"
          f"{c['deep']:.0f} % | hits {r['hits']} misses {r['misses']} false {r['false_marks']} | "
          f"score {r['score']:.1f} {r['verdict']} | {r['pattern']} | felt "
          f"{r['trainee'].get('felt_samples')} | load {r['load']}", flush=True)
    return r


def markdown_row(case: str, trainee: str, r: dict) -> str:
    """One README table row: what the trainee found, from the forces alone, and why it missed."""
    det = '; '.join(f"({d['y_mm']:.0f}, {d['z_mm']:.0f}) mm +{d['excess_pct']:.0f} % "
                    f"({d['sigma']:.1f} σ)" for d in r['trainee']['detections']) or 'none'
    why = '; '.join(f"{les['name']}: {les['missed']}" for les in r['lesions']
                    if not les['found']) or '–'
    return (f"| {case} | {trainee} | {len(r['lesions'])} | {r['hits']} | {r['misses']} | "
            f"{r['false_marks']} | {r['coverage_pct']['deep']:.1f} | {r['score']:.1f} "
            f"({r['verdict']}) | {r['pattern']} | {r['wall_s']:.0f} ({r['duration_s']:.0f}) | "
            f"{r['load']} | {det} | {why} |")


def all_cases(names: list[str]) -> None:
    """The systematic trainee on every given (default: every ready) case, the careless one on the
    default case; a Markdown table at the end."""
    from haptic_anfis.cases import library
    names = names or [c.name for c in library().ready()]
    rows = []
    for name in names:
        r = full_exam('systematic', name)
        if r is not None:
            rows.append(markdown_row(name, 'systematic', r))
    r = full_exam('careless', 'default')
    if r is not None:
        rows.append(markdown_row('default', 'careless', r))
    print('\n| case | trainee | lesions | hits | misses | false marks | deep coverage % | score | '
          'pattern | wall s (session s) | load | marked where the forces said (excess) | missed |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    print('\n'.join(rows))


def margins(seed: int = 0) -> None:
    """How far each ready case's lesions stand out in its MODEL's forces, as the trainee's
    detector sees them without dynamics: the top 3 bumps (no threshold) of ``detect_lumps`` on
    ``ForceModel.predict`` along the trainee's strips fitted to the case (depth uniform 8-12 mm,
    0.5 mm lateral jitter, seeded)."""
    from haptic_anfis.anfis import ForceModel
    from haptic_anfis.cases import library
    from haptic_anfis.exam.detector import detect_lumps
    rng = np.random.default_rng(seed)
    for c in library().ready():
        sc = c.scene
        rx, ry, rz = sc.radii
        k = sc.palpable_radius / 0.042
        yz = []
        for y in np.arange(-0.040, 0.0401, 0.008) * k:
            h = np.sqrt(max((0.044 * k) ** 2 - y * y, 0))
            yz += [(y + rng.normal(0, 0.0005), z) for z in np.arange(-h, h, 0.001)]
        yz = np.array(yz)
        x = rx * np.sqrt(np.clip(1 - (yz[:, 0] / ry) ** 2 - (yz[:, 1] / rz) ** 2, 0, None))
        d = rng.uniform(0.008, 0.012, len(yz))
        P = np.c_[x, yz]
        F = np.linalg.norm(ForceModel.load(c.model_path).predict(np.c_[P, d]), axis=1)
        les = ', '.join(f'({t.centre[1] * 1e3:.0f}, {t.centre[2] * 1e3:.0f}) mm '
                        f'r {t.radius * 1e3:.1f}' for t in sc.tumours) or 'none'
        top = detect_lumps(P, d, F, min_rel=0.0, k_sigma=0.0)
        bumps = '; '.join(f'({b.y * 1e3:.1f}, {b.z * 1e3:.1f}) mm +{100 * b.excess:.1f} % '
                          f'{b.sigma:.1f} σ' for b in top)
        print(f'{c.name:24s} lesions {les} | bumps {bumps}', flush=True)


def core_costs() -> None:
    from haptic_anfis.contact import load_mesh
    from haptic_anfis.exam.config import ExamConfig
    from haptic_anfis.exam.lesions import subject_from_scene
    from haptic_anfis.exam.session import ExamSession, Surface
    from haptic_anfis.pipeline.contact import DEFAULT_SURFACE
    mesh = load_mesh(DEFAULT_SURFACE, unit='mm')
    mesh.merge_vertices()
    s = ExamSession(Surface.from_mesh(mesh), subject_from_scene(), ExamConfig())
    rng = np.random.default_rng(0)
    ticks = []
    for k in range(50):   # 50 heat-map ticks of 200 samples along a strip
        y = -0.04 + 0.0016 * k
        for i in range(200):
            z = -0.04 + 0.0004 * i
            x = 0.045 * np.sqrt(max(1 - (y / 0.07) ** 2 - (z / 0.07) ** 2, 0))
            s.add_contact(k + i * 1e-3, (x, y, z), rng.uniform(0.002, 0.012), True)
        t0 = time.perf_counter()
        s.update_coverage()
        ticks.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    s.report()
    rep = time.perf_counter() - t0
    q = np.percentile(np.array(ticks) * 1e3, [50, 99])
    print(f'coverage update (200 samples): p50 {q[0]:.2f} ms, p99 {q[1]:.2f} ms '
          f'({len(s.grid.centroids)} region cells); report {rep * 1e3:.0f} ms; load {load()}')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true', help='skip the full simulated exams')
    ap.add_argument('--cases', nargs='*', default=None, metavar='NAME',
                    help='the systematic trainee on these cases (none given: every ready case) '
                         'and the careless one on the default case, as a Markdown table')
    ap.add_argument('--margins', action='store_true',
                    help="each ready case's lesion bumps in its model's forces (no dynamics)")
    a = ap.parse_args()
    if a.margins:
        margins()
        return
    if a.cases is not None:
        all_cases(a.cases)
        return
    core_costs()
    if not a.quick:
        for trainee in ('systematic', 'careless'):
            full_exam(trainee)


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

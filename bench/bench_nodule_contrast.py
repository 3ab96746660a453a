"""Nodule and rib contrast: how much one normal region changes the force a 16 mm probe feels.

A normal background is a confounder only if its bumps reach what the trainee can feel through
the stylus (22 %, :data:`haptic_anfis.cases.grading.PALPABLE_PCT`). This script solves the FE
(the nodular series' small breast, radii 35 x 60 x 60 mm, its validated mesh and five depths) at
one loading point with a single region under it, and at the same point without it, and prints
the contrast |F| / |F without| - 1 per depth. Regions: glandular / fibrous nodules in fat and
fat / fibrous nodules in glandular tissue (radius, centre depth under the skin, modulus), a
carcinoma for comparison, and a rigid rib under the point (the chest wall rises over it). Moduli: Krouskop et al. 1998, 5 %
precompression, 1 Hz (fat 19, glandular 33, fibrous 107, IDC 93 kPa; see config/scenes/nod_s_*.yaml
for the sources). The ``... at (0, 0) @ (o, 0)`` rows move the point o mm off the nodule: the
width of its bump.

The grading (:mod:`haptic_anfis.cases.background`) reads a region's contrast over the smooth
breast of the same body (a lesion-free smooth library case, fitted per depth and scaled by the
modulus); the second table checks it, from committed stores (no solve but the baseline at
(0, 16) mm), against the ground truth: nod_s_fatty_idc10_d10's lesion against its lesion-free
twin, nod_s_fatty_free's point over a nodule at (0, 16) mm against the same point without
nodules, and the reference itself against the FE there; the third the modulus scaling; then the
shipped nodular cases' levels as graded. "no conv.": the load path
stopped there (one attempt at the scene's 4 mm step, no retries; the sweep retries at 2 and 1 mm).

    .venv/bin/python bench/bench_nodule_contrast.py [--cache FILE] [--only KEY ...]

``--cache`` keeps each solved point (JSON) so an interrupted run resumes. Asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from harness import ROOT, run_with_page  # noqa: E402
from haptic_anfis.cases.grading import DEEP_DEPTH, PALPABLE_PCT  # noqa: E402
from haptic_anfis.tissue.fe import FESolveError, solve_scene_point  # noqa: E402
from haptic_anfis.tissue.scene import parse_scene  # noqa: E402
from haptic_anfis.tissue.scenebase import surface_height  # noqa: E402

BASE = ROOT / 'config' / 'scenes' / 'nod_s_fatty_free.yaml'
DEEP_MM = round(DEEP_DEPTH * 1e3, 6)  # the exam's deep level [mm]
RIBS = {'z_mm': [-45, -15, 15, 45], 'width_mm': 12, 'height_mm': 9, 'cover_mm': 5,
        'source': 'bench'}
#: key: (breast kPa, point (y, z) mm, region kind, region kPa, radius mm, centre depth mm[,
#: region (y, z) mm when not under the point]); region kind 'nodule' / 'lesion' / 'rib' / None (the
#: baseline the others are compared with: same breast, same point)
CASES: dict[str, tuple] = {
    'fat19': (19, (0, 0), None, 0, 0, 0),
    'fat19 + glandular33 r4 d8': (19, (0, 0), 'nodule', 33, 4, 8),
    'fat19 + fibrous107 r3 d8': (19, (0, 0), 'nodule', 107, 3, 8),
    'fat19 + fibrous107 r4 d10': (19, (0, 0), 'nodule', 107, 4, 10),
    'fat19 + fibrous107 r5 d7': (19, (0, 0), 'nodule', 107, 5, 7),
    'fat19 + fibrous107 r6 d10': (19, (0, 0), 'nodule', 107, 6, 10),
    'fat19 + fibrous107 r6 d7': (19, (0, 0), 'nodule', 107, 6, 7),
    'fat19 + idc93 r8 d12': (19, (0, 0), 'lesion', 93, 8, 12),
    'fat19 + idc93 r10 d10': (19, (0, 0), 'lesion', 93, 10, 10),
    'fat19 + idc93 r8 d8': (19, (0, 0), 'lesion', 93, 8, 8),
    'fat19 + idc93 r5 d8': (19, (0, 0), 'lesion', 93, 5, 8),
    'fat19 + idc93 r6 d8': (19, (0, 0), 'lesion', 93, 6, 8),
    'fat19 + idc93 r7 d12': (19, (0, 0), 'lesion', 93, 7, 12),
    'fat19 + idc93 r8 d16': (19, (0, 0), 'lesion', 93, 8, 16),
    'fat19 + idc93 r10 d16': (19, (0, 0), 'lesion', 93, 10, 16),
    'fat19 + idc93 r6 d16': (19, (0, 0), 'lesion', 93, 6, 16),
    'fat19 + idc93 r6.5 d16': (19, (0, 0), 'lesion', 93, 6.5, 16),
    'fat19 + idc93 r7 d16': (19, (0, 0), 'lesion', 93, 7, 16),
    'fat19 + idc93 r7.5 d16': (19, (0, 0), 'lesion', 93, 7.5, 16),
    **{f'fat19 @ ({o}, 0)': (19, (o, 0), None, 0, 0, 0) for o in (4, 8, 12, 16)},
    **{f'fat19 + fibrous107 r6 d10 at (0, 0) @ ({o}, 0)': (19, (o, 0), 'nodule', 107, 6, 10, (0, 0))
       for o in (4, 8, 12, 16)},
    'gland33': (33, (0, 0), None, 0, 0, 0),
    'gland33 + fat19 r5 d8': (33, (0, 0), 'nodule', 19, 5, 8),
    'gland33 + fibrous107 r5 d8': (33, (0, 0), 'nodule', 107, 5, 8),
    'gland33 + fibrous107 r6 d7': (33, (0, 0), 'nodule', 107, 6, 7),
    'gland33 + idc93 r10 d10': (33, (0, 0), 'lesion', 93, 10, 10),
    'gland33 + idc93 r8 d8': (33, (0, 0), 'lesion', 93, 8, 8),
    'gland33 + idc93 r10 d14': (33, (0, 0), 'lesion', 93, 10, 14),
    'gland33 + idc93 r12 d14': (33, (0, 0), 'lesion', 93, 12, 14),
    'gland33 + idc93 r9 d16': (33, (0, 0), 'lesion', 93, 9, 16),
    'gland33 + idc93 r10 d18': (33, (0, 0), 'lesion', 93, 10, 18),
    'fat19 @ (0, 15)': (19, (0, 15), None, 0, 0, 0),
    'fat19 @ (0, 16)': (19, (0, 16), None, 0, 0, 0),
    'fat19 + rib @ (0, 15)': (19, (0, 15), 'rib', 0, 6, 0),
    'fat19 @ (25, 0)': (19, (25, 0), None, 0, 0, 0),
    'fat19 @ (25, 15)': (19, (25, 15), None, 0, 0, 0),
    'fat19 + ribs, between two @ (0, 0)': (19, (0, 0), 'rib', 0, 6, 0),
    'fat19 + ribs, between two @ (25, 0)': (19, (25, 0), 'rib', 0, 6, 0),
    'fat19 + rib @ (25, 15)': (19, (25, 15), 'rib', 0, 6, 0),
}


def _baseline(key: str) -> str:
    """The key of the baseline (same breast and point, no region) of ``key``."""
    e, p = CASES[key][:2]
    return next(k for k, v in CASES.items() if v[0] == e and v[1] == p and v[2] is None)


def scene_of(key: str):
    """The scene of ``key``: the nodular series' small breast with only that region."""
    e, _, kind, er, r, d, *at = CASES[key]
    y, z = at[0] if at else CASES[key][1]
    data = yaml.safe_load(BASE.read_text())
    data.pop('background', None)
    data['tumours'] = []
    data['material']['youngs_kPa'] = e
    data.setdefault('loading', {}).pop('ring_diameters', None)
    data['loading'].pop('ring_points', None)
    if kind == 'lesion':
        data['tumours'] = [{'name': 'lesion', 'kind': 'malignant', 'position_mm': [y, z],
                            'depth_mm': d, 'radius_mm': r, 'youngs_kPa': er}]
    elif kind == 'nodule':
        data['background'] = {'nodules': {
            'items': [{'position_mm': [y, z], 'depth_mm': d, 'radius_mm': r}],
            'youngs_kPa': er, 'source': 'bench'}}
    elif kind == 'rib':
        data['background'] = {'ribs': dict(RIBS)}  # rigid: the chest wall rises over them
    return parse_scene(data, name=key.replace(' ', '_'))


def solve(key: str) -> dict:
    """Forces |F| [N] per depth at the case's point, with CPU and wall seconds."""
    scene = scene_of(key)
    y, z = (v * 1e-3 for v in CASES[key][1])
    x = float(surface_height(np.array(y), np.array(z), scene.radii))
    c0, t0 = time.process_time(), time.perf_counter()
    try:
        res, note = solve_scene_point(scene, (x, y, z)), ''
    except FESolveError as exc:  # keep the depths it reached (the sweep would retry smaller steps)
        res, note = exc.partial, str(exc)
    f = [float(np.linalg.norm(v)) for v in res.forces] if res is not None else []
    return {'depths_mm': [d * 1e3 for d in scene.depths],
            'force_n': f + [float('nan')] * (len(scene.depths) - len(f)), 'error': note,
            'cpu_s': time.process_time() - c0, 'wall_s': time.perf_counter() - t0}


def _graded_vs_contrast(done: dict) -> list[str]:
    """Rows, from committed stores (no solve but the baseline at (0, 16) mm), per depth: what
    the grading reads (over the smooth breast, :mod:`haptic_anfis.cases.reference`) against the
    ground truth, the same point with and without the region: nod_s_fatty_idc10_d10's lesion
    against its lesion-free twin; nod_s_fatty_free's point (0, 16) mm over a nodule against the
    same point solved without nodules (``fat19 @ (0, 16)``); and the reference itself there."""
    from haptic_anfis.cases import library
    from haptic_anfis.cases.background import background_grades, map_contrasts
    from haptic_anfis.cases.grading import lesion_grades
    from haptic_anfis.cases.reference import smooth_reference
    from haptic_anfis.cases.sweeps import case_stores, stored_records

    rows = ['| what | depth mm | ground truth % | graded % | graded - truth |',
            '|---|---|---|---|---|']
    case = library().get('nod_s_fatty_idc10_d10')
    recs, twins = stored_records(case_stores(case))
    ref = smooth_reference(case)
    truth = {round(c['depth_m'] * 1e3, 6): c['contrast_pct']
             for c in lesion_grades(case.scene, recs, twins)[0]['contrasts']}
    t = case.scene.tumours[0]
    g = background_grades(case.scene, recs, ref)
    for r in g['lesions'][0]['contrasts']:
        d = round(r['depth_m'] * 1e3, 6)
        rows.append(f'| {case.name} {t.name} (r {t.radius * 1e3:g} mm, {t.youngs / 1e3:g} kPa): '
                    f'contrast vs its twin | {d:g} | {truth[d]:.2f} | {r["contrast_pct"]:.2f} | '
                    f'{r["contrast_pct"] - truth[d]:+.2f} |')
    if 'fat19 @ (0, 16)' not in done:
        return rows
    case = library().get('nod_s_fatty_free')
    recs, _ = stored_records(case_stores(case))
    ref = smooth_reference(case)
    base = done['fat19 @ (0, 16)']
    p = np.array(CASES['fat19 @ (0, 16)'][1]) * 1e-3
    for i, d in enumerate(base['depths_mm']):
        fb = base['force_n'][i]
        yz, c, _ = map_contrasts(recs, ref, d * 1e-3)
        k = int(np.argmin(np.hypot(yz[:, 0] - p[0], yz[:, 1] - p[1])))
        f = ref.forces(yz[k:k + 1], d * 1e-3)[0] * (1.0 + c[k] / 100.0)
        tr = 100.0 * (f / fb - 1.0)
        rows.append(f'| {case.name} point (0, 16) mm over a nodule: contrast vs no nodules | '
                    f'{d:g} | {tr:.2f} | {c[k]:.2f} | {c[k] - tr:+.2f} |')
    for i, d in enumerate(base['depths_mm']):
        fr = ref.forces(p[None], d * 1e-3)[0]
        rows.append(f'| smooth reference ({ref.name}, fitted) at (0, 16) mm: error vs the FE '
                    f'there | {d:g} | 0 | {100.0 * (fr / base["force_n"][i] - 1.0):.2f} | '
                    f'{100.0 * (fr / base["force_n"][i] - 1.0):+.2f} |')
    return rows


def _modulus_scaling() -> list[str]:
    """Rows: the smooth medium fatty breast's force map scaled by 33/19 against the dense one's
    (the reference of a dense nodular case is a fatty smooth case scaled by its modulus)."""
    from haptic_anfis.cases import library
    from haptic_anfis.cases.background import force_map
    from haptic_anfis.cases.reference import SmoothReference
    from haptic_anfis.cases.sweeps import case_stores, stored_records

    lib = library()
    fat, dense = (lib.get(n) for n in ('lib_free_m_fatty', 'lib_free_m_dense'))
    rf, _ = stored_records(case_stores(fat))
    rd, _ = stored_records(case_stores(dense))
    scale = dense.scene.material.youngs / fat.scene.material.youngs
    ref = SmoothReference(fat.name, scale, tuple(rf))
    rows = [f'| depth mm | mean % | max abs % | ({fat.name} x {scale:.3f} vs {dense.name}, '
            f'{len(rd)} points) |', '|---|---|---|---|']
    for d in dense.scene.depths:
        yz, f = force_map(rd, d)
        e = 100.0 * (ref.forces(yz, d) / f - 1.0)
        rows.append(f'| {d * 1e3:g} | {e.mean():+.2f} | {np.abs(e).max():.2f} | |')
    return rows


def _levels() -> list[str]:
    """The shipped nodular cases' levels and their lesions' per-depth figures as graded."""
    from haptic_anfis.cases import library
    out = []
    for c in library().ready():
        g = (c.grading() or {}).get('background')
        if g is None:
            continue
        nb = {round(n['depth_m'] * 1e3, 6): n for n in g['normal_by_depth']}
        out.append(f'- {c.name}: level {g["level"]}; normal regions graded '
                   f'{next(iter(nb.values()))["count"]}, confounders {len(g["confounders"])}; '
                   'normal contrast max per depth: ' + ', '.join(
                       f'{d:g} mm {n["max_pct"]:+.1f} %' for d, n in nb.items()))
        for les in g['lesions']:
            out.append(f'  - {les["lesion"]}: difficulty {les["difficulty"]}, over the smooth '
                       'breast / over the firmest normal region: ' + ', '.join(
                           f'{r["depth_m"] * 1e3:g} mm {r["contrast_pct"]:+.1f} / '
                           f'{r["separation_pct"]:+.1f} %' for r in les['contrasts']))
    return out


def _contrast(done: dict, key: str, depth_mm: float) -> float:
    """Contrast [%] of ``key`` over its baseline at ``depth_mm`` (NaN where not solved)."""
    b, f = done[_baseline(key)], done[key]
    k = b['depths_mm'].index(depth_mm)
    return 100.0 * (f['force_n'][k] / b['force_n'][k] - 1.0)


def _summary(done: dict, keys: list[str], depth_mm: float = DEEP_MM) -> str:
    """The deep level's figures in one paragraph: the fibrocystic nodules' contrast at the point
    over them in fat and in glandular tissue (the spec's radius range), against the stylus
    threshold, and the rib's."""
    def span(prefix: str) -> tuple[float, float, int, int]:
        c = [_contrast(done, k, depth_mm) for k in keys
             if k.startswith(prefix) and ' at ' not in k]
        return min(c), max(c), sum(v >= PALPABLE_PCT for v in c), len(c)
    out = [f'\nAt the deep level ({depth_mm:g} mm), over one region:']
    for name, prefix in (('fibrous nodules (107 kPa, radius 3-6 mm) in fat', 'fat19 + fibrous107'),
                         ('fibrous nodules in glandular tissue', 'gland33 + fibrous107')):
        if any(k.startswith(prefix) for k in keys):
            lo, hi, n_at, n = span(prefix)
            out.append(f'- {name}: {lo:+.1f} to {hi:+.1f} %; {n_at} of {n} at or above the '
                       f'{PALPABLE_PCT:g} % stylus threshold')
    rib = [k for k in keys if CASES[k][2] == 'rib']
    for k in rib:
        out.append(f'- {k}: {_contrast(done, k, depth_mm):+.1f} %')
    ridge = [(y, f'fat19 + rib @ ({y}, 15)', f'fat19 + ribs, between two @ ({y}, 0)')
             for y in (0, 25)]
    ridge = [(y, a, b) for y, a, b in ridge if a in done and b in done]
    if ridge:
        out.append('\nThe ribs raise the whole breast (the rows above are over a flat chest wall); '
                   'what the hand feels as a rib is its ridge, the force over it against the '
                   'intercostal tissue beside it (z = 15 vs 0 mm, same y), per depth:')
        for y, a, b in ridge:
            k = range(len(done[a]['force_n']))
            out.append(f'- y = {y} mm: ' + ', '.join(
                f"{done[a]['depths_mm'][i]:g} mm {100 * (done[a]['force_n'][i] / done[b]['force_n'][i] - 1):+.1f} %"
                for i in k if np.isfinite(done[a]['force_n'][i] / done[b]['force_n'][i])))
    return '\n'.join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--cache', type=Path, help='JSON file of solved points (resume)')
    ap.add_argument('--only', nargs='*', help='solve only these keys (and their baselines)')
    args = ap.parse_args()
    done = json.loads(args.cache.read_text()) if args.cache and args.cache.is_file() else {}
    keys = list(CASES) if not args.only else list(dict.fromkeys(
        k for o in args.only for k in (_baseline(o), o)))
    for k in keys:
        if k not in done:
            done[k] = solve(k)
            print(f'solved {k}: {done[k]["cpu_s"]:.1f} s CPU', file=sys.stderr, flush=True)
            if args.cache:
                args.cache.write_text(json.dumps(done, indent=1))
    depths = done[keys[0]]['depths_mm']
    print('Contrast of one region at the loading point over it, vs the same point without it '
          '(% of |F|), per indentation depth:\n')
    print('| breast + region | E ratio | ' + ' | '.join(f'{d:g} mm' for d in depths)
          + ' | CPU s |')
    print('|---|---|' + '---|' * len(depths) + '---|')
    for k in keys:
        if CASES[k][2] is None:
            continue
        b = np.asarray(done[_baseline(k)]['force_n'])
        f = np.asarray(done[k]['force_n'])
        c = 100.0 * (f / b - 1.0)
        ratio = 'rigid' if CASES[k][2] == 'rib' else f'{CASES[k][3] / CASES[k][0]:.2f}'
        print(f'| {k} | {ratio} | '
              + ' | '.join(f'{v:+.1f}' if np.isfinite(v) else 'no conv.' for v in c)
              + f' | {done[k]["cpu_s"]:.0f} |')
    print('\nWhat the grading reads (cases/background.py: over the smooth breast of the same '
          'body) against the ground truth (the same point with and without the region):\n')
    print('\n'.join(_graded_vs_contrast(done)))
    print('\nThe modulus scaling of the smooth reference (neo-Hookean: force proportional to '
          'the modulus at a fixed geometry):\n')
    print('\n'.join(_modulus_scaling()))
    print('\nThe shipped nodular cases as graded:\n')
    print('\n'.join(_levels()))
    print(_summary(done, keys))
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

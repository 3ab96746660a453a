"""Per-case force scale against one library-wide scale: what the device gives at the exam's
levels. For every ready case: its scale (:mod:`haptic_anfis.cases.force_mapping`), the FE's
largest force over the palpable disc at the deepest trained depth, and the device force over the
breast without its lesions (the smallest FE force over the disc) at the light (2 mm) and deep
(8 mm) levels, with the case's scale and with the one library scale (set by the stiffest case).
Pang, Tan & Durlach 1991 measured the ~7 % force JND over 2.5-10 N.

    .venv/bin/python bench/bench_force_mapping.py [--no-page]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from harness import write_page
from haptic_anfis.cases import library
from haptic_anfis.cases.force_mapping import HEADROOM, case_force_mapping
from haptic_anfis.device.falcon import RATED_FORCE
from haptic_anfis.tissue.dataset import load_dataset


def background(ds, radius: float, depth: float) -> float:
    """The smallest FE |F| [N] over the palpable disc at ``depth`` [m]."""
    sel = (np.abs(ds.X[:, 3] - depth) < 1e-9) & (np.hypot(ds.X[:, 1], ds.X[:, 2])
                                                 <= radius + 1e-9)
    return float(np.linalg.norm(ds.Y[sel], axis=1).min())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    cases = library().ready()
    maps = {c.name: case_force_mapping(c) for c in cases}
    stiffest = max(maps.values(), key=lambda m: m.fe_peak_n)
    lib_scale = HEADROOM * RATED_FORCE / stiffest.fe_peak_n
    rows, deep_case, deep_lib = [], [], []
    for c in cases:
        m = maps[c.name]
        ds = load_dataset(c.dataset_path)
        lo, hi = (background(ds, c.scene.palpable_radius, d) for d in (0.002, 0.008))
        deep_case.append(m.force_scale * hi)
        deep_lib.append(lib_scale * hi)
        rows.append(f'| {c.name} | {m.force_scale:.3f} | {m.fe_peak_n:.1f} | '
                    f'{m.force_scale * lo:.2f} | {m.force_scale * hi:.2f} | {lib_scale * lo:.2f} | '
                    f'{lib_scale * hi:.2f} |')
    text = '\n'.join([
        f'One library scale would be {lib_scale:.3f} (set by {stiffest.case}: '
        f'{stiffest.fe_peak_n:.1f} N at {stiffest.depth_m * 1e3:g} mm at {100 * HEADROOM:g} % of '
        f'{RATED_FORCE:g} N). Device force over the breast at the deep level (8 mm): '
        f'{min(deep_case):.1f}-{max(deep_case):.1f} N with the case scales, '
        f'{min(deep_lib):.1f}-{max(deep_lib):.1f} N with the library scale.', '',
        '| case | case scale | FE peak at 16 mm (N) | device N at 2 mm, case scale | '
        'at 8 mm, case scale | at 2 mm, library scale | at 8 mm, library scale |',
        '|---|---|---|---|---|---|---|', *rows])
    print(text)
    if not a.no_page:
        write_page('force_mapping', 'Force scale per case or for the library', text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())

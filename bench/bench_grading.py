"""The graded library at a palpability threshold: each lesion's FE contrast at every depth, the
pressure level it is first palpable at, its difficulty, and how many ready cases each level 1-5
has. Read from the shipped grading (``cases regrade`` writes it from the committed FE store);
``--threshold`` grades the stored per-depth contrasts at another threshold instead (a trainee's
own, or the finger's 7 %).

    .venv/bin/python bench/bench_grading.py [--threshold PCT] [--no-page]
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter

from harness import write_page
from haptic_anfis.cases import library
from haptic_anfis.cases.grading import BASIS, below_device


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--threshold', type=float, default=None,
                    help='grade at this threshold [%%] (default: as shipped)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    rows, levels, thr = [], Counter(), None
    free, bd = [], []
    for c in library().ready():
        g = c.grading(a.threshold)
        if g is None:
            continue
        thr = g['threshold_pct']
        lvl = 'no level (bd)' if below_device(g) else g['level']
        if not g['lesions']:
            free.append(c.name)
            rows.append(f'| {c.name} | {lvl} | (none) | | | | |')
        elif below_device(g):
            bd.append(c.name)
        else:
            levels[g['level']] += 1
        for e in g['lesions']:
            con = ', '.join(f'{r["contrast_pct"]:+.1f}' for r in e['contrasts'])
            where = (f'{e["found_level"]} ({e["found_depth_m"] * 1e3:g} mm)' if e['palpable']
                     else 'below what this device renders')
            rows.append(f'| {c.name} | {lvl} | {e["lesion"]} | {con} | {where} | '
                        f'{e["difficulty"] or "-"} | {e["reason"] or ""} |')
    dist = ', '.join(f'level {k}: {levels[k]}' for k in range(1, 6))
    empty = [k for k in range(1, 6) if not levels[k]]
    below = sum(1 for r in rows if 'below what this device renders |' in r)
    text = '\n'.join([
        f'Threshold {thr:g} % ({BASIS}).', '',
        f'Ready graded cases with a palpable lesion per level: {dist}'
        + (f' (empty: {", ".join(map(str, empty))})' if empty else ' (none empty)')
        + f'; lesion-free cases (their own group, drawn at every level): {len(free)}; '
        f'cases whose lesions are all below what this device renders (no level, not drawn): '
        f'{len(bd)} ({", ".join(bd) or "none"}); {below} lesion(s) below what this device '
        'renders.', '',
        '| case | level | lesion | FE contrast at 2, 5, 8, 12, 16 mm (%) | first palpable at | '
        'difficulty | reason |', '|---|---|---|---|---|---|---|', *rows])
    print(text)
    if not a.no_page:
        write_page('grading' if a.threshold is None else f'grading_{a.threshold:g}pct',
                   'The graded library: where each lesion is felt, and the levels', text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())

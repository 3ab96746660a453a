"""How well ``haptic-anfis threshold``'s procedure measures a known threshold: simulated
observers of 7, 10, 15, 22 and 40 % (:class:`~haptic_anfis.exam.staircase.SimulatedObserver`),
200 seeded runs each on exact stiffnesses with the default procedure (a 4-down-1-up track, the
maximum-likelihood threshold of every trial) and with the previous one (3-down-1-up, 24
reversals, the geometric mean of the last 20), and a few runs rendered on the simulated Falcon
(:func:`~haptic_anfis.device.stiffness_press.simulated_press`). Per threshold: the share of
single runs within 20 % of the observer's threshold, the median error of one run, the trials a
run takes and the minutes they take on the device (two presses per trial at ``threshold
--press-time``'s default 2 s each: the rendered time alone; the trainee's answer and the ENTER
before each press come on top).

    .venv/bin/python bench/bench_threshold.py [--runs 200] [--device-runs 3] [--no-page]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from harness import write_page
from haptic_anfis.device.stiffness_press import simulated_press
from haptic_anfis.exam.staircase import DOWN_RATIO, LAPSE, STEPS, SimulatedObserver, Staircase
from haptic_anfis.exam.threshold_run import run_threshold

#: [s] rendered per press on the device (``haptic-anfis threshold --press-time`` default)
PRESS_TIME_S = 2.0
#: the bar a single run is held to, relative to the observer's threshold
WITHIN = 0.20
THRESHOLDS = (0.07, 0.10, 0.15, 0.22, 0.40)


def exact_press(k: float):
    """A press that gives the hand exactly the asked stiffness (the procedure alone)."""
    return type('P', (), {'stiffness': k})()


def one_run(threshold: float, seed: int, press, old: bool) -> tuple[float, int]:
    """(estimated threshold [fraction], trials) of one seeded run."""
    obs = SimulatedObserver(threshold, seed)
    s = Staircase(down=3, reversals=24) if old else Staircase()
    res = run_threshold(press, lambda a, b: obs.choose(a.stiffness, b.stiffness), s, seed=seed)
    key = 'reversal_threshold_pct' if old else 'threshold_pct'
    return res[key] / 100.0, res['trials']


def row(threshold: float, procedure: str, presses: str, got: list[tuple[float, int]]) -> dict:
    est = np.array([g for g, _ in got])
    err = est / threshold - 1
    trials = float(np.mean([t for _, t in got]))
    return {'threshold': threshold, 'procedure': procedure, 'presses': presses, 'runs': len(got),
            'within': float(np.mean(np.abs(err) <= WITHIN)), 'median_err': float(np.median(err)),
            'trials': trials, 'minutes': trials * 2 * PRESS_TIME_S / 60.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=200)
    ap.add_argument('--device-runs', type=int, default=3)
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    s = Staircase()
    new = f'{s.down}-down-1-up, {s.reversals} reversals, max likelihood'
    old = '3-down-1-up, 24 reversals, mean of last 20'
    rows = []
    for T in THRESHOLDS:
        for name, press, n, is_old in ((new, exact_press, a.runs, False),
                                       (old, exact_press, a.runs, True),
                                       (new, simulated_press, a.device_runs, False)):
            if n < 1:
                continue
            label = 'exact' if press is exact_press else 'simulated Falcon'
            rows.append(row(T, name, label, [one_run(T, seed, press, is_old)
                                             for seed in range(n)]))
            print(rows[-1], flush=True)
    lines = ['| observer threshold (%) | procedure | presses | runs | single runs within 20 % | '
             'median error of one run (%) | trials per run (mean) | rendered minutes per run |',
             '|---|---|---|---|---|---|---|---|']
    lines += [f'| {100 * r["threshold"]:g} | {r["procedure"]} | {r["presses"]} | {r["runs"]} | '
              f'{100 * r["within"]:.0f} % | {100 * r["median_err"]:+.1f} | {r["trials"]:.0f} | '
              f'{r["minutes"]:.1f} |' for r in rows]
    mine = [r for r in rows if r['procedure'] == new and r['presses'] == 'exact']
    prev = [r for r in rows if r['procedure'] == old]
    summary = (f'Default procedure ({new}): a single run within 20 % of the observer\'s '
               f'threshold in {100 * min(r["within"] for r in mine):.0f}-'
               f'{100 * max(r["within"] for r in mine):.0f} % of {a.runs} seeded runs per '
               f'threshold ({", ".join(f"{100 * t:g}" for t in THRESHOLDS)} %), in '
               f'{min(r["trials"] for r in mine):.0f}-{max(r["trials"] for r in mine):.0f} trials '
               f'({min(r["minutes"] for r in mine):.0f}-{max(r["minutes"] for r in mine):.0f} '
               f'rendered minutes); the previous procedure: '
               f'{100 * min(r["within"] for r in prev):.0f}-'
               f'{100 * max(r["within"] for r in prev):.0f} %.' if mine and prev else '')
    text = (f'{summary}\n\nTrack: steps x{STEPS[0]:g} then x{STEPS[1]:g}, a step down '
            f'{DOWN_RATIO:g} of a step up; the fit allows a lapse rate of {LAPSE:g} (the '
            'simulated observer has none: the small low median error).\n\n'
            + '\n'.join(lines))
    print(text)
    if not a.no_page:
        write_page('threshold', "A trainee's own threshold: the staircase on known observers",
                   text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())

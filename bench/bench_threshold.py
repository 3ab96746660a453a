"""How well ``haptic-anfis threshold``'s staircase measures a known threshold: simulated observers
of 10, 22 and 40 % (:class:`~haptic_anfis.exam.staircase.SimulatedObserver`), 40 seeded runs
each on exact stiffnesses, and 5 runs each rendered on the simulated Falcon
(:func:`~haptic_anfis.device.stiffness_press.simulated_press`). Per threshold: the median error
of one run, the share of single runs within 20 %, the geometric mean of groups of 5 runs and the
trials a run takes.

    .venv/bin/python bench/bench_threshold.py [--runs 40] [--no-page]
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from harness import write_page
from haptic_anfis.device.stiffness_press import simulated_press
from haptic_anfis.exam.staircase import DOWN_RATIO, STEPS, SimulatedObserver, Staircase
from haptic_anfis.exam.threshold_run import run_threshold


def exact_press(k: float):
    """A press that gives the hand exactly the asked stiffness (the staircase alone)."""
    return type('P', (), {'stiffness': k})()


def one_run(threshold: float, seed: int, press) -> tuple[float, int]:
    obs = SimulatedObserver(threshold, seed)
    res = run_threshold(press, lambda a, b: obs.choose(a.stiffness, b.stiffness), Staircase(),
                        seed=seed)
    return res['threshold_pct'] / 100.0, res['trials']


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=40)
    ap.add_argument('--device-runs', type=int, default=5)
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    lines = ['| observer threshold (%) | presses | runs | median error of one run (%) | '
             'single runs within 20 % | geometric mean of 5 runs: worst error (%) | '
             'trials per run (mean) |', '|---|---|---|---|---|---|---|']
    for T in (0.10, 0.22, 0.40):
        for name, press, n in (('exact', exact_press, a.runs),
                               ('simulated Falcon', simulated_press, a.device_runs)):
            got = [one_run(T, seed, press) for seed in range(n)]
            est = np.array([g for g, _ in got])
            err = est / T - 1
            groups = [math.exp(np.mean(np.log(est[i:i + 5]))) / T - 1
                      for i in range(0, n - 4, 5)]
            worst = max(groups, key=abs) if groups else float('nan')
            lines.append(f'| {100 * T:g} | {name} | {n} | {100 * np.median(err):+.1f} | '
                         f'{np.mean(np.abs(err) <= 0.2) * 100:.0f} % | {100 * worst:+.1f} | '
                         f'{np.mean([t for _, t in got]):.0f} |')
            print(lines[-1], flush=True)
    text = (f'Staircase: 3-down-1-up, steps x{STEPS[0]:g} then x{STEPS[1]:g}, a step down '
            f'{DOWN_RATIO:g} of a step up, {Staircase().reversals} reversals, the geometric mean of the '
            f'last {Staircase().averaged}.\n\n'
            + '\n'.join(lines))
    print(text)
    if not a.no_page:
        write_page('threshold', "A trainee's own threshold: the staircase on known observers",
                   text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""One threshold measurement: the staircase (:mod:`.staircase`) run on rendered presses.

Each trial renders two presses on the device (:mod:`haptic_anfis.device.stiffness_press`), the
reference spring and one ``1 + delta`` stiffer, in an order drawn by the seed; the observer (the
trainee, or a :class:`~.staircase.SimulatedObserver` judging what the device rendered) names the
stiffer one. Pure Python, no ROS.
"""
from __future__ import annotations

import random
from typing import Callable

from ..device.stiffness_press import PressResult
from .staircase import Staircase

__all__ = ['REFERENCE_STIFFNESS', 'run_threshold']

#: [N/m] the reference spring: 4 N at 10 mm, inside the 2.5-10 N over which force discrimination
#: keeps its Weber fraction (Pang, Tan & Durlach 1991), as a breast's deep press is rendered
REFERENCE_STIFFNESS = 400.0


def run_threshold(press: Callable[[float], PressResult],
                  choose: Callable[[PressResult, PressResult], int],
                  staircase: Staircase | None = None, seed: int = 0,
                  reference: float = REFERENCE_STIFFNESS,
                  on_trial: Callable[[int, float, bool], None] | None = None) -> dict:
    """Run ``staircase`` to its end: ``press(stiffness)`` renders one press, ``choose(a, b)``
    returns 0 when the first press felt stiffer. Returns ``threshold_pct`` (the maximum-likelihood
    fit, :meth:`.Staircase.threshold`), ``reversal_threshold_pct`` (the last reversals' mean),
    ``method``, ``trials``, ``reversals``, ``correct_pct``, ``reference_n_per_m``,
    ``reversal_pct`` (every reversal's difference) and the rendered stiffness ratio's mean
    error against the one asked for."""
    s = staircase or Staircase()
    order = random.Random(seed)
    ratio_err = []
    while not s.done:
        stiffer = reference * (1.0 + s.delta)
        first = order.random() < 0.5
        a, b = (press(stiffer), press(reference)) if first else (press(reference), press(stiffer))
        got = (a.stiffness / b.stiffness) if first else (b.stiffness / a.stiffness)
        ratio_err.append(got / (1.0 + s.delta) - 1.0)
        correct = (choose(a, b) == 0) == first
        if on_trial is not None:
            on_trial(len(s.trials) + 1, s.delta, correct)
        s.answer(correct)
    return {'threshold_pct': 100.0 * s.threshold(), 'trials': len(s.trials),
            'reversals': len(s.reversal_deltas), 'method': f'{s.down}-down-1-up, max likelihood',
            'reversal_threshold_pct': 100.0 * s.reversal_threshold(),
            'correct_pct': 100.0 * sum(c for _, c in s.trials) / len(s.trials),
            'reference_n_per_m': reference,
            'reversal_pct': [round(100.0 * d, 3) for d in s.reversal_deltas],
            'rendered_ratio_error_pct': 100.0 * sum(ratio_err) / len(ratio_err)}

"""Press onsets with the graph late (issue 32): how many ticks of a trainee's trajectory render
0 N in contact while the tissue pushes back > 1 N, when the servo loop renders models made some
milliseconds earlier, for each contact_detector ``approach_distance`` and falcon_driver
``model_approach_radius``.

A free probe's model carries the surface plane ahead of it only while that surface lies within
``approach_distance`` along the indentation direction; the servo loop then renders the press from
the tick the probe crosses the plane. With the graph L ms late (a busy machine without real-time
priority: the no-RT launch hour's press-onset dropouts came with contacts 150-290 ms old), the
model in hand at the crossing was made v L before it: at the hand script's 30 mm/s press, 4.5-8.7
mm above the surface — beyond the shipped 5 mm, so the model said "free" and the loop rendered 0 N
until a model from inside arrived. The models are made as the nodes make them (contact tracker,
approach fields, force server) at every pose of a servo trace; the model made ``age`` ticks
earlier is rendered at each tick (``LocalModelRenderer`` without expiry: the compiled tick holds a
model up to ``model_hold_time``, 1 s). Counted: dropout ticks (in contact, ideal > 1 N, 0 N
rendered, as ``zero_ticks`` on the servo_load pages) and phantom ticks (free, > 0.1 N rendered:
a stale plane pressing on the probe in free space), for each radius out to which an approach
plane is rendered along it from its point (``local_model.across_beyond``; past it, zero) and
without that rule. Asserts nothing; prints and writes docs/measurements/approach_late.md.

    .venv/bin/python bench/bench_approach_late.py [--trace FILE] [--start S] [--seconds 60]
        [--ages 250,500] [--distances 0.005,0.01,0.015,0.02]
        [--radii 0.005,0.01,0.015,0.02,0.03] [--no-page]
"""
from __future__ import annotations

import argparse
import contextlib
import sys

import numpy as np

from _args import positive_numbers
from _page import write_page
from bench_model_age import add_trace_arguments, models_along, rendered, trace_window
from haptic_anfis.device import local_model
from haptic_anfis.device.force_error import dropout_ticks, phantom_ticks, runs_of


@contextlib.contextmanager
def without_the_plane_rule():
    """The Python renderer with an approach plane rendered at any distance along it (the rule
    as it was before: the offset held at the radius)."""
    rule = local_model.across_beyond
    local_model.across_beyond = lambda *a: False
    try:
        yield
    finally:
        local_model.across_beyond = rule


def counts(models, positions, times, F, contact, age: int, approach_radius: float
           ) -> tuple[int, int, int, float]:
    """(dropout ticks, their longest run, phantom ticks, RMS error % of the RMS ideal force)
    rendering the model made ``age`` ticks earlier, approach planes out to ``approach_radius``
    [m] along them."""
    f = rendered(models, positions, times, age, symmetric_only=False,
                 approach_radius=approach_radius)
    fn, Fn = np.linalg.norm(f, axis=1), np.linalg.norm(F, axis=1)
    drop = dropout_ticks(fn, Fn, contact)
    starts, ends = runs_of(drop)
    longest = int((ends - starts).max()) if len(starts) else 0
    phantom = int(phantom_ticks(fn, contact).sum())
    e = np.linalg.norm(f[contact] - F[contact], axis=1)
    rms = np.sqrt(np.mean(Fn[contact] ** 2))
    return int(drop.sum()), longest, phantom, float(100 * np.sqrt(np.mean(e ** 2)) / rms)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(ap, 60.0)
    ap.add_argument('--ages', type=positive_numbers, default=[250, 500],
                    help='model ages [ms] (default 250,500)')
    ap.add_argument('--distances', type=positive_numbers, default=[0.005, 0.01, 0.015, 0.02],
                    help='contact_detector approach_distance values [m] (default '
                         '0.005,0.01,0.015,0.02)')
    ap.add_argument('--radii', type=positive_numbers,
                    default=[0.005, 0.01, 0.015, 0.02, 0.03],
                    help='falcon_driver model_approach_radius values [m] (default '
                         '0.005,0.01,0.015,0.02,0.03)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    name, a.start, times, positions = trace_window(a)
    period = float(np.median(np.diff(times)))
    lines = [f'{name}: {len(times)} ticks from {a.start:g} s, {a.seconds:g} s', '',
             '| approach_distance (mm) | model age (ms) | approach_radius (mm) | dropout ticks '
             '| longest (ticks) | phantom ticks | error (%) |',
             '|---|---|---|---|---|---|---|']
    for dist in a.distances:
        models, F, contact = models_along(positions, {'approach_distance': dist})
        for age_ms in a.ages:
            age = max(int(round(age_ms * 1e-3 / period)), 0)
            for radius in a.radii:
                drop, longest, phantom, err = counts(models, positions, times, F, contact, age,
                                                     radius)
                lines.append(f'| {dist * 1e3:g} | {age_ms:g} | {radius * 1e3:g} | {drop} | '
                             f'{longest} | {phantom} | {err:.2f} |')
                print(lines[-1], flush=True)
            with without_the_plane_rule():
                drop, longest, phantom, err = counts(models, positions, times, F, contact, age,
                                                     a.radii[0])
            lines.append(f'| {dist * 1e3:g} | {age_ms:g} | no rule | {drop} | {longest} | '
                         f'{phantom} | {err:.2f} |')
            print(lines[-1], flush=True)
    text = '\n'.join(lines)
    print(text)
    if not a.no_page:
        body = (text + '\n\nThe trace: the hand script\'s presses (30 mm/s into the tissue from '
                '8 mm above it), as a session\'s servo loop moved them. A model age is in servo '
                'ticks (1 ms at the nominal rate). Dropout: in contact, the ideal force > 1 N, 0 N '
                'rendered. Phantom: not in contact, > 0.1 N rendered. Error: RMS over the contact '
                'ticks, % of the RMS ideal force. approach_radius: how far along an approach '
                'plane from its point it is rendered; "no rule": at any distance (the offset '
                'held at model_validity_radius, as before the rule), the same models.\n')
        write_page('approach_late',
                   'Press onsets with the graph late, by approach distance and radius', body)
    return 0


if __name__ == '__main__':
    sys.exit(main())

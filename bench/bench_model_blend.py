"""What falcon_driver's ``model_blend_time`` buys and costs (issue 32): the step between two
successive local models faded out with that time constant, against the ripple windows and the
force error of a loop whose models come late now and then.

A trainee's trajectory (a session's servo trace) is replayed tick by tick through the compiled
tick (``native_tick``, the driver's defaults but the blend time), the handle pinned where the
trainee was. The local model of every pose is made as the contact detector and the force server
make it (``bench_model_age.models_along``) and reaches the loop ``--latency-ms`` after its pose;
every ``--every`` seconds a stall of the graph (each of ``--stalls``) lets no model through, then
the newest one comes (so the loop renders one model held, then steps to a fresh one: what a busy
machine does to the graph). Per blend time and stall length: the applied-force RMS error (% of
the RMS ideal force, over the ticks in contact) and the ripple windows (200 ms windows with the
force > 0.1 N off its 50 ms mean; the ideal force's own beside it), as ``haptic-anfis loop``
counts them. Asserts nothing; prints and writes docs/measurements/model_blend.md.

    .venv/bin/python bench/bench_model_blend.py [--trace FILE] [--start 30] [--seconds 60]
        [--latency-ms 2] [--every 1] [--stalls 0,0.02,0.05,0.1,0.2]
        [--blend-times 0,0.01,0.02,0.05] [--no-page]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from _args import non_negative_numbers
from _page import write_page
from bench_model_age import add_trace_arguments, models_along, trace_window
from bench_stall_hold import driver_loop, tick_at
from haptic_anfis.device.servo_native import NativeServoLoop
from haptic_anfis.device.force_error import force_error, ripple_and_dropouts
from haptic_anfis.nodes.falcon_driver import PARAMS
from haptic_anfis.nodes.parameters import default_of


def arrivals(times: np.ndarray, latency: float, every: float, stall: float) -> np.ndarray:
    """(n,) index of the newest pose whose model the loop has at each tick (-1: none yet): the
    model of a pose reaches the loop ``latency`` [s] after it, except during a stall of
    ``stall`` [s] starting every ``every`` [s] (from ``every``), when none arrives."""
    newest = np.searchsorted(times, times - latency, side='right') - 1
    if stall > 0.0:
        t = times - times[0]
        in_stall = (t >= every) & ((t % every) < stall)
        idx = np.arange(len(times))
        # during a stall the loop keeps what it had at the stall's first tick
        held = np.where(in_stall, -1, newest)
        held = np.maximum.accumulate(np.where(held >= 0, idx, 0))   # last tick outside a stall
        newest = np.where(in_stall, newest[held], newest)
    return newest


def replay(models: list, times: np.ndarray, positions: np.ndarray, newest: np.ndarray,
           blend_time: float) -> np.ndarray:
    """The force the loop renders (n, 3) [N], tissue frame (the tick's target force, before
    the safety layer's rate limit), offered the model of pose ``newest[i]`` at tick i."""
    return replay_on(driver_loop(default_of(PARAMS, 'model_hold_time'), blend_time=blend_time),
                     models, times, positions, newest)


def replay_on(lp: NativeServoLoop, models: list, times: np.ndarray, positions: np.ndarray,
              newest: np.ndarray) -> np.ndarray:
    """:func:`replay` on a loop of the caller's (``lp``, fresh, never started): its safety
    layer started, then one tick per pose, offered the model of pose ``newest[i]`` at tick i."""
    lp.safety.start()
    out = np.zeros((len(times), 3))
    offered = -1
    for i, (p, t) in enumerate(zip(positions, times)):
        j = newest[i]
        if j != offered and j >= 0:
            lp.renderer.offer_values(models[j], float(times[j]))
            offered = j
        out[i] = tick_at(lp, p, t)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(ap, 60.0)
    ap.add_argument('--latency-ms', type=float, default=2.0,
                    help='pose -> model latency outside the stalls [ms] (default 2)')
    ap.add_argument('--every', type=float, default=1.0,
                    help='seconds between stall starts (default 1)')
    ap.add_argument('--stalls', type=non_negative_numbers, default=[0.0, 0.02, 0.05, 0.1, 0.2],
                    help='stall lengths [s], 0 for none (default 0,0.02,0.05,0.1,0.2)')
    ap.add_argument('--blend-times', type=non_negative_numbers, default=[0.0, 0.01, 0.02, 0.05],
                    help='model_blend_time values [s], 0 for off (default 0,0.01,0.02,0.05)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    if max(a.stalls) >= a.every:
        raise SystemExit(f'--stalls: expected each shorter than --every ({a.every:g} s), got '
                         f'{max(a.stalls):g} s')
    name, a.start, times, positions = trace_window(a)
    models, F, contact = models_along(positions)
    lines = [f'{name}: {len(times)} ticks from {a.start:g} s, {a.seconds:g} s; models '
             f'{a.latency_ms:g} ms after their pose, a stall every {a.every:g} s', '',
             '| stall (ms) | model_blend_time (ms) | error (%) | ripple windows (%) '
             '| the ideal\'s own (%) |', '|---|---|---|---|---|']
    for stall in a.stalls:
        newest = arrivals(times, a.latency_ms * 1e-3, a.every, stall)
        for tau in a.blend_times:
            f = replay(models, times, positions, newest, tau)
            err = force_error(f, F, contact)
            rip = ripple_and_dropouts(times, f, F, contact)
            lines.append(f'| {stall * 1e3:g} | {tau * 1e3:g} | {err["force_error_rms_pct"]:.3f} '
                         f'| {rip["ripple_windows_pct"]:.2f} '
                         f'| {rip["ripple_windows_ideal_pct"]:.2f} |')
            print(lines[-1], flush=True)
    text = '\n'.join(lines)
    print(text)
    if not a.no_page:
        body = (text + '\n\nStall 0: models only ever the latency late (the quiet case: what the '
                'fade costs). Error: RMS of |rendered - ideal| over the ticks in contact, % of '
                'the RMS ideal force; the ideal is the force server\'s at the pose itself. '
                'Ripple windows: 200 ms windows at least half in contact in which the rendered '
                'force leaves its centred 50 ms mean by more than 0.1 N (issue 32\'s target: '
                '<= 1 %). The rendered force is the tick\'s target, before the safety layer\'s '
                'rate limit; the handle is pinned on the trajectory (no hand dynamics).\n')
        write_page('model_blend', 'Fading the step between two models: what it buys and costs',
                   body)
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""What falcon_driver's ``model_hold_time`` and ``model_hold_radius`` cost and buy (issue 32):
the graph stalls (no new local model for S seconds, as when the force server is descheduled on
a busy machine) and the servo loop renders the last model it has, held up to H seconds while the
probe stays within the hold radius of where the model was made, then expired (0 N after the
watchdog ramp).

A held model is rendered as the compiled tick renders it (``native_tick``: the depth followed
exactly, the offset across held at ``model_validity_radius``, the skew part dropped where K has a
rotating mode, the passivity bound by the measured period), tick by tick at the trace's own times
and positions. A stall starts every ``--every`` seconds of a trainee's trajectory (a session's
servo trace: in a press, in free space or anywhere between, as a stall would fall); the model in
hand is the one made at the stall's first pose. What a hold buys: dropout ticks (in contact, the
ideal force > 1 N, 0 N rendered) that a shorter or narrower hold leaves. What it costs: the error
of the held ticks against the force the tissue would push back with (the force server's at the
same pose), and phantom ticks (not in contact, > 0.1 N rendered). Asserts nothing; prints and
writes docs/measurements/stall_hold.md.

    .venv/bin/python bench/bench_stall_hold.py [--trace FILE] [--start 30] [--seconds 120]
        [--every 4] [--stalls 0.25,0.5,0.6,1,1.5,2] [--holds 0.5,1,1.5,2] [--radii 0.02,0.03,0.04,1]
        [--no-page]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from _args import positive_numbers
from _page import write_page
from bench_model_age import add_trace_arguments, models_along, trace_window
from haptic_anfis.device import HandParams, PalpationScript, WorkspaceMapping
from haptic_anfis.device import native_tick as nt
from haptic_anfis.device.force_error import dropout_ticks, phantom_ticks
from haptic_anfis.device.local_model import EXPIRED, HOLD_RADIUS
from haptic_anfis.device.servo_native import NativeServoLoop
from haptic_anfis.nodes.falcon_driver import PARAMS
from haptic_anfis.nodes.parameters import default_of


#: [m] a hold radius that no trajectory leaves (the workspace is a 10 cm cube): no radius rule
NO_RADIUS = 1.0


def driver_mapping() -> WorkspaceMapping:
    """The workspace mapping and force scale as falcon_driver builds them by default."""
    d = lambda name: default_of(PARAMS, name)  # noqa: E731
    return WorkspaceMapping(d('workspace_scale'), tuple(d('workspace_offset')),
                            d('force_scale'))


def driver_loop(hold: float, radius: float = HOLD_RADIUS,
                blend_time: float | None = None,
                passivity_window: float | None = None) -> NativeServoLoop:
    """The compiled loop as falcon_driver builds it by default (mapping, hand, local model
    radii and times), with ``hold`` [s] as its ``model_hold_time``, ``radius`` [m] as its
    ``model_hold_radius`` and ``blend_time`` [s] (None: the default) as its
    ``model_blend_time``, ``passivity_window`` [s] likewise; driven tick by tick
    (:func:`held_forces`), never started."""
    d = lambda name: default_of(PARAMS, name)  # noqa: E731
    mapping = driver_mapping()
    still = PalpationScript(np.array([0.0, 1.0]), np.zeros((2, 3)), np.array([False]),
                            loop=False)
    return NativeServoLoop(still, mapping, HandParams(), rate=d('rate'), mode='local_model',
                           max_force=d('max_force'), max_force_rate=d('max_force_rate'),
                           watchdog_timeout=d('watchdog_timeout'),
                           max_stiffness=d('max_stiffness'), damping=d('passivity_damping'),
                           validity_time=d('model_validity_time'),
                           validity_radius=d('model_validity_radius'),
                           approach_radius=d('model_approach_radius'), hold_time=hold,
                           hold_radius=radius,
                           blend_time=(d('model_blend_time') if blend_time is None
                                       else blend_time),
                           passivity_window=(d('passivity_window') if passivity_window is None
                                             else passivity_window))


def held_forces(lp: NativeServoLoop, model, t0: float, positions: np.ndarray,
                times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(force rendered (n, 3) [N], tissue frame; expired (n,)) at each pose (tissue frame [m])
    of a stall at ``times`` [s] whose only model is ``model`` (26 values) of time ``t0`` [s], on
    a loop of its own (``lp``, fresh: nothing carried from another stall): the tick's target
    force before the safety layer. An expired tick is counted as 0 N at once: the watchdog's
    10 ms and its ramp, which hold the last force a little longer on the device, are left out
    (so a phantom that a hold radius ends lasts up to ~15 ticks longer than counted here)."""
    lp.safety.start()
    lp.renderer.offer_values(model, t0)
    out, expired = np.zeros((len(times), 3)), np.zeros(len(times), dtype=bool)
    for i, (p, t) in enumerate(zip(positions, times)):
        f = tick_at(lp, p, t)
        if int(lp.st[nt.S.status]) == EXPIRED:
            expired[i] = True
        else:
            out[i] = f
    return out, expired


def tick_at(lp: NativeServoLoop, p, t: float) -> np.ndarray:
    """One tick of ``lp`` at time ``t`` [s] with the handle held at the tissue position ``p``
    [m] (where the trainee was, at rest): the tick's target force (3,) [N], tissue frame,
    before the safety layer's rate limit."""
    S = nt.S
    lp.st[S.x0:S.x0 + 3] = lp.mapping.to_device(tuple(p))
    lp.st[S.v0:S.v0 + 3] = 0.0
    lp.st[S.t_dev] = t
    lp.tick(float(t))
    return lp.st[S.target0:S.target0 + 3] / lp.mapping.force_scale


def row(stall: float, hold: float, radius: float, stalls: list) -> str:
    """One table row: the first ``stall`` [s] of each of ``stalls`` ((time since the stall's
    start [s], rendered force [N], expired, ideal force [N], in contact) per tick), for a
    ``hold`` [s] and ``radius`` [m]."""
    drop = held = phantom = 0
    err2 = ref2 = all2 = allref2 = err_max = ph_max = 0.0
    for dt, f, expired, Fs, cs in stalls:
        w = dt < stall
        fn, Fn = np.linalg.norm(f, axis=1), np.linalg.norm(Fs, axis=1)
        drop += int((w & dropout_ticks(fn, Fn, cs)).sum())
        h = w & cs & ~expired
        held += int(h.sum())
        e = np.linalg.norm(f[h] - Fs[h], axis=1)
        err2, ref2 = err2 + float(np.sum(e ** 2)), ref2 + float(np.sum(Fn[h] ** 2))
        err_max = max(err_max, float(e.max(initial=0.0)))
        ph = w & phantom_ticks(fn, cs)
        phantom += int(ph.sum())
        ph_max = max(ph_max, float(fn[ph].max(initial=0.0)))
        every = w & (cs | (fn > 0.0))  # in contact, or rendering a force: what the hand feels
        all2 += float(np.sum(np.linalg.norm(f[every] - Fs[every], axis=1) ** 2))
        allref2 += float(np.sum(Fn[w & cs] ** 2))
    pct = lambda a, b: 100 * np.sqrt(a / b) if b > 0 else 0.0  # noqa: E731
    shown = 'none' if radius >= NO_RADIUS else f'{radius * 1e3:g}'
    return (f'| {stall:g} | {hold:g} | {shown} | {drop} | {held} | {pct(err2, ref2):.2f} | '
            f'{err_max:.2f} | {phantom} | {ph_max:.2f} | {pct(all2, allref2):.2f} |')


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(ap, 120.0)
    ap.add_argument('--every', type=float, default=4.0,
                    help='seconds between stall starts (default 4)')
    ap.add_argument('--stalls', type=positive_numbers, default=[0.25, 0.5, 0.6, 1.0, 1.5, 2.0],
                    help='stall lengths [s] (default 0.25,0.5,0.6,1,1.5,2)')
    ap.add_argument('--holds', type=positive_numbers, default=[0.5, 1.0, 1.5, 2.0],
                    help='model_hold_time values [s] (default 0.5,1,1.5,2)')
    ap.add_argument('--radii', type=positive_numbers, default=[0.02, 0.03, HOLD_RADIUS, NO_RADIUS],
                    help=f'model_hold_radius values [m] (default 0.02,0.03,{HOLD_RADIUS:g},'
                         f'{NO_RADIUS:g}: {NO_RADIUS:g} is none)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    if max(a.stalls) >= a.every:
        raise SystemExit(f'--stalls: expected each shorter than --every ({a.every:g} s), got '
                         f'{max(a.stalls):g} s')
    name, a.start, times, positions = trace_window(a)
    models, F, contact = models_along(positions)
    Fn = np.linalg.norm(F, axis=1)
    firsts = np.searchsorted(times, times[0] + np.arange(0.0, times[-1] - times[0] - max(a.stalls),
                                                         a.every))
    in_press = int(sum(contact[i] and Fn[i] > 1.0 for i in firsts))
    longest = max(a.stalls)
    lines = [f'{name}: {len(times)} ticks from {a.start:g} s, {a.seconds:g} s; {len(firsts)} '
             f'stalls, one every {a.every:g} s ({in_press} starting in a press, ideal > 1 N)', '',
             '| stall (s) | model_hold_time (s) | model_hold_radius (mm) | dropout ticks '
             '| ticks in contact, not expired | their error (%) | their max error (N) '
             '| phantom ticks | max phantom (N) | error over the stalls (%) |',
             '|---|---|---|---|---|---|---|---|---|---|']
    table = {}
    for hold in a.holds:
        for radius in a.radii:
            stalls = []
            for i0 in firsts:
                sl = slice(i0, np.searchsorted(times, times[i0] + longest))
                f, expired = held_forces(driver_loop(hold, radius), models[i0], times[i0],
                                         positions[sl], times[sl])
                stalls.append((times[sl] - times[i0], f, expired, F[sl], contact[sl]))
            for stall in a.stalls:
                table[stall, hold, radius] = row(stall, hold, radius, stalls)
                print(table[stall, hold, radius], flush=True)
    lines += [table[k] for k in sorted(table)]
    text = '\n'.join(lines)
    print(text)
    if not a.no_page:
        body = (text + '\n\nA stall: no model newer than its first pose\'s for its length; the '
                'trajectory goes on as the trace has it (a trainee does not stop when the graph '
                'does). Each stall on a loop of its own. Ticks in contact, not expired: rendered '
                'from the stall\'s model (valid for its model_validity_time, then held); an '
                'expired tick counts as 0 N at once (the watchdog\'s 10 ms and ramp left out). '
                'Dropout: in contact, ideal > 1 N, 0 N rendered '
                '(expired, or the held model says free). Phantom: not in contact, > 0.1 N '
                'rendered. Their error: RMS of |rendered - ideal| over those ticks, % '
                'of the RMS ideal force over the same ticks; the ideal is the force server\'s '
                'at the pose itself. Error over the stalls: the same over every stall tick in '
                'contact or rendering a force (dropouts and phantoms included), % of the RMS '
                'ideal force over the stalls\' contact ticks. model_hold_radius "none": 1 m, '
                'more than the workspace.\n')
        write_page('stall_hold', 'A stalled graph: what the model hold buys and costs',
                   body)
    return 0


if __name__ == '__main__':
    sys.exit(main())

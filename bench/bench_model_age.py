"""The local model's force error by its age (issue 32): how far the force rendered from a model
made some milliseconds ago drifts from the tissue's, with the stiffness guard as shipped (the
symmetric part made a passive spring, the skew part kept) and as it was before (the symmetric
part only).

The probe positions come from a servo tick trace of a real session (``haptic-anfis launch`` with
the default scene and hand script, the graph without real-time priority: a trainee's trajectory
as the loop saw it), or from ``--trace`` (a falcon_driver ``trace_path`` .npz). Every pose goes
through the contact tracker and force model as the nodes run them; the model made at pose i - a is
rendered at pose i (``LocalModelRenderer``, no expiry) and compared with the ideal force at pose i.
Error: RMS over the contact ticks, % of the RMS ideal force (the figure of ``sim --json``). What
a loop sees is a mixture of ages (pose -> model latency: ``lat_p99_ms`` on the servo_load pages).
Asserts nothing; prints and writes docs/measurements/model_age.md.

    .venv/bin/python bench/bench_model_age.py [--duration 15] [--trace FILE] [--no-page]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from _page import write_page
from haptic_anfis.device.local_model import LocalModelRenderer, condition_stiffness_values, \
    rotating_mode, skew_vector, symmetric_part
from haptic_anfis.device.trace import DISABLED, load_trace
from haptic_anfis.nodes.resim import build_pipeline
from haptic_anfis.pipeline.contact import approach_values, contact_values
from haptic_anfis.pipeline.force import local_model_from_contact

ROOT = Path(__file__).resolve().parent.parent
AGES_MS = (1, 2, 3, 5, 10, 20, 50)


def session_trace(duration: float, d: Path) -> Path:
    """Run a ``launch`` (driver, detector, force server; no real-time priority) for ``duration``
    seconds on a domain of its own and return its driver's tick trace."""
    pf = d / 'params.yaml'
    pf.write_text('falcon_driver:\n  ros__parameters:\n    servo_priority: 0\n')
    log = d / 'log'
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(140 + os.getpid() % 50),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [str(Path(sys.executable).parent / 'haptic-anfis'), 'launch', '--duration',
           str(duration), '--nodes', 'falcon_driver,contact_detector,force_server', '--localhost',
           '--graph-priority', '0', '--params-file', str(pf), '--log-dir', str(log)]
    subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=duration + 900,
                   check=True)
    return log / 'falcon_driver_trace.npz'


def add_trace_arguments(ap: argparse.ArgumentParser, seconds: float) -> None:
    """``--trace``, ``--start`` and ``--seconds``: the part of a servo tick trace a benchmark
    replays (:func:`trace_window`)."""
    ap.add_argument('--trace', type=Path, help='a falcon_driver tick trace (.npz; default: a '
                                               'launch of --seconds + 10 s, no real-time priority)')
    ap.add_argument('--start', type=float, default=30.0,
                    help='seconds into the trace to start (default 30: past the start-up)')
    ap.add_argument('--seconds', type=float, default=seconds,
                    help=f'seconds of trace (default {seconds:g})')


def trace_window(a: argparse.Namespace) -> tuple[str, float, np.ndarray, np.ndarray]:
    """(the trace's file name, the start used [s], tick times (n,) [s], probe positions (n, 3)
    [m], tissue frame) of ``a.seconds`` of ``a.trace`` from ``a.start``
    (:func:`add_trace_arguments`; without a trace: a session of its own, from 5 s), the ticks
    with the safety layer off left out."""
    start = a.start if a.trace is not None else min(a.start, 5.0)
    with tempfile.TemporaryDirectory(prefix='bench-trace-') as tmp:
        trace = a.trace or session_trace(start + a.seconds + 5.0, Path(tmp))
        rows, _ = load_trace(trace)
    rows = rows[rows[:, 7] != DISABLED]
    t = rows[:, 0] - rows[0, 0]
    rows = rows[(t >= start) & (t < start + a.seconds)]
    if not len(rows):
        raise SystemExit(f'{trace}: no ticks between {start:g} and {start + a.seconds:g} s')
    return trace.name, start, rows[:, 0], np.ascontiguousarray(rows[:, 1:4])


def models_along(positions: np.ndarray, contact_overrides: dict | None = None
                 ) -> tuple[list, np.ndarray, np.ndarray]:
    """(local model values per pose, ideal force (n, 3) [N], in contact (n,)) as the contact
    detector and force server make them (default parameters, the detector's overridden by
    ``contact_overrides``)."""
    cp, tracker, _, model = build_pipeline((), contact_overrides)
    frame = cp['frame_id']
    models, F = [], np.zeros((len(positions), 3))
    contact = np.zeros(len(positions), dtype=bool)
    for i, p in enumerate(positions):
        v, c, _ = contact_values(tracker, frame, frame, p)
        ahead = approach_values(tracker, c, tuple(p), cp['approach_distance'])
        F[i], values, _ = local_model_from_contact(model, v, approach=ahead)
        models.append(values)
        contact[i] = c is not None and c.in_contact
    return models, F, contact


def rendered(models: list, positions: np.ndarray, times: np.ndarray, age: int,
             symmetric_only: bool, **renderer_kw) -> np.ndarray:
    """The force at every pose from the model made ``age`` poses earlier (the first pose's
    model for the first ``age``); ``renderer_kw``: :class:`LocalModelRenderer`'s arguments."""
    r = LocalModelRenderer(validity_time=1e9, **renderer_kw)
    out = np.zeros((len(positions), 3))
    for i, p in enumerate(positions):
        j = max(i - age, 0)
        v = models[j]
        if symmetric_only:
            v = [*v[:6], *symmetric_part(v[6:15]), *v[15:]]
        r.offer_values(v, times[j], checked=True)
        f, _ = r.render(p, times[i])
        out[i] = f if f is not None else 0.0
    return out


def guard_figures(models: list, contact: np.ndarray) -> list[str]:
    """Lines on what the stiffness guard leaves of the contact models' K: the symmetric part's
    positive eigenvalues it clips, the skew part it keeps, and the share with a rotating mode
    (a held model renders those without the skew part)."""
    top, skew, rotating = [], [], 0
    bound = LocalModelRenderer().max_stiffness  # the guard as the renderer here applies it
    for values, c in zip(models, contact):
        if not c:
            continue
        k = values[6:15]
        top.append(np.linalg.eigvalsh(np.reshape(symmetric_part(k), (3, 3)))[-1])
        skew.append(np.linalg.norm(skew_vector(k)))
        rotating += rotating_mode(condition_stiffness_values(k, bound)[0])
    if not top:
        return ['no contact model']
    p = lambda a, q: float(np.percentile(a, q))  # noqa: E731
    return [f'{len(top)} contact models: the symmetric part\'s largest eigenvalue (clipped to 0 '
            f'when positive) p50 {p(top, 50):.1f}, p99 {p(top, 99):.1f} N/m; the skew part |w| '
            f'p50 {p(skew, 50):.1f}, p99 {p(skew, 99):.1f} N/m; with a rotating mode after the '
            f'guard (held: rendered without the skew part) {100 * rotating / len(top):.0f} %']


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=15.0, help='seconds of session (default 15)')
    ap.add_argument('--trace', type=Path, help='a falcon_driver tick trace instead of a session')
    ap.add_argument('--no-page', action='store_true', help='print only')
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix='bench-model-age-') as tmp:
        trace = args.trace or session_trace(args.duration, Path(tmp))
        rows, _ = load_trace(trace)
    rows = rows[rows[:, 7] != DISABLED]
    times, positions = rows[:, 0], np.ascontiguousarray(rows[:, 1:4])
    models, F, contact = models_along(positions)
    rms = float(np.sqrt(np.mean(np.sum(F[contact] ** 2, axis=1))))
    speed = np.linalg.norm(np.diff(positions, axis=0), axis=1) / np.diff(times)
    lines = [f'{len(rows)} ticks, {int(contact.sum())} in contact, RMS ideal force {rms:.3f} N, '
             f'probe speed p50 {np.median(speed) * 1e3:.0f} mm/s, p99 '
             f'{np.percentile(speed, 99) * 1e3:.0f} mm/s', '',
             '| model age (ms) | error, symmetric part only (before) (%) | max (mN) '
             '| error, with the skew part (shipped) (%) | max (mN) | ratio |',
             '|---|---|---|---|---|---|']
    for age in AGES_MS:
        cells = []
        for sym in (True, False):
            e = rendered(models, positions, times, age, sym)[contact] - F[contact]
            n = np.linalg.norm(e, axis=1)
            cells.append((100 * np.sqrt(np.mean(n ** 2)) / rms, 1e3 * n.max()))
        (a, am), (b, bm) = cells
        lines.append(f'| {age} | {a:.3f} | {am:.1f} | {b:.3f} | {bm:.1f} | '
                     f'{a / b if b > 0 else float("inf"):.1f} |')
    lines += ['', *guard_figures(models, contact)]
    text = '\n'.join(lines)
    print(text)
    if not args.no_page:
        body = (text + '\n\nAges are in servo ticks (1 ms each at the nominal rate). The ideal'
                " force is the force server's at the pose itself; 0 ms age renders it exactly."
                ' Targets (issue 32): applied-force error <= 0.2 % quiet, <= 2 % loaded.\n')
        write_page('model_age', 'Local model error by model age', body)
    return 0


if __name__ == '__main__':
    sys.exit(main())

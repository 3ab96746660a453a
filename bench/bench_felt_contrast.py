"""What the hand feels over each lesion: the applied force's contrast against the FE's, per
lesion and depth, and the ticks at the device's clamp, through the whole chain.

For every ready case, the simulated hand presses straight in (along the contact detector's
indentation direction, -x) over each lesion's loading point and over its mirror point (-y, -z),
and over the case's stiffest loading point (where the FE force at the deepest trained depth is
largest: where the clamp is met first), from 5 mm above the skin until the probe is past the
FE's deepest trained depth (16 mm). Each press runs the driver's compiled servo tick
(``NativeServoLoop.tick``: the simulated Falcon's hand, the local model with its passivity bound
and stiffness guard, the safety layer's rate limit and clamp) at 1 kHz, tick by tick; the local
model it renders is the force server's (the case's contact surface and force model,
:func:`~haptic_anfis.pipeline.force.local_model_from_contact`) made at the previous tick's pose,
as in a quiet session. The force applied is the device's, divided by the force scale (the
tissue force the hand is given to feel, as the driver's gauge shows it).

Felt contrast at depth d: |F_applied| over the lesion / over the mirror point - 1, each read at
the tick where the probe's depth first reaches d; FE contrast: the FE dataset's |F| at the two
loading points at d; model contrast: the case's force model at the same two points and depth
(what the chain is given to render: felt vs model isolates the chain, FE vs model the model's own
error). Clamped ticks: ticks with the device force at the clamp (within 1e-6) while
the probe is in contact and no deeper than the deepest trained depth. Rows for the force scale
of :mod:`haptic_anfis.cases.force_mapping` ("case") and one to one ("1.0", the old default).

    .venv/bin/python bench/bench_felt_contrast.py [--cases a,b] [--scales case,1.0] [--no-page]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from harness import write_page
from haptic_anfis.cases import library
from haptic_anfis.cases.force_mapping import case_force_mapping
from haptic_anfis.cases.grading import PALPABLE_PCT
from haptic_anfis.device import HandParams, PalpationScript, WorkspaceMapping
from haptic_anfis.device import native_tick as nt
from haptic_anfis.device.servo_native import NativeServoLoop
from haptic_anfis.nodes.falcon_driver import PARAMS
from haptic_anfis.nodes.parameters import default_of
from haptic_anfis.nodes.resim import build_pipeline
from haptic_anfis.pipeline.contact import approach_values, contact_values
from haptic_anfis.pipeline.force import local_model_from_contact
from haptic_anfis.tissue.dataset import load_dataset
from haptic_anfis.tissue.scene import surface_height

#: [m] the hand starts this far above the skin
START_ABOVE = 0.005
#: [m/s] the hand target's speed into the tissue (tissue frame): slow beside the 1 kHz loop
PRESS_SPEED = 0.04
#: [m] the hand's target goes this far past the deepest trained depth: enough for the probe to
#: pass it at the clamp (8.9 N on the hand's 1000 N/m spring is 13.4 mm of tissue)
PAST_DEEPEST = 0.016
#: relative: the felt contrast's bar against the FE's
CONTRAST_TOLERANCE = 0.10


def _d(name: str):
    return default_of(PARAMS, name)


def driver_loop(script: PalpationScript, force_scale: float) -> NativeServoLoop:
    """The compiled loop as falcon_driver builds it by default, at ``force_scale``."""
    mapping = WorkspaceMapping(_d('workspace_scale'), tuple(_d('workspace_offset')), force_scale)
    return NativeServoLoop(
        script, mapping, HandParams(_d('hand_mass'), _d('hand_stiffness'), _d('hand_damping')),
        rate=_d('rate'), mode='local_model', max_force=_d('max_force'),
        max_force_rate=_d('max_force_rate'), watchdog_timeout=_d('watchdog_timeout'),
        max_stiffness=_d('max_stiffness'), damping=_d('passivity_damping'),
        validity_time=_d('model_validity_time'), validity_radius=_d('model_validity_radius'),
        approach_radius=_d('model_approach_radius'), hold_time=_d('model_hold_time'),
        hold_radius=_d('model_hold_radius'), blend_time=_d('model_blend_time'),
        passivity_window=_d('passivity_window'))


def press(pipeline, yz: tuple[float, float], radii, deepest: float, force_scale: float
          ) -> dict[str, np.ndarray]:
    """One straight press at ``yz`` [m]: per tick the probe depth [m], in contact, the applied
    tissue force |F| [N] and whether the device force was at the clamp."""
    pc, tracker, _, model = pipeline
    tracker.reset()
    skin = float(surface_height(np.array(yz[0]), np.array(yz[1]), radii))
    top, bottom = skin + START_ABOVE, skin - deepest - PAST_DEEPEST
    dur = (top - bottom) / PRESS_SPEED
    script = PalpationScript(np.array([0.0, 0.3, 0.3 + dur]),
                             np.array([[top, *yz], [top, *yz], [bottom, *yz]]),
                             np.array([False, True]), loop=False)
    lp = driver_loop(script, force_scale)
    lp.safety.start()
    frame, dt, S = pc['frame_id'], lp.period, nt.S
    n = int(round((0.3 + dur) / dt))
    depth, contact = np.zeros(n), np.zeros(n, dtype=bool)
    force, clamped = np.zeros(n), np.zeros(n, dtype=bool)
    mx = lp.cfg[nt.CFG.max_force]
    for i in range(n):
        t = 1.0 + i * dt
        f = lp.tick(t)
        p = lp.mapping.to_tissue(tuple(lp.st[S.x0:S.x0 + 3]))
        v, c, _ = contact_values(tracker, frame, frame, p)
        ahead = approach_values(tracker, c, tuple(p), pc['approach_distance'])
        _, values, _ = local_model_from_contact(model, v, approach=ahead)
        lp.renderer.offer_values(values, t)   # answered for the next tick, as a quiet graph
        fn = float(np.linalg.norm(f))
        depth[i], contact[i] = v[3], v[7] > 0.5
        force[i], clamped[i] = fn / force_scale, fn >= mx - 1e-6
    return {'depth': depth, 'contact': contact, 'force': force, 'clamped': clamped}


def felt_at(p: dict[str, np.ndarray], depth: float) -> float | None:
    """|F| [N] the hand was given at the first tick whose depth reached ``depth`` [m]."""
    k = np.flatnonzero(p['contact'] & (p['depth'] >= depth - 1e-6))
    return None if not len(k) else float(p['force'][k[0]])


def clamped_within(p: dict[str, np.ndarray], deepest: float) -> int:
    return int(np.sum(p['clamped'] & p['contact'] & (p['depth'] <= deepest + 1e-9)))


def fe_at(ds, yz, depth: float) -> float | None:
    sel = ((np.abs(ds.X[:, 1] - yz[0]) < 1e-6) & (np.abs(ds.X[:, 2] - yz[1]) < 1e-6)
           & (np.abs(ds.X[:, 3] - depth) < 1e-9))
    return float(np.linalg.norm(ds.Y[sel][0])) if sel.any() else None


def over_and_mirror(ds, centre_yz) -> tuple[tuple[float, float], tuple[float, float]]:
    """The loading point over the lesion (its centre, else the nearest with a mirror point in
    the data) and its mirror point (-y, -z)."""
    yz = np.unique(np.round(ds.X[:, 1:3], 9), axis=0)
    d = np.hypot(yz[:, 0] - centre_yz[0], yz[:, 1] - centre_yz[1])
    d[[not np.any(np.hypot(*(yz + q).T) < 1e-6) for q in yz]] = np.inf
    k = int(np.argmin(d))
    return (float(yz[k, 0]), float(yz[k, 1])), (-float(yz[k, 0]), -float(yz[k, 1]))


def model_at(model, radii, yz, depth: float) -> float:
    """|F| [N] the case's force model gives at the surface point over ``yz`` [m], ``depth``."""
    x = float(surface_height(np.array(yz[0]), np.array(yz[1]), radii))
    return float(np.linalg.norm(model.predict(np.array([[x, yz[0], yz[1], depth]]))[0]))


def stiffest_point(ds, palpable_radius: float, deepest: float) -> tuple[float, float]:
    sel = (np.abs(ds.X[:, 3] - deepest) < 1e-9) & (np.hypot(ds.X[:, 1], ds.X[:, 2])
                                                   <= palpable_radius + 1e-9)
    k = np.flatnonzero(sel)[int(np.argmax(np.linalg.norm(ds.Y[sel], axis=1)))]
    return float(ds.X[k, 1]), float(ds.X[k, 2])


def pct(v: float | None) -> str:
    return '-' if v is None else f'{100 * v:+.1f}'


def measure_case(case, scales: list[str]) -> tuple[list[str], list[str], list[dict]]:
    """(contrast rows, clamp rows, findings) of one case for each scale ('case' or a number)."""
    ds = load_dataset(case.dataset_path)
    sc = case.scene
    depths = sorted({round(float(d), 6) for d in ds.X[:, 3]})
    deepest = depths[-1]
    pipeline = build_pipeline((), {'mesh_path': str(case.mesh_path), 'mesh_unit': 'mm'},
                              {'model_path': str(case.model_path)})
    mapping = case_force_mapping(case)
    rows, clamps, found = [], [], []
    for scale in scales:
        s = mapping.force_scale if scale == 'case' else float(scale)
        label = f'{s:.3f}' + (' (case)' if scale == 'case' else '')
        pressed = {'stiffest': press(pipeline, stiffest_point(ds, sc.palpable_radius, deepest),
                                     sc.radii, deepest, s)}
        for t in sc.tumours:
            over, mirror = over_and_mirror(ds, (t.centre[1], t.centre[2]))
            po = press(pipeline, over, sc.radii, deepest, s)
            pm = press(pipeline, mirror, sc.radii, deepest, s)
            pressed[t.name], pressed[t.name + ' mirror'] = po, pm
            for d in depths:
                fo, fm = felt_at(po, d), felt_at(pm, d)
                eo, em = fe_at(ds, over, d), fe_at(ds, mirror, d)
                felt = None if fo is None or fm is None else fo / fm - 1
                fe = None if eo is None or em is None else eo / em - 1
                err = None if felt is None or fe is None or abs(fe) < 1e-12 else felt / fe - 1
                ok = err is not None and abs(err) <= CONTRAST_TOLERANCE
                mo, mm = model_at(pipeline[3], sc.radii, over, d), model_at(pipeline[3], sc.radii,
                                                                            mirror, d)
                mod = mo / mm - 1
                chain = None if felt is None or abs(mod) < 1e-12 else felt / mod - 1
                palp = fe is not None and 100 * fe >= PALPABLE_PCT
                rows.append(f'| {case.name} | {t.name} | {label} | {d * 1e3:g} | {pct(fe)} | '
                            f'{pct(mod)} | {pct(felt)} | {pct(err)} | {pct(chain)} | '
                            f'{"ok" if ok else "**no**"} | {"yes" if palp else "no"} | '
                            f'{"-" if fo is None else f"{fo:.2f}"} |')
                found.append({'case': case.name, 'lesion': t.name, 'scale': scale, 'depth': d,
                              'fe': fe, 'felt': felt, 'ok': ok, 'palpable': palp,
                              'chain_ok': chain is not None
                              and abs(chain) <= CONTRAST_TOLERANCE})
        n_clamped = {k: clamped_within(p, deepest) for k, p in pressed.items()}
        reach = max(float(p['depth'][p['contact']].max(initial=0.0)) for p in pressed.values())
        peak = max(float(p['force'][p['contact'] & (p['depth'] <= deepest + 1e-9)].max(
            initial=0.0)) * s for p in pressed.values())
        clamps.append(f'| {case.name} | {label} | {len(pressed)} | {sum(n_clamped.values())} | '
                      f'{peak:.2f} | {reach * 1e3:.1f} |')
        found.append({'case': case.name, 'scale': scale, 'clamped': sum(n_clamped.values())})
    return rows, clamps, found


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--cases', default='', help='comma-separated case names (default: every '
                                                'ready case)')
    ap.add_argument('--scales', default='case,1.0',
                    help="force scales to press with: 'case' (the case's mapping) and/or numbers")
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    lib = library()
    cases = ([lib.get(n) for n in a.cases.split(',') if n] if a.cases else lib.ready())
    scales = [s.strip() for s in a.scales.split(',') if s.strip()]
    t0 = time.perf_counter()
    rows, clamps, found = [], [], []
    for c in cases:
        r, cl, f = measure_case(c, scales)
        rows += r
        clamps += cl
        found += f
        print('\n'.join(cl), flush=True)
    lesion = [f for f in found if 'lesion' in f]
    lines = []
    for scale in scales:
        mine = [f for f in lesion if f['scale'] == scale]
        cl = [f for f in found if f.get('clamped') is not None and f['scale'] == scale]
        palp = [f for f in mine if f['palpable']]
        lines.append(f'- scale {scale}: {sum(f["ok"] for f in mine)} of {len(mine)} lesion x depth '
                     f'rows within {100 * CONTRAST_TOLERANCE:g} % of the FE contrast '
                     f'({sum(f["ok"] for f in palp)} of the {len(palp)} where the FE contrast '
                     f'reaches the {PALPABLE_PCT:g} % palpability threshold; the felt within '
                     f'{100 * CONTRAST_TOLERANCE:g} % of the force model\'s own contrast in '
                     f'{sum(f["chain_ok"] for f in palp)} of those); '
                     f'{sum(1 for f in cl if f["clamped"])} of {len(cl)} cases with a tick at the '
                     f'clamp within the trained depth ({sum(f["clamped"] for f in cl)} ticks)')
    head = ['| case | lesion | force scale | depth (mm) | FE contrast (%) | model contrast (%) | '
            'felt contrast (%) | felt vs FE (%) | felt vs model (%) | felt within 10 % of FE | '
            f'FE >= {PALPABLE_PCT:g} % | felt over lesion (N, tissue) |',
            '|---|---|---|---|---|---|---|---|---|---|---|---|']
    chead = ['| case | force scale | presses | ticks at the clamp within the trained depth | '
             'largest device force within it (N) | deepest probe depth reached (mm) |',
             '|---|---|---|---|---|---|']
    text = '\n'.join(['## Summary', '', *lines, '', '## Clamped ticks', '', *chead, *clamps, '',
                      '## Felt contrast per lesion and depth', '', *head, *rows])
    print(text)
    print(f'{time.perf_counter() - t0:.0f} s', file=sys.stderr)
    if not a.no_page:
        write_page('felt_contrast', 'What the hand feels over each lesion: felt vs FE contrast',
                   __doc__.split('\n\n', 1)[1].split('\n    .venv')[0].strip() + '\n\n' + text
                   + '\n')
    return 0


if __name__ == '__main__':
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())

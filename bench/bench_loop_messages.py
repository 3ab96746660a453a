"""Per-message cost of the haptic loop's Python work, zero-order hold vs local force model.

The servo thread shares its process's GIL with the executor thread that handles the force server's
messages; in one process it also shares it with the contact detector and the force server. Every
microsecond those handlers hold the GIL per pose is taken from the 1 kHz servo thread's budget, so
this bench times each step a pose causes, one at a time, on plain Python (no executor, no DDS):
contact detector (one pose through the tracker,
:func:`haptic_anfis.pipeline.contact.contact_values`), force server (force / local model from a
contact, :mod:`haptic_anfis.pipeline.force`; message fill, serialisation) and driver
(deserialisation, the ``servo_cf`` and ``servo_cf_local`` handlers' bodies), rclpy's
(de)serialisation beside the raw CDR path the loop nodes use (:mod:`haptic_anfis.nodes.cdr`). The
contacts are those of the shipped palpation script pressed into the shipped model.

    .venv/bin/python bench/bench_loop_messages.py [--n 2000]

Printed: µs per message (median of 5 repeats of n calls), never asserted (shared machine).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def timed(fn, items, repeats: int = 5) -> float:
    """Median over ``repeats`` of the mean µs per call of ``fn(item)`` over ``items``."""
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for it in items:
            fn(it)
        runs.append((time.perf_counter() - t0) / len(items) * 1e6)
    runs.sort()
    return runs[len(runs) // 2]


def press_path(n: int) -> list[tuple[float, float, float]]:
    """n probe positions [m]: in from 2 cm out of the shipped surface to 12 mm in along the
    default direction, sliding sideways."""
    import numpy as np
    return [(0.035 + 0.02 - 0.032 * s, 0.01 * np.sin(6 * s), 0.01 * np.cos(5 * s))
            for s in np.linspace(0.0, 1.0, n).tolist()]


def contacts(n: int) -> list[list[float]]:
    """n in-contact contact message values: the press of :func:`press_path` through the contact
    detector's tracker (the tracker's answers)."""
    from haptic_anfis.pipeline.contact import contact_values
    from haptic_anfis.nodes.resim import build_pipeline
    tracker = build_pipeline()[1]  # the contact detector's, from its default parameters
    out = []
    for p in press_path(4 * n):
        v, c, _ = contact_values(tracker, 'tissue', 'tissue', p)
        if c is not None and c.in_contact:
            out.append(v)
    if len(out) < n // 4:
        raise RuntimeError(f'only {len(out)} contacts on the test path')
    return (out * (n // len(out) + 1))[:n]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--n', type=int, default=2000, help='messages per timing')
    a = ap.parse_args()
    import rclpy  # noqa: F401 (message types need it loaded)
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from haptic_anfis.device import PalpationScript, WorkspaceMapping
    from haptic_anfis.device.force_input import ForceInput
    from haptic_anfis import interfaces as ifc
    from haptic_anfis.pipeline import contact as pc, force as pf
    from haptic_anfis.device.local_model import LocalModel
    from haptic_anfis.device.servo_native import NativeServoLoop
    from haptic_anfis.resources import config_file
    from haptic_anfis.nodes.resim import build_pipeline

    _, tracker, _, model = build_pipeline()  # as the nodes build them, default parameters
    cs = contacts(a.n)
    print(f'{len(cs)} in-contact messages, {os.cpu_count()} CPUs, load average '
          f'{os.getloadavg()[0]:.2f} (1 min); µs per message, median of 5')
    rows = []
    path = press_path(a.n)
    rows.append(('detector: contact_values (tracker step)', timed(
        lambda p: pc.contact_values(tracker, 'tissue', 'tissue', p), path)))
    rows.append(('server: force_from_contact (zoh)', timed(
        lambda v: pf.force_from_contact(model, v), cs)))
    rows.append(('server: local_model_from_contact', timed(
        lambda v: pf.local_model_from_contact(model, v), cs)))
    lms = [pf.local_model_from_contact(model, v)[1] for v in cs]
    js = JointState(name=list(ifc.LOCAL_MODEL_FIELDS))

    def fill(v):
        js.position = v
    rows.append(('server: JointState.position = values', timed(fill, lms)))
    if hasattr(ifc, 'local_model_message_names'):
        js.name = ifc.local_model_message_names()
    raw_lm = [serialize_message(JointState(name=js.name, position=v)) for v in lms]
    rows.append(('server: serialise servo_cf_local', timed(
        lambda v: serialize_message(JointState(name=js.name, position=v)), lms)))
    w = WrenchStamped()
    w.header.frame_id = 'tissue'
    raw_w = serialize_message(w)
    rows.append(('server: serialise servo_cf', timed(lambda _: serialize_message(w), lms)))
    rows.append(('driver: deserialise servo_cf_local', timed(
        lambda r: deserialize_message(r, JointState), raw_lm)))
    rows.append(('driver: deserialise servo_cf', timed(
        lambda _: deserialize_message(raw_w, WrenchStamped), lms)))

    try:  # the raw path (nodes/cdr.py) that replaces rclpy's (de)serialisation on the loop
        from haptic_anfis.nodes import cdr
        jw = cdr.JointStateWriter('tissue', ifc.LOCAL_MODEL_FIELDS, len(ifc.LOCAL_MODEL_FIELDS))
        rows.append(('server: cdr JointStateWriter.pack (servo_cf_local)', timed(
            lambda v: jw.pack(1_763_900_000_123_456_789, v), lms)))
        rows.append(('driver: cdr.read_joint_state (servo_cf_local)', timed(
            cdr.read_joint_state, raw_lm)))
        raw_own = [jw.pack(1_763_900_000_123_456_789, v) for v in lms]
        rows.append(('driver: JointStateWriter.read (own layout)', timed(jw.read, raw_own)))
        rows.append(('driver: cdr.read_wrench_stamped (servo_cf)', timed(
            lambda _: cdr.read_wrench_stamped(raw_w), lms)))
    except ImportError:
        pass
    now = [0.0]
    mapping = WorkspaceMapping(1.5, (0.03, 0.0, 0.0))

    def driver_input(mode: str) -> ForceInput:
        """The driver's force input over a compiled loop's buffers (the loop is not started:
        only the Python side of a message is timed)."""
        loop = NativeServoLoop(PalpationScript.from_yaml(config_file('palpation.yaml')),
                               mapping, mode=mode)
        loop.safety.start(0.0)
        return ForceInput(loop.safety, mapping, loop.renderer, mode)
    inp = driver_input('local_model')
    # every message answers a recorded pose 1 ms old
    msgs = [deserialize_message(r, JointState) for r in raw_lm]

    def on_lm(msg, i=[0]):  # what FalconDriver._on_local_model does with a message
        i[0] += 1
        now[0] = i[0] * 1e-3
        inp.on_pose(i[0], now[0] - 1e-3)
        inp.model_values(msg.position, i[0], 'tissue', now[0])
    rows.append(('driver: servo_cf_local handler body', timed(on_lm, msgs)))
    rows.append(('driver: servo_cf handler body (local mode)', timed(
        lambda _: inp.command((0.1, 0.2, 0.3), 1, 'tissue', now[0]), lms)))
    models = [LocalModel.from_values(v) for v in lms]
    r = inp.renderer
    rows.append(('driver: NativeRenderer.offer_values', timed(
        lambda v: r.offer_values(v, 0.0, checked=True), [m.position for m in msgs])))
    rows.append(('driver: LocalModel.check', timed(lambda m: m.check(), models)))
    rows.append(('driver: LocalModel.from_values', timed(LocalModel.from_values, lms)))
    zi = driver_input('zoh')

    def on_cmd(_, i=[0]):
        i[0] += 1
        zi.on_pose(i[0], i[0] * 1e-3 - 1e-3)
        zi.command((0.1, 0.2, 0.3), i[0], 'tissue', i[0] * 1e-3)
    rows.append(('driver: servo_cf handler body (zoh mode)', timed(on_cmd, lms)))
    for name, us in rows:
        print(f'  {name:<46} {us:8.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

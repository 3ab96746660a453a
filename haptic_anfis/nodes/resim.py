"""Re-simulation: recorded poses through the CURRENT contact tracker and force model, compared with
the recorded force commands (offline, no ROS publishing). It lives with the nodes because it
resolves their parameters (declarations, ``--params-file`` YAMLs); the bag layer imports no node.

The tracker and model are built by the nodes' own construction code
(:func:`haptic_anfis.pipeline.contact.make_tracker`, :func:`haptic_anfis.pipeline.force.
load_model`) from the same parameters (defaults, ``--params-file`` YAMLs, overrides), and each pose
goes through the same per-message functions the nodes run
(:func:`haptic_anfis.pipeline.replay.pose_to_force`: ``contact_values`` then
``force_from_contact``). The tracker is stateful, so it must see exactly the poses the recorded
detector saw: the recorded contact messages carry their pose's stamp, so when the contact topic is
in the bag only those poses are fed (a 1 kHz detector that fell behind skipped some poses,
keep-last-1 QoS); otherwise every pose. Identical code and parameters reproduce the recorded
wrenches exactly (difference 0 N).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from . import contact_detector as cd, force_server as fs
from .. import interfaces as ifc
from ..bag.errors import BagError
from ..bag.reader import read_messages
from ..bag.topics import JOINT_STATE_TYPE, POSE_TYPE, WRENCH_TYPE, absolute
from ..cases import resolve_case
from ..pipeline.contact import make_tracker
from ..pipeline.force import load_model
from ..pipeline.replay import pose_to_force
from ._case import apply_case
from .parameter_files import resolve_parameters
from .parameters import CASE_PARAMS


def _ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


@dataclass
class ResimResult:
    path: Path
    model_path: str
    poses: int = 0                 # recorded poses
    fed: int = 0                   # poses fed to the tracker
    skipped: int = 0               # recorded poses the recorded detector never answered
    missing_poses: int = 0         # recorded contacts whose pose the bag lacks
    wrenches: int = 0              # recorded force commands compared
    max_diff_N: float = 0.0        # max |F_recomputed - F_recorded| (Euclidean norm)
    rms_diff_N: float = 0.0
    max_axis_diff_N: tuple = (0.0, 0.0, 0.0)
    contacts: int = 0              # recorded contact messages compared
    max_contact_diff: float = 0.0  # max abs difference over the contact fields (m or 0/1)
    in_contact: int = 0            # recomputed poses in contact
    max_force_N: float = 0.0       # largest recomputed force
    recomputed: dict = field(default_factory=dict, repr=False)  # stamp -> (fx, fy, fz)

    def format(self) -> str:
        ax = ', '.join(f'{v:.3g}' for v in self.max_axis_diff_N)
        lines = [f're-simulation of {self.path} with model {self.model_path}',
                 f'  poses          {self.poses} recorded, {self.fed} fed to the tracker '
                 f'({self.skipped} skipped by the recorded detector, {self.missing_poses} missing)',
                 f'  contact        {self.contacts} compared, max field difference '
                 f'{self.max_contact_diff:.3g}; {self.in_contact} poses in contact',
                 f'  wrench         {self.wrenches} compared: max |dF| {self.max_diff_N:.3g} N, '
                 f'RMS {self.rms_diff_N:.3g} N (per axis max {ax} N); '
                 f'largest recomputed force {self.max_force_N:.2f} N']
        return '\n'.join(lines)


def build_pipeline(params_files=(), contact_overrides=None, force_overrides=None):
    """(contact_detector params, tracker, model path, model) as the nodes would build them,
    with the case their ``case`` / ``random_case_seed`` parameters select (files or overrides)
    in place of their own mesh and model files, as the nodes take it.

    Raises:
        ParameterError: a bad parameter; CaseError: an unknown case.
    """
    pc = resolve_parameters(cd.PARAMS + CASE_PARAMS, 'contact_detector', params_files,
                            contact_overrides)
    pf = resolve_parameters(fs.PARAMS + CASE_PARAMS, 'force_server', params_files,
                            force_overrides)
    pc = apply_case(pc, resolve_case(pc['case'], pc['random_case_seed']))
    pf = apply_case(pf, resolve_case(pf['case'], pf['random_case_seed']))
    tracker = make_tracker(pc)
    model_path, model = load_model(pf)
    return pc, tracker, model_path, model


def resimulate(path: str | Path, params_files=(), contact_overrides=None, force_overrides=None,
               pose_topic: str = ifc.TOPIC_POSE, contact_topic: str = ifc.TOPIC_CONTACT,
               wrench_topic: str = ifc.TOPIC_COMMAND) -> ResimResult:
    """Feed the bag's poses through the current tracker and model; compare (see module doc)."""
    p = Path(path)
    tp, tc, tw = absolute(pose_topic), absolute(contact_topic), absolute(wrench_topic)
    poses, contacts, wrenches = [], {}, {}
    seen = set()
    for topic, _, _, msg in read_messages(p, expect_types={tp: POSE_TYPE, tc: JOINT_STATE_TYPE,
                                                           tw: WRENCH_TYPE}):
        seen.add(topic)
        if topic == tp:
            q = msg.pose.position
            poses.append((_ns(msg.header.stamp), msg.header.frame_id, (q.x, q.y, q.z)))
        elif topic == tc:
            contacts[_ns(msg.header.stamp)] = [float(v) for v in msg.position]
        elif topic == tw:
            f = msg.wrench.force
            wrenches[_ns(msg.header.stamp)] = (f.x, f.y, f.z)
    if tp not in seen:
        raise BagError(f'{p}: no {tp} messages ({POSE_TYPE}) to re-simulate')
    pc, tracker, model_path, model = build_pipeline(params_files, contact_overrides,
                                                    force_overrides)
    poses.sort(key=lambda r: r[0])
    r = ResimResult(p, str(model_path), poses=len(poses))
    if contacts:
        pose_stamps = {s for s, _, _ in poses}
        r.missing_poses = sum(1 for s in contacts if s not in pose_stamps)
        feed = [x for x in poses if x[0] in contacts]
        r.skipped = len(poses) - len(feed)
    else:
        feed = poses
    frame_id = pc['frame_id']
    sq = 0.0
    axis = [0.0, 0.0, 0.0]
    for stamp, frame, xyz in feed:
        values, c, (fx, fy, fz), _ = pose_to_force(tracker, model, frame_id, frame, xyz)
        r.fed += 1
        r.recomputed[stamp] = (fx, fy, fz)
        if c is not None and c.in_contact:
            r.in_contact += 1
        r.max_force_N = max(r.max_force_N, math.sqrt(fx * fx + fy * fy + fz * fz))
        rec_c = contacts.get(stamp)
        if rec_c is not None:
            r.contacts += 1
            if not ifc.is_contact_values(rec_c):  # an older 9-value contact compares its 9
                r.max_contact_diff = math.inf
            else:
                r.max_contact_diff = max(r.max_contact_diff,
                                         max(abs(a - b) for a, b in zip(values, rec_c)))
        rec_w = wrenches.get(stamp)
        if rec_w is not None:
            d = (fx - rec_w[0], fy - rec_w[1], fz - rec_w[2])
            n2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            sq += n2
            r.wrenches += 1
            r.max_diff_N = max(r.max_diff_N, math.sqrt(n2))
            axis = [max(a, abs(v)) for a, v in zip(axis, d)]
    r.max_axis_diff_N = tuple(axis)
    r.rms_diff_N = math.sqrt(sq / r.wrenches) if r.wrenches else 0.0
    return r

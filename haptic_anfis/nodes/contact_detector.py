"""``contact_detector``: probe pose in, contact out (:mod:`haptic_anfis.contact`).

Subscribes to ``falcon/measured_cp`` (``geometry_msgs/PoseStamped``, tissue frame); for each pose
advances a :class:`~haptic_anfis.contact.ContactTracker` on the tissue surface (loaded once at
start) and publishes ``contact`` (``sensor_msgs/JointState``, layout in
:mod:`haptic_anfis.nodes.interfaces`) stamped with the pose's stamp. A NaN/Inf pose or one in
another frame is logged (throttled) and answered with "no contact"; the tracker is reset so the
next good pose cannot start a contact from inside the tissue.
"""
from __future__ import annotations

import math
from array import array

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from ..contact import ContactDetector, ContactTracker, ellipsoid_dome
from ..contact.approach import surface_ahead
from ..contact.proxy import FREE
from ..tissue.dataset import DATA_DIR
from . import interfaces as ifc
from ._case import CASE_PARAMS, apply_case, declare_case  # noqa: F401 (CASE_PARAMS: in config)
from ._common import (LOOP_QOS, Param, declare_parameters, finite_vector, non_negative, one_of,
                      positive, run_node)

#: Surface mesh of the default FE scene (config/scenes/default.yaml), in millimetres.
DEFAULT_SURFACE = DATA_DIR / 'default_surface.stl'

MESH_PARAMS = [
    Param('mesh_path', '', "tissue surface mesh file (STL, OBJ, PLY...; '' = the shipped surface "
          "of the default FE scene, so forces and surface agree by construction; 'dome' = a "
          'built-in semi-ellipsoid with dome_radii)'),
    Param('mesh_unit', 'mm', "length unit of mesh_path: 'mm' or 'm'", one_of('mm', 'm')),
    Param('dome_radii', [0.045, 0.070, 0.070], "radii (x, y, z) [m] of the mesh_path 'dome'",
          finite_vector(3, positive=True)),
    Param('frame_id', 'tissue', 'the tissue frame: poses in other frames are rejected; frame of '
          'the published messages'),
]

PARAMS = MESH_PARAMS + [
    Param('direction', [-1.0, 0.0, 0.0], 'indentation direction into the tissue (normalised; '
          '[0.0, 0.0, 0.0] = along the surface normal at entry)', finite_vector(3)),
    Param('max_step', 0.01, 'largest probe motion between two poses the tracker follows [m]',
          positive),
    Param('max_depth', 0.0, 'cap on the reported depth [m] (0 = only the tissue thickness caps it)',
          non_negative),
    Param('approach_distance', 0.005, 'while the probe is free and a front surface lies at most '
          'this far [m] ahead along the direction, the contact message carries that surface point '
          'and its normal (the approach fields, in effort) so the force server can send the '
          'plane before contact (0 = off)', non_negative),
]


def load_surface(node, p: dict):
    """The tissue mesh named by the mesh parameters (metres, tissue frame)."""
    from ..contact import load_mesh
    if p['mesh_path'] == 'dome':
        return ellipsoid_dome(tuple(p['dome_radii']))
    path, unit = (p['mesh_path'], p['mesh_unit']) if p['mesh_path'] else (DEFAULT_SURFACE, 'mm')
    mesh = load_mesh(path, unit=unit)
    # Files such as STL store every triangle's corners separately: join equal vertices so the
    # surface is connected (same faces and coordinates, so the same contact answers).
    mesh.merge_vertices()
    return mesh


def make_tracker(p: dict) -> ContactTracker:
    """The node's contact tracker from its parameter values ``p`` (also used by the bag
    re-simulation, so a replay is configured exactly like the node)."""
    mesh = load_surface(None, p)
    d = p['direction']
    detector = ContactDetector(mesh, direction=None if not any(d) else d)
    return ContactTracker(detector, max_step=p['max_step'], max_depth=p['max_depth'] or None)


def contact_values(tracker: ContactTracker, frame_id: str, pose_frame: str, xyz):
    """One pose through the tracker: ``(position list of the contact message, TrackedContact or
    None, error or None)``. A pose in another frame or with NaN/Inf gives "no contact" (zeros)
    and resets the tracker, so the next good pose cannot start a contact from inside."""
    if pose_frame != frame_id:
        tracker.reset()
        return [0.0] * len(ifc.CONTACT_FIELDS), None, \
            f'pose in frame {pose_frame!r}, expected {frame_id!r}'
    try:
        c = tracker.update(xyz)
    except ValueError as exc:  # NaN/Inf pose: tracker reset, no contact
        tracker.reset()
        return [0.0] * len(ifc.CONTACT_FIELDS), None, str(exc)
    cp, dv, nv = c.contact_point, c.direction, c.normal
    return [float(cp[0]), float(cp[1]), float(cp[2]), float(c.depth),
            float(dv[0]), float(dv[1]), float(dv[2]),
            1.0 if c.in_contact else 0.0, 1.0 if c.saturated else 0.0,
            float(nv[0]), float(nv[1]), float(nv[2])], c, None


def approach_values(tracker: ContactTracker, c, p, max_distance: float) -> list[float]:
    """The approach fields (:data:`~.interfaces.APPROACH_FIELDS`: surface point ahead [m], outward
    normal there) for the tracker's answer ``c`` at the probe position ``p`` (3,) [m]: only while
    free (not in contact, not rejected) and a front surface lies within ``max_distance`` [m] along
    the indentation direction; else [] (:func:`~haptic_anfis.contact.approach.surface_ahead`)."""
    if c is None or c.state != FREE or max_distance <= 0.0:
        return []
    a = surface_ahead(tracker.detector, p, tracker.detector.direction, max_distance)
    if a is None:
        return []
    s, n, _ = a
    return [float(s[0]), float(s[1]), float(s[2]), float(n[0]), float(n[1]), float(n[2])]


class ContactDetectorNode(Node):
    def __init__(self, name: str = 'contact_detector', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        p = self.params = apply_case(p, declare_case(self, self.switch_case))
        self.frame_id = p['frame_id']
        self.tracker = make_tracker(p)
        self.detector = self.tracker.detector
        d = p['direction']
        self.pub = self.create_publisher(JointState, ifc.TOPIC_CONTACT, LOOP_QOS)
        self.sub = self.create_subscription(PoseStamped, ifc.TOPIC_POSE, self._on_pose, LOOP_QOS)
        self._msg = JointState()
        self._msg.name = list(ifc.CONTACT_FIELDS)
        self._msg.header.frame_id = self.frame_id
        self.approach_distance = p['approach_distance']
        self.n_poses = self.n_contact = self.n_bad = 0
        self.max_depth_seen = 0.0
        self.last = None
        self.get_logger().info(
            f"tissue mesh {p['mesh_path'] or DEFAULT_SURFACE}: "
            f'{self.detector.n_faces} faces; direction {d}')

    def switch_case(self, case) -> None:
        """Swap in the surface of ``case`` (None: the own mesh parameters). The new tracker starts
        free, so a probe already inside the new surface makes no contact until it re-enters."""
        params = apply_case(self.params, case, self.own_params)
        tracker = make_tracker(params)  # raises on a bad mesh: nothing changed
        self.params, self.tracker, self.detector = params, tracker, tracker.detector

    def _on_pose(self, msg: PoseStamped) -> None:
        self.n_poses += 1
        q = msg.pose.position
        out = self._msg
        out.header.stamp = msg.header.stamp
        values, c, error = contact_values(self.tracker, self.frame_id, msg.header.frame_id,
                                          (q.x, q.y, q.z))
        out.position = array('d', values)  # an array skips the setter's per-element checks
        out.effort = array('d', approach_values(self.tracker, c, (q.x, q.y, q.z),
                                                self.approach_distance))
        if error is not None:
            self._bad(error)
        else:
            if c.in_contact:
                self.n_contact += 1
                if c.depth > self.max_depth_seen:
                    self.max_depth_seen = c.depth
            self.last = c
        self.pub.publish(out)

    def _bad(self, why: str) -> None:
        self.n_bad += 1
        self.get_logger().warning(f'bad pose ({why}): publishing no contact',
                                  throttle_duration_sec=1.0)

    def summary(self) -> dict:
        return {'poses': self.n_poses, 'in_contact': self.n_contact,
                'contact_fraction': self.n_contact / self.n_poses if self.n_poses else 0.0,
                'max_depth_mm': self.max_depth_seen * 1e3, 'bad_poses': self.n_bad}


def main(args=None) -> None:
    raise SystemExit(run_node(ContactDetectorNode, args))


if __name__ == '__main__':
    main()

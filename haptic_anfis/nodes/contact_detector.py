"""``contact_detector``: probe pose in, contact out (:mod:`haptic_anfis.contact`).

Subscribes to ``falcon/measured_cp`` (``geometry_msgs/PoseStamped``, tissue frame); for each pose
advances a :class:`~haptic_anfis.contact.ContactTracker` on the tissue surface (loaded once at
start) and publishes ``contact`` (``sensor_msgs/JointState``, layout in
:mod:`haptic_anfis.interfaces`) stamped with the pose's stamp. A NaN/Inf pose or one in
another frame is logged (throttled) and answered with "no contact"; the tracker is reset so the
next good pose cannot start a contact from inside the tissue.

The per-message work is :mod:`haptic_anfis.pipeline.contact` (``contact_values``,
``approach_values``, ``make_tracker``); this node wires it to the topics, its parameters and the
case switch.
"""
from __future__ import annotations

from array import array

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState

from ..pipeline.contact import DEFAULT_SURFACE, approach_values, contact_values, make_tracker
from .. import interfaces as ifc
from ._case import apply_case, declare_case
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import Param, declare_parameters, finite_vector, non_negative, one_of, positive
from .runtime import LOOP_QOS, run_node
from .base import HapticNode

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
    Param('approach_distance', 0.015, 'while the probe is free and a front surface lies at most '
          'this far [m] ahead along the direction, the contact message carries that surface point '
          'and its normal (the approach fields, in effort) so the force server can send the '
          'plane before contact (0 = off); 15 mm: a 30 mm/s press starts from the plane with '
          'the graph up to 0.5 s late', non_negative),
]


class ContactDetectorNode(HapticNode):
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

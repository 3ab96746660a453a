"""``visualizer``: RViz markers at ~30 Hz, off the haptic loop.

Publishes ``visualization/tissue`` (``MarkerArray``, transient local, once at start: the tissue
mesh as a TRIANGLE_LIST) and ``visualization/markers`` (``MarkerArray`` at ``rate`` Hz: the probe
sphere, the contact point on the undeformed surface, the force arrow, and the tumours when
``show_tumours``). Subscribes to the pose, contact and force command topics.
"""
from __future__ import annotations

from geometry_msgs.msg import Point, PoseStamped, WrenchStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker, MarkerArray

from . import interfaces as ifc
from ._case import CASE_PARAMS, apply_case, declare_case  # noqa: F401 (CASE_PARAMS: in config)
from ._common import LOOP_QOS, Param, declare_parameters, positive, run_node
from .contact_detector import MESH_PARAMS, load_surface

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _tumour_check(v):
    if len(v) % 4:
        return 'expected a flat list x, y, z, radius per tumour (a multiple of 4 numbers)'
    return None if all(r > 0 for r in v[3::4]) else 'tumour radii must be > 0'


PARAMS = MESH_PARAMS + [
    Param('rate', 30.0, 'marker rate [Hz]', positive),
    Param('force_scale', 0.01, 'force arrow length per newton [m/N]', positive),
    Param('probe_radius', 0.008, 'probe sphere radius [m]', positive),
    Param('show_tumours', False, 'draw the tumours'),
    Param('tumours', [0.0285, 0.015, -0.010, 0.0075], 'tumours, flat x, y, z, radius [m] per '
          'tumour (tissue frame; default: the default FE scene\'s tumour, '
          'config/scenes/default.yaml)', _tumour_check),
    Param('mesh_alpha', 0.5, 'tissue mesh opacity (0..1)',
          lambda v: None if 0 <= v <= 1 else 'expected 0 <= value <= 1'),
]


def _marker(kind, mid, frame, ns, rgba, scale):
    m = Marker()
    m.header.frame_id = frame
    m.ns, m.id, m.type, m.action = ns, mid, kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color.r, m.color.g, m.color.b, m.color.a = rgba
    return m


class Visualizer(Node):
    def __init__(self, name: str = 'visualizer', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        p = self.params = apply_case(p, declare_case(self, self.switch_case))
        f = self.frame_id = p['frame_id']
        self.pub_tissue = self.create_publisher(MarkerArray, ifc.TOPIC_TISSUE, LATCHED)
        self.pub = self.create_publisher(MarkerArray, ifc.TOPIC_MARKERS, 10)
        self._publish_tissue(p)
        d = 2 * p['probe_radius']
        self.probe = _marker(Marker.SPHERE, 0, f, 'probe', (0.2, 0.4, 1.0, 1.0), (d, d, d))
        self.contact = _marker(Marker.SPHERE, 1, f, 'contact', (1.0, 0.2, 0.2, 1.0),
                               (0.004, 0.004, 0.004))
        self.arrow = _marker(Marker.ARROW, 2, f, 'force', (0.1, 0.9, 0.1, 1.0), (0.002, 0.004, 0.004))
        self.arrow.points = [Point(), Point()]
        self.tumours = self._tumour_markers(p)
        self._pose = self._contact = self._force = None
        self.create_subscription(PoseStamped, ifc.TOPIC_POSE, self._set('_pose'), LOOP_QOS)
        self.create_subscription(JointState, ifc.TOPIC_CONTACT, self._set('_contact'), LOOP_QOS)
        self.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND, self._set('_force'), LOOP_QOS)
        self.timer = self.create_timer(1.0 / p['rate'], self._draw)
        self.n_published = 0

    def _publish_tissue(self, p: dict) -> None:
        mesh = load_surface(self, p)
        tissue = _marker(Marker.TRIANGLE_LIST, 0, self.frame_id, 'tissue',
                         (1.0, 0.8, 0.7, p['mesh_alpha']), (1.0, 1.0, 1.0))
        tissue.points = [Point(x=float(a), y=float(b), z=float(c))
                         for a, b, c in mesh.vertices[mesh.faces.reshape(-1)]]
        self.pub_tissue.publish(MarkerArray(markers=[tissue]))

    def _tumour_markers(self, p: dict) -> list:
        """Tumour spheres, only with ``show_tumours`` (hidden from the trainee otherwise)."""
        out = []
        if p['show_tumours']:
            t = p['tumours']
            for i in range(len(t) // 4):
                x, y, z, r = t[4 * i:4 * i + 4]
                m = _marker(Marker.SPHERE, 10 + i, self.frame_id, 'tumours', (0.6, 0.0, 0.6, 0.8),
                            (2 * r, 2 * r, 2 * r))
                m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, z
                out.append(m)
        return out

    def switch_case(self, case) -> None:
        """Show the surface (and, with ``show_tumours``, the lesions) of ``case``."""
        params = apply_case(self.params, case, self.own_params)
        self._publish_tissue(params)  # raises on a bad mesh: nothing changed
        clear = Marker(action=Marker.DELETEALL)
        clear.header.frame_id = self.frame_id
        self.pub.publish(MarkerArray(markers=[clear]))  # drop the old case's tumour spheres
        self.params, self.tumours = params, self._tumour_markers(params)

    def _set(self, attr):
        def cb(msg):
            setattr(self, attr, msg)
        return cb

    def _draw(self) -> None:
        markers = list(self.tumours)
        if self._pose is not None:
            q = self._pose.pose.position
            self.probe.pose.position = q
            markers.append(self.probe)
            c = self._contact
            touching = c is not None and len(c.position) == len(ifc.CONTACT_FIELDS) \
                and c.position[ifc.I_IN_CONTACT] > 0.5
            self.contact.action = Marker.ADD if touching else Marker.DELETE
            if touching:
                pos = self.contact.pose.position
                pos.x, pos.y, pos.z = (float(v) for v in c.position[0:3])
            markers.append(self.contact)
            f = self._force.wrench.force if self._force is not None else None
            k = self.params['force_scale']
            self.arrow.points[0] = q
            self.arrow.points[1] = Point(x=q.x + k * f.x, y=q.y + k * f.y, z=q.z + k * f.z) \
                if f is not None else q
            markers.append(self.arrow)
        if markers:
            self.pub.publish(MarkerArray(markers=markers))
            self.n_published += 1


def main(args=None) -> None:
    raise SystemExit(run_node(Visualizer, args))


if __name__ == '__main__':
    main()

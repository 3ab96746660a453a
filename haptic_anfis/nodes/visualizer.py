"""``visualizer``: RViz markers at ~30 Hz, off the haptic loop.

Publishes ``visualization/tissue`` (``MarkerArray``, transient local: the tissue surface as
TRIANGLE_LIST patches with per-corner colour, all of them at start; then, at ``rate`` Hz while the
probe dents the skin, only the patches whose drawing changed: the dent from the FE sweep's skin
displacements, ``haptic_anfis.tissue.deformation``) and ``visualization/markers`` (``MarkerArray``
at ``rate`` Hz: the probe as a flat 16 mm cylinder whose face is at the probe position, the
contact point on the undeformed surface, the force arrow, and the tumours when ``show_tumours``).
Reads the pose, contact and force command topics at the marker rate (newest sample, best effort;
no callback per 1 kHz message). The dent is computed and published on
the node's own thread, in messages of a bounded size, so the executor that carries the haptic
loop (``haptic-anfis sim``) only stores the latest messages.
"""
from __future__ import annotations

import collections
import threading
import time

import numpy as np
from geometry_msgs.msg import Point, PoseStamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker, MarkerArray

from ..pipeline.contact import load_surface
from ..tissue.dent_display import DentFeed, DentSurface, dent_model
from ..tissue.displacement import DisplacementDataError
from ..view.scene import PROBE_LENGTH, probe_centred
from . import cdr
from .. import interfaces as ifc
from ._case import apply_case, declare_case
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import declare_parameters
from .runtime import run_node
from .base import HapticNode
from .polled import PolledSubscription
from .session import inputs_matched
from .visualizer_params import PARAMS  # the node's parameter table (the registry reads it here)

# transient local, deep enough to hold the whole surface's messages for a late subscriber
LATCHED = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# the loop topics as drawn: the newest sample, best effort
VIEW_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.BEST_EFFORT)


def _marker(kind, mid, frame, ns, rgba, scale):
    m = Marker()
    m.header.frame_id = frame
    m.ns, m.id, m.type, m.action = ns, mid, kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color.r, m.color.g, m.color.b, m.color.a = rgba
    return m


def _points(xyz: np.ndarray) -> list:
    """Point messages for (n, 3) coordinates without the per-field checks of Point(...) (the
    values are finite floats by construction; this is the per-frame cost of the dent)."""
    new = Point.__new__
    out = []
    for x, y, z in xyz.tolist():
        p = new(Point)
        p._x, p._y, p._z = x, y, z
        out.append(p)
    return out


class Visualizer(HapticNode):
    def __init__(self, name: str = 'visualizer', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        p = self.params = apply_case(p, declare_case(self, self.switch_case))
        f = self.frame_id = p['frame_id']
        self.pub_tissue = self.create_publisher(MarkerArray, ifc.TOPIC_TISSUE, LATCHED)
        self.surface = None
        self.n_dent_messages = 0
        self.pub = self.create_publisher(MarkerArray, ifc.TOPIC_MARKERS, 10)
        self._publish_tissue(p)
        d = 2 * p['probe_radius']
        self.probe = _marker(Marker.CYLINDER, 0, f, 'probe', (0.2, 0.4, 1.0, 1.0),
                             (d, d, PROBE_LENGTH))
        self.contact = _marker(Marker.SPHERE, 1, f, 'contact', (1.0, 0.2, 0.2, 1.0),
                               (0.004, 0.004, 0.004))
        self.arrow = _marker(Marker.ARROW, 2, f, 'force', (0.1, 0.9, 0.1, 1.0), (0.002, 0.004, 0.004))
        self.arrow.points = [Point(), Point()]
        self.tumours = self._tumour_markers(p)
        self._pose = self._contact = self._force = None
        # The 1 kHz loop topics are read at the marker rate, newest sample only, best effort: no
        # callback per message (3 000/s) and no acknowledgements for the loop's publishers
        # (nodes/polled.py); drawing a 30 Hz picture needs nothing older.
        self._inputs = [(attr, PolledSubscription(self, t, topic, VIEW_QOS))
                        for attr, t, topic in (('_pose', PoseStamped, ifc.TOPIC_POSE),
                                               ('_contact', JointState, ifc.TOPIC_CONTACT),
                                               ('_force', WrenchStamped, ifc.TOPIC_COMMAND))]
        self.timer = self.create_timer(1.0 / p['rate'], self._draw)
        self.n_published = 0
        # marker frames not built: their topic had no subscriber. RViz is not part of every
        # install, and a picture nobody draws took about a tenth of a core of the loop's
        # machine (the dent thread skips the same way while visualization/tissue has no
        # subscriber)
        self.frames_unwatched = 0
        # compute + publish time of the last dent frames [s] (bounded: a long session)
        self.dent_seconds: collections.deque = collections.deque(maxlen=10000)
        self.last_dent = None
        self.n_dent_frames = 0
        self._stop = threading.Event()
        self._thread = None
        if p['deform']:  # the dent thread (idle while the case has no displacement data)
            self._thread = threading.Thread(target=self._dent_loop, name='visualizer-dent',
                                            daemon=True)
            self._thread.start()

    # -- the dent --------------------------------------------------------------------------

    def _dent_surface(self, mesh, p):
        """The patched surface with its dent model, or None (logged) when there is no data."""
        try:
            model = dent_model(p['displacement_path'], p['dent_reach'])
        except (DisplacementDataError, OSError, ValueError) as exc:
            self.get_logger().warning(f'no dent drawn: {exc}')
            return None
        if abs(model.probe_radius_ - p['probe_radius']) > 1e-9:
            self.get_logger().warning(
                f'probe_radius {p["probe_radius"]} m differs from the FE probe '
                f'{model.probe_radius_} m the dent was computed for')
        return DentSurface(np.asarray(mesh.vertices), np.asarray(mesh.faces), model,
                           patch_size=p['patch_size'], tolerance=p['dent_tolerance'],
                           alpha=p['mesh_alpha'])

    def _publish_patches(self, patches) -> None:
        """Publish ``patches`` as TRIANGLE_LIST markers, in messages of at most
        ``max_points_per_message`` corners, serialized straight from their arrays
        (:func:`~haptic_anfis.nodes.cdr.triangle_markers`: rclpy's message objects cost ~17 ms
        of the interpreter per frame)."""
        cap = self.params['max_points_per_message']
        batch, n = [], 0
        for pt in patches:
            if batch and n + len(pt.corners) > cap:
                self.pub_tissue.publish(cdr.triangle_markers(self.frame_id, 'tissue', batch))
                self.n_dent_messages += 1
                batch, n = [], 0
                time.sleep(0)  # let another thread of this process run between messages
            batch.append((pt.index, pt.corners, pt.colours))
            n += len(pt.corners)
        if batch:
            self.pub_tissue.publish(cdr.triangle_markers(self.frame_id, 'tissue', batch))
            self.n_dent_messages += 1

    def _contact_state(self):
        c = self._contact
        return None if c is None else ifc.contact_geometry(c.position)

    def _dent_loop(self) -> None:
        """The dent frames at ``rate`` Hz (:class:`~haptic_anfis.tissue.dent_display.DentFeed`
        decides what each sends), to absolute deadlines: a frame's own time does not lower the
        rate; one that fell behind starts afresh, without a burst."""
        period = 1.0 / self.params['rate']
        feed = DentFeed(self.pub_tissue.get_subscription_count())
        due = time.monotonic()
        while True:
            due += period
            now = time.monotonic()
            if now - due > period:
                due = now
            if self._stop.wait(max(due - now, 0.0)):
                break
            try:
                t0 = time.perf_counter()
                patches = feed.frame(self.surface, self._contact_state(),   # swapped by a switch
                                     self.pub_tissue.get_subscription_count())
                self._publish_patches(patches)
                if feed.frames > self.n_dent_frames:
                    self.dent_seconds.append(time.perf_counter() - t0)
                    self.n_dent_frames, self.last_dent = feed.frames, feed.last
            except Exception as exc:  # never let the drawing thread die silently
                if not self.context.ok():  # Ctrl-C shut the context down under us: just stop
                    return
                self.get_logger().error(f'dent drawing failed: {exc!r}', throttle_duration_sec=5.0)

    def close(self) -> None:
        """Stop the dent thread (called before the node is destroyed) and log what it drew
        (once)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        dent = ''
        if self.dent_seconds:
            ms = np.percentile(np.asarray(self.dent_seconds) * 1e3, [50, 99])
            dent = (f'dent: {self.n_dent_frames} frames drawn, {self.n_dent_messages} messages, '
                    f'compute + publish p50 {ms[0]:.1f} ms, p99 {ms[1]:.1f} ms (newest '
                    f'{len(self.dent_seconds)} frames); ')
        self.get_logger().info(f'{dent}{self.n_published} marker arrays, '
                               f'{self.frames_unwatched} frames not drawn (no subscriber)')

    def destroy_node(self):
        self.close()
        for _, sub in self._inputs:
            sub.destroy()
        return super().destroy_node()

    # -- the 30 Hz markers -----------------------------------------------------------------

    def _publish_tissue(self, p: dict) -> None:
        """Publish the surface of ``p``'s mesh: as dent patches when ``deform`` and there is
        displacement data, else as one static TRIANGLE_LIST. Raises on a bad mesh (nothing
        changed then)."""
        mesh = load_surface(p)
        surface = self._dent_surface(mesh, p) if p['deform'] else None
        if self.surface is not None:  # a case switch: drop the old surface's patches
            clear = Marker(action=Marker.DELETEALL)
            clear.header.frame_id = self.frame_id
            clear.ns = 'tissue'
            self.pub_tissue.publish(MarkerArray(markers=[clear]))
        self.surface = surface  # one assignment: the dent thread sees the old or the new one
        if surface is None:
            tissue = _marker(Marker.TRIANGLE_LIST, 0, self.frame_id, 'tissue',
                             (1.0, 0.8, 0.7, p['mesh_alpha']), (1.0, 1.0, 1.0))
            tissue.points = _points(mesh.vertices[mesh.faces.reshape(-1)])
            self.pub_tissue.publish(MarkerArray(markers=[tissue]))
        else:
            self._publish_patches(surface.all_patches())

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

    def ready_condition(self) -> tuple[bool, str]:
        """Ready (nodes/session.py) once every loop topic it draws has a publisher."""
        return inputs_matched(self, [self.resolve_topic_name(s.topic) for _, s in self._inputs])

    def _take_inputs(self) -> None:
        """The newest pose, contact and force command (kept when none arrived since)."""
        for attr, sub in self._inputs:
            m = sub.take_newest(raw=False)
            if m is not None:
                setattr(self, attr, m)

    def _draw(self) -> None:
        self._take_inputs()  # the dent thread reads what this took
        if self.pub.get_subscription_count() == 0:  # nobody draws them: build nothing
            self.frames_unwatched += 1
            return
        markers = list(self.tumours)
        if self._pose is not None:
            q = self._pose.pose.position
            c = None if self._contact is None else ifc.contact_geometry(self._contact.position)
            pos, o = self.probe.pose.position, self.probe.pose.orientation
            (pos.x, pos.y, pos.z), (o.w, o.x, o.y, o.z) = probe_centred(
                (q.x, q.y, q.z), None if c is None else c[1])
            markers.append(self.probe)
            self.contact.action = Marker.ADD if c is not None else Marker.DELETE
            if c is not None:
                pos = self.contact.pose.position
                pos.x, pos.y, pos.z = c[0]
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

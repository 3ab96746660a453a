"""``examiner``: watches a palpation session and scores it (:mod:`haptic_anfis.exam`).

Subscribes to the probe pose, contact, force command, buttons and marks (``exam/marks``); knows the
case — its surface and lesions — from ``case`` / ``random_case_seed`` (the case library, as the
other case-aware nodes; setting either on a running examiner starts a new exam on that case) or,
with no case, from ``scene`` and the mesh parameters (:func:`lesion_source`). Publishes a
live coverage heat map on the mesh (``exam/coverage``, ``visualization_msgs/MarkerArray``: the
palpable region's triangles coloured by the deepest level pressed — pale grey none, yellow
light, orange medium, dark red deep (:mod:`haptic_anfis.palette`) — in ~16 mm patches, each
sent when it changes and all every 2 s, plus a text marker with the coverage numbers, at
``rate`` Hz) and, on :meth:`Examiner.close`, writes the report (``report.json`` +
``report.png``) into ``report_dir``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from geometry_msgs.msg import Point, PointStamped, PoseStamped, WrenchStamped
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Joy, JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from . import cdr
from .. import interfaces as ifc, palette
from ..exam.config import load_exam_config
from ..exam.figure import save_figure
from ..exam.files import write_text_atomic
from ..exam.lesions import ExamSubject, subject_from_scene
from ..exam.session import ExamSession, Surface
from ..pipeline.contact import load_surface
from ._case import apply_case, declare_case
from .base import HapticNode
from .contact_detector import MESH_PARAMS
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import Param, declare_parameters, positive
from .runtime import run_node, stamp_ns

PARAMS = MESH_PARAMS + [
    Param('scene', '', "scene file whose tumours are the lesions to find ('' = "
          'config/scenes/default.yaml)'),
    Param('exam_config', '', "scoring settings ('' = config/exam.yaml: pressure levels, margins, "
          'score weights, with their sources)'),
    Param('rate', 5.0, 'coverage heat map rate [Hz]', positive),
    Param('report_dir', '', "directory for report.json and report.png at the end ('' = none)"),
]

#: The examiner wants every sample, not only the newest (as the recorder): a deep queue (10 s
#: of 1 kHz: in a process of its own on a loaded machine it falls seconds behind and catches up).
SAMPLE_QOS = QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE)

#: the heat map's colour (RGBA 0-1) per deepest level pressed: none, light, medium, deep (the
#: colours of every figure and the page, haptic_anfis.palette; untouched patches half clear)
LEVEL_COLOURS = tuple((*(c / 255 for c in palette.rgb255(colour)), alpha) for colour, alpha in zip(
    (palette.NOT_PRESSED, palette.LEVEL['light'], palette.LEVEL['medium'], palette.LEVEL['deep']),
    (0.5, 0.8, 0.85, 0.9)))


def lesion_source(p: dict, case=None) -> ExamSubject:
    """The lesions to find: the case's scene when a case is chosen, else the ``scene`` file."""
    if case is not None:
        return subject_from_scene(case.scene_path)
    return subject_from_scene(p['scene'] or None)


class Examiner(HapticNode):
    def __init__(self, name: str = 'examiner', **kw):
        super().__init__(name, **kw)
        p = self.own_params = declare_parameters(self, PARAMS)
        self.config = load_exam_config(p['exam_config'] or None)   # ValueError -> exit 1
        case = declare_case(self, self.switch_case)
        self._start_exam(case)
        self.pub = self.create_publisher(MarkerArray, ifc.TOPIC_COVERAGE, 1)
        # The three 1 kHz topics arrive as raw bytes read by nodes/cdr.py: rclpy's own
        # deserialisation made a side examiner fall seconds behind and lose samples.
        self.create_subscription(JointState, ifc.TOPIC_CONTACT, self._on_contact, SAMPLE_QOS,
                                 raw=True)
        self.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND, self._on_force, SAMPLE_QOS,
                                 raw=True)
        self.create_subscription(PoseStamped, ifc.TOPIC_POSE, self._on_pose, SAMPLE_QOS,
                                 raw=True)
        self.malformed = 0   # loop messages that could not be read (counted, said once)
        self.create_subscription(PointStamped, ifc.TOPIC_MARKS, self._on_mark, 10)
        self.create_subscription(Joy, ifc.TOPIC_BUTTONS, self._on_buttons, 10)
        self.timer = self.create_timer(1.0 / p['rate'], self._publish)
        self.n_published = 0

    def switch_case(self, case) -> None:
        """A new exam on ``case`` (None: the own scene / mesh parameters); the samples so far are
        dropped (write the report first if it is wanted)."""
        self._start_exam(case)
        self.get_logger().warning('case switched: a new exam starts')

    def _start_exam(self, case) -> None:
        p = self.params = apply_case(self.own_params, case, self.own_params)
        subject = lesion_source(p, case)
        mesh = load_surface(p)
        session = ExamSession(Surface.from_mesh(mesh), subject, self.config)
        self.subject, self.session = subject, session
        s = session
        self._colours = [ColorRGBA(r=r, g=g, b=b, a=a) for r, g, b, a in LEVEL_COLOURS]
        self._patches, self._patch_faces = _patch_markers(s, p['frame_id'])
        self._text = Marker()
        t = self._text
        t.header.frame_id = p['frame_id']
        t.ns, t.id, t.type, t.action = 'exam_summary', 0, Marker.TEXT_VIEW_FACING, Marker.ADD
        t.pose.orientation.w = 1.0
        t.pose.position.x, t.pose.position.z = 0.06, s.region_radius + 0.01
        t.scale.z = 0.006
        t.color.r = t.color.g = t.color.b = t.color.a = 1.0
        self._last_levels = None
        self._last_full = -1e9
        blind = self.get_parameter('random_case_seed').value >= 0   # log no case name
        self.get_logger().info(f'{len(subject.lesions)} lesion(s)'
                               + ('' if blind else f' from {subject.source}')
                               + f', {len(s.grid.centroids)} surface cells in the palpable region')

    def _bad(self, exc: ValueError) -> None:
        self.malformed += 1
        if self.malformed == 1:
            self.get_logger().warning(f'{exc}: not scored (further ones counted)')

    def _on_contact(self, raw: bytes) -> None:
        try:
            stamp, _, position, _ = cdr.read_joint_state(raw)
        except ValueError as exc:
            self._bad(exc)
            return
        self.session.add_contact_values(stamp * 1e-9, position)

    def _on_force(self, raw: bytes) -> None:
        try:
            stamp, _, f = cdr.read_wrench_stamped(raw)
        except ValueError as exc:
            self._bad(exc)
            return
        self.session.add_force(stamp * 1e-9, f)

    def _on_pose(self, raw: bytes) -> None:
        try:
            stamp, _, q = cdr.read_pose_position(raw)
        except ValueError as exc:
            self._bad(exc)
            return
        self.session.add_pose(stamp * 1e-9, q)

    def _on_mark(self, msg: PointStamped) -> None:
        q = msg.point
        self.session.add_mark(stamp_ns(msg.header.stamp) * 1e-9, (q.x, q.y, q.z))
        self.get_logger().info(f'mark at ({q.x * 1e3:.1f}, {q.y * 1e3:.1f}, {q.z * 1e3:.1f}) mm')

    def _on_buttons(self, msg: Joy) -> None:
        self.session.add_buttons(stamp_ns(msg.header.stamp) * 1e-9, list(msg.buttons))

    def _publish(self) -> None:
        """Fold the new samples into the grid; publish the summary text and the heat-map patches
        whose colours changed (all of them every ``FULL_REFRESH`` s, for late subscribers): the
        whole map is ~6k vertices, too slow to serialise at 5 Hz on a loaded machine."""
        self.session.update_coverage()
        levels = self.session.grid.level_per_face()
        now = self.get_clock().now()
        full = (now.nanoseconds * 1e-9 - self._last_full) >= FULL_REFRESH
        if full:
            self._last_full = now.nanoseconds * 1e-9
        changed = np.ones(len(levels), bool) if full or self._last_levels is None \
            else levels != self._last_levels
        self._last_levels = levels
        stamp = now.to_msg()
        out = []
        cols = self._colours
        for m, faces in zip(self._patches, self._patch_faces):
            if changed[faces].any():
                m.colors = [cols[lv] for lv in np.repeat(levels[faces], 3)]
                m.header.stamp = stamp
                out.append(m)
        c = self.session.grid.fraction()
        self._text.text = (f"light {100 * c['light']:.0f} %  medium {100 * c['medium']:.0f} %  "
                           f"deep {100 * c['deep']:.0f} %  marks {len(self.session.marks)}  "
                           f"samples {len(self.session.contacts)}")
        self._text.header.stamp = stamp
        out.append(self._text)
        self.pub.publish(MarkerArray(markers=out))
        self.n_published += 1

    def report(self) -> dict:
        return self.session.report()

    def close(self) -> None:
        """Write the report into ``report_dir`` (when set)."""
        if self.params['report_dir']:
            out = Path(self.params['report_dir'])
            out.mkdir(parents=True, exist_ok=True)
            # the raw samples first (exam run --view replays them in its debrief): report.json,
            # written last, says everything is there
            self.session.save_samples(out / SAMPLES_FILE)
            write_report(self.session, out)


#: the raw samples' file in ``report_dir`` (:meth:`ExamSession.save_samples`)
SAMPLES_FILE = 'samples.npz'
FULL_REFRESH = 2.0   # [s] between heat maps carrying every patch
PATCH = 0.016        # [m] patch size: ~30 patches over the default region


def _patch_markers(session, frame_id: str):
    """The region's triangles split into square (y, z) patches of ``PATCH`` m, one TRIANGLE_LIST
    marker each (points fixed, lifted 0.5 mm out of the skin so they draw over the tissue mesh);
    returns (markers, face indices into the region per marker)."""
    g = session.grid
    key = np.floor(g.centroids[:, 1:3] / PATCH).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    markers, faces = [], []
    for k in range(inv.max() + 1):
        idx = np.flatnonzero(inv == k)
        m = Marker()
        m.header.frame_id = frame_id
        m.ns, m.id, m.type, m.action = 'exam_coverage', k, Marker.TRIANGLE_LIST, Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 1.0
        tri = g.vertices[g.faces[g.faces_index[idx]]].reshape(-1, 3)
        m.points = [Point(x=float(a) + 5e-4, y=float(b), z=float(c)) for a, b, c in tri]
        markers.append(m)
        faces.append(idx)
    return markers, faces


def write_report(session: ExamSession, out_dir, report: dict | None = None) -> dict:
    """report.png then report.json of ``session`` into ``out_dir`` (created); returns the
    report. report.json comes last and whole (renamed into place): a reader that sees it has
    the figure too."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = report if report is not None else session.report()
    save_figure(session, report, out / 'report.png')
    write_text_atomic(out / 'report.json', json.dumps(report, indent=1))
    return report


def main(args=None) -> None:
    raise SystemExit(run_node(Examiner, args))


if __name__ == '__main__':
    main()

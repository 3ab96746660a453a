"""The browser page: a viser server drawing the breast, the probe, the coverage and the debrief,
with the trainee's gauges and the instructor's controls (no ROS).

Why viser (PyPI ``viser``): a Python server with a bundled three.js client — meshes with vertex
colours, GUI panels, a scene a browser reconnecting later receives whole (the server replays its
current state) — so no hand-written WebGL and no RViz, which the ROS wheels here do not include.

One :class:`ViewApp` serves one port: the trainee's page, the exam live and its debrief and
nothing else (the instructor's controls are on a page of their own, :mod:`.console`). The caller
feeds it: :meth:`ViewApp.show_live` at its own rate (the web_view node: newest pose / contact /
force, ~30 Hz) and :meth:`ViewApp.show_debrief` with a
:class:`~haptic_anfis.view.debrief.Debrief`. The server answers only its own origin
(:mod:`.doors`); every text shown that a user typed or a file named is escaped
(:func:`.escape.md`). Tissue frame, metres.
"""
from __future__ import annotations

import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import trimesh

from ..errors import HapticAnfisError
from ..exam.config import LEVELS
from ..exam.normal import normal_lines
from ..palette import REGION, rgb255
from ..record import history
from .doors import close_door, guarded_server
from .escape import md
from .gauge import DEVICE_MAX_FORCE, gauge
from .legend import banner_html, gauge_html, legend_html
from .panel import history_markdown, numbers_markdown
from .scene import (LESION_RGB, MARK_RGB, NORMAL_RGB, PROBE_LENGTH, SkinPaint, frame_camera,
                    probe_quaternion, region_outline)

__all__ = ['BLIND', 'PROBE_LENGTH', 'md', 'ViewApp', 'ViewError', 'check_port', 'coverage_fractions',
           'trainee_history']

#: the dropdown's entry for a blind random case
BLIND = 'blind random case'
FORCE_SCALE = 0.004  # [m/N] force arrow length
#: the legend's place in the panel: after every folder, the trainee history's too
LAST = 1e6
#: what the page says between the end of an exam and its debrief
OVER = 'exam over — debrief loading'


class ViewError(HapticAnfisError, ValueError):
    """Bad input for the view (a port in use, a bag it cannot show): one line naming it."""


def check_port(port: int, host: str = '127.0.0.1', flag: str = '--port') -> None:
    """Raise :class:`ViewError` when ``port`` is not a free TCP port on ``host`` (viser would
    silently move to the next free port, and the URL printed would be wrong); ``flag``: the
    option the message names."""
    if not 0 < int(port) < 65536:
        raise ViewError(f'{flag} {port}: expected 1..65535')
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as the server binds it
    try:
        s.bind((host, int(port)))
    except OSError as exc:
        raise ViewError(f'{flag} {port}: in use or not available on {host} ({exc.strerror}); '
                        f'choose another with {flag}') from None
    finally:
        s.close()


def trainee_history(trainee: str, db=None) -> list[dict]:
    """The trainee's sessions from the trainee record (:func:`haptic_anfis.record.history`,
    oldest first; ``db``: the record file, None = its default). A record that cannot be read
    gives one row ``{'error': ...}`` naming it, as does a malformed id (typed on the page):
    the page shows it and goes on."""
    try:
        return history(db, trainee)
    except (ValueError, OSError) as exc:   # RecordError is a ValueError
        return [{'error': str(exc)}]


@dataclass
class ViewStats:
    """What the page was sent: skin frames (dent / coverage), their times (monotonic [s]),
    compute time per frame [s], the newest probe position drawn and when."""
    skin_frames: int = 0
    frame_times: deque = field(default_factory=lambda: deque(maxlen=600))
    frame_seconds: deque = field(default_factory=lambda: deque(maxlen=600))
    probe_updates: int = 0
    probe_position: tuple | None = None
    probe_at: float = 0.0

    def skin_rate(self) -> float:
        """Skin frames per second over the newest frames (0 with fewer than 2)."""
        t = list(self.frame_times)
        return (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else 0.0

    def drawing_rate(self, pause: float = 0.5) -> float:
        """Skin frames per second while the skin was being redrawn: 1 / the median interval
        between the newest frames, leaving out gaps longer than ``pause`` [s] (a steady press or
        a lifted probe sends nothing); 0 without two such frames."""
        d = np.diff(np.asarray(self.frame_times, dtype=float))
        d = d[(d > 0) & (d <= pause)]
        return float(1.0 / np.median(d)) if len(d) else 0.0


class ViewApp:
    """The page on ``host:port``.

    Args:
        vertices, faces: the skin mesh [m] (tissue frame); region_faces: the coverage grid's
            faces (indices into ``faces``); thresholds: (light, medium, deep) [m].
        deformation: a :class:`~haptic_anfis.tissue.deformation.DeformationModel` for the dent
            (None: no dent drawn).
    """

    def __init__(self, vertices, faces, region_faces, thresholds, port: int = 8080,
                 host: str = '127.0.0.1', title: str = 'haptic_anfis', deformation=None,
                 max_force: float = DEVICE_MAX_FORCE) -> None:
        check_port(port, host)
        self._trimesh = trimesh
        self.port, self.host = int(port), host
        self.thresholds = tuple(float(t) for t in thresholds)
        self.max_force = float(max_force)
        self.deformation = deformation
        self.stats = ViewStats()
        self.mode = 'live'
        self.debrief = None
        self._lock = threading.RLock()
        self._light_since = None
        self.server, self.door = guarded_server(self.port, host, title)
        s = self.server
        self.n_connects = 0   # pages that connected (a reconnect counts again)

        @s.on_client_connect
        def _(client) -> None:
            self.n_connects += 1
        s.scene.set_up_direction('+z')
        self._gui()
        self.set_surface(vertices, faces, region_faces)
        probe = trimesh.creation.cylinder(radius=0.008, height=PROBE_LENGTH, sections=32)
        probe.apply_translation((0, 0, PROBE_LENGTH / 2))   # face at z = 0, body along +z
        self.probe = s.scene.add_mesh_simple('/probe', probe.vertices, probe.faces,
                                             color=(60, 110, 240), visible=False)
        self.arrow = None
        self._live_marks: list = []   # the trainee's marks as they are placed
        self._lesion_nodes: list = []
        self._mark_nodes: list = []
        self._path = None

    @property
    def url(self) -> str:
        return f'http://{self.host}:{self.port}/'

    # -- GUI --------------------------------------------------------------------------------

    def _gui(self) -> None:
        g = self.server.gui
        # the wide panel: the debrief's lines and the history table unwrapped (at 1280 x 800
        # the breast still has the window's middle)
        g.configure_theme(control_width='large')
        self.g_status = g.add_markdown('**live** — waiting for the probe')
        #: the cue, a banner above everything else (the text in ``cue``)
        self.g_banner = g.add_html('')
        self.cue = ''
        with g.add_folder('Exam') as self.g_exam:
            self.g_clock = g.add_markdown('clock 0:00')
            self.g_bar = g.add_html(gauge_html(self.thresholds, None))
            self.g_gauge = g.add_markdown(self._gauge_text(None))
            self.g_cov = g.add_markdown(self._coverage_text({k: 0.0 for k in LEVELS}))
        with g.add_folder('Debrief', visible=False) as f:
            self.g_debrief = f
            self.g_numbers = g.add_markdown('')
            self.g_time = g.add_slider('replay time [s]', min=0.0, max=1.0, step=0.1,
                                       initial_value=1.0)
            self.g_lesions = g.add_markdown('')
            self.g_feedback = g.add_markdown('')
        with g.add_folder('Feel it again', expand_by_default=False, visible=False) as f:
            self.g_feel = f
            self.g_feel_md = g.add_markdown('')
        with g.add_folder('Colours', order=LAST):   # under everything: the numbers first
            self.g_legend = g.add_html(legend_html())
        self.g_time.on_update(lambda _: self.scrub(self.g_time.value))
        # made only by a debrief shown with a trainee (haptic-anfis view BAG --trainee-id, the
        # instructor's review of a recording): the live trainee's page never has it
        self.g_history = self.g_history_md = None

    def message(self, text: str) -> None:
        """A line in the page's status (escaped: shown as the characters given)."""
        self.g_status.content = md(text)

    def set_exam_running(self, running: bool, blind: bool = False, case_name: str = '') -> None:
        """The live state of an exam: lesions hidden, no marks yet, status line."""
        with self._lock:
            if running:
                self.mode = 'live'
                self._clear_debrief()
                self._clear_live_marks()
                self._say_cue('', '')
                self._live_panel(True)
                shown = 'blind case' if blind else (case_name or 'default case')
                self.g_status.content = f'**exam running** — {md(shown)}; lesions hidden'

    def _live_panel(self, live: bool) -> None:
        """The panel's live-only parts (the gauge) shown or not, the legend for the exam or
        for its debrief (lesions and marks scored)."""
        self.g_bar.visible = self.g_gauge.visible = live
        self.g_legend.content = legend_html(debrief=not live)

    def _say_cue(self, cue: str, kind: str) -> None:
        if cue != self.cue:   # every update redraws the panel
            self.cue = cue
            self.g_banner.content = banner_html(cue, kind)

    def show_over(self) -> None:
        """The exam has ended and its debrief is being computed: said at once, in the banner
        and the status, the clock and the probe taken off (a page still saying "exam running"
        with a stopped clock reads as a hung exam); live frames are ignored until the debrief
        or the next exam."""
        with self._lock:
            if self.mode != 'live':
                return
            self.mode = 'over'
            self.probe.visible = False
            if self.arrow is not None:
                self.arrow.visible = False
            self.g_status.content = f'**{OVER}**'
            self.g_clock.content = 'exam over'
            self.g_bar.content = gauge_html(self.thresholds, None)
            self.g_gauge.content = self._gauge_text(None)
            self._say_cue(OVER, 'over')
            self._dent(None)

    def _gauge_text(self, gg) -> str:
        lv = ' | '.join(f'{k} >= {t * 1e3:.0f} mm' for k, t in zip(LEVELS, self.thresholds))
        if gg is None:
            return f'pressure: — (bands: {lv})'
        return (f'pressure: **{gg.level}** ({gg.depth_mm:.1f} mm) · force **{gg.force_n:.1f} N**'
                f' (the device clamps at {self.max_force:.1f} N)  \nbands: {lv}')

    @staticmethod
    def _coverage_text(cov: dict) -> str:
        return 'coverage: ' + ', '.join(f'{k} {100 * cov[k]:.1f} %' for k in LEVELS)

    # -- the skin ---------------------------------------------------------------------------

    def set_surface(self, vertices, faces, region_faces) -> None:
        """A (new) skin mesh: repaint it, frame the camera on it."""
        with self._lock:
            self.vertices = np.asarray(vertices, float)
            self.faces = np.asarray(faces, np.int64)
            self.paint = SkinPaint(self.vertices, self.faces, region_faces, self.thresholds)
            self._outline(region_faces)
            self.vertex_levels = np.zeros(len(self.vertices), np.int64)
            self.displacement = None
            self._moved = np.zeros(len(self.vertices), bool)   # drawn displaced
            fr = frame_camera(self.vertices)
            cam = self.server.initial_camera
            cam.position, cam.look_at, cam.up = fr.position, fr.look_at, fr.up
            cam.fov, cam.near, cam.far = fr.fov, fr.near, fr.far
            for client in self.server.get_clients().values():   # the open pages too
                client.camera.position, client.camera.look_at = fr.position, fr.look_at
                client.camera.fov = fr.fov
            self.framing = fr
            self._send_skin()

    def _send_skin(self, changed: np.ndarray | None = None) -> None:
        """Send the skin when a vertex of ``changed`` (v,) bool changed (None: always). One mesh
        for the whole skin: measured, re-sending only the changed pieces of a tiled skin cost
        ~20x more CPU per dent frame (viser's per-node overhead, ~3 ms a node) than one glTF of
        the 10 k-vertex skin (~4 ms), and the dent reaches a third of the breast."""
        if changed is not None and not changed.any():
            return
        t0 = time.perf_counter()
        u = self.displacement
        v = self.vertices if u is None else self.vertices + u
        m = self._trimesh.Trimesh(v, self.faces, process=False,
                                  vertex_colors=self.paint.colours(self.vertex_levels, u))
        self.server.scene.add_mesh_trimesh('/skin', m)
        self._moved = np.zeros(len(v), bool) if u is None else np.any(u != 0.0, axis=1)
        st = self.stats
        st.skin_frames += 1
        st.frame_times.append(time.monotonic())
        st.frame_seconds.append(time.perf_counter() - t0)

    def set_coverage(self, face_levels: np.ndarray, fractions: dict | None = None) -> None:
        """Paint the coverage: ``face_levels`` (m,) 0..3 per region face; ``fractions`` {level:
        0..1} for the panel line."""
        with self._lock:
            lv = self.paint.vertex_levels(face_levels)
            changed = lv != self.vertex_levels
            self.vertex_levels = lv
            if fractions is not None:
                self.g_cov.content = self._coverage_text(fractions)
            if changed.any():
                self._send_skin(changed)

    def _outline(self, region_faces) -> None:
        """Draw the border of the region to examine, lifted off the skin."""
        e = region_outline(self.faces, region_faces)
        seg = _segments_lifted(self.vertices[e], lift=0.0008)
        self.server.scene.add_line_segments('/region', seg, rgb255(REGION), thickness=3.0,
                                            thickness_units='screen')

    def show_mark(self, point) -> None:
        """A mark the trainee placed at ``point`` (3,) [m] (the probe tip): drawn at once on the
        nearest point of the skin, in the colour of the legend's "your marks" (whether it hit
        a lesion is said only in the debrief)."""
        p = np.asarray(point, float)
        if p.shape != (3,) or not np.isfinite(p).all():
            return
        with self._lock:
            v = self.vertices[int(np.argmin(np.sum((self.vertices - p) ** 2, axis=1)))]
            self._live_marks.append(self.server.scene.add_icosphere(
                f'/live_marks/{len(self._live_marks)}', radius=0.003, color=MARK_RGB['live'],
                position=tuple(map(float, _segments_lifted(v[None, None], 0.002)[0, 0]))))

    def _clear_live_marks(self) -> None:
        for n in self._live_marks:
            n.remove()
        self._live_marks = []

    # -- live -------------------------------------------------------------------------------

    def show_live(self, pose, contact=None, force=None, clock_s: float | None = None) -> None:
        """One live frame: probe tip ``pose`` (3,) [m] or None; ``contact`` None or (point (3,),
        direction (3,), depth [m]) while in contact; ``force`` (3,) [N] or None; the exam clock
        [s]. Re-sends the skin only when the dent changed; nothing once the exam is over."""
        with self._lock:
            if self.mode != 'live':
                return
            now = time.monotonic()
            fvec = np.zeros(3) if force is None else np.asarray(force, float)
            fn = float(np.linalg.norm(fvec)) if np.isfinite(fvec).all() else 0.0
            if pose is not None and np.isfinite(pose).all():
                d = contact[1] if contact is not None else (-1.0, 0.0, 0.0)
                self.probe.position = tuple(float(x) for x in pose)
                self.probe.wxyz = probe_quaternion(d)
                self.probe.visible = True
                self.stats.probe_updates += 1
                self.stats.probe_position = tuple(float(x) for x in pose)
                self.stats.probe_at = now
                tip = np.asarray(pose, float)
                pts = np.array([[tip, tip + FORCE_SCALE * fvec]]) if fn > 1e-3 else None
                if pts is not None and self.arrow is None:
                    self.arrow = self.server.scene.add_arrows(
                        '/force', pts, (30, 160, 30), shaft_radius=0.0012, head_radius=0.003,
                        head_length=0.005)
                elif pts is not None:   # move it: a new node per frame cost ~2 ms (profiled)
                    self.arrow.points = pts.astype(np.float32)
                    self.arrow.visible = True
                elif self.arrow is not None:
                    self.arrow.visible = False
            in_contact = contact is not None and contact[2] > 0
            depth = contact[2] if in_contact else 0.0
            if in_contact and depth < self.thresholds[-1]:
                self._light_since = self._light_since or now
            else:
                self._light_since = None
            gg = gauge(depth, fn, self.thresholds, in_contact,
                       0.0 if self._light_since is None else now - self._light_since,
                       self.max_force)
            bar = gauge_html(self.thresholds, depth if in_contact else None)
            if bar != self.g_bar.content:
                self.g_bar.content = bar
            self.g_gauge.content = self._gauge_text(gg)
            self._say_cue(gg.cue, gg.kind)
            if clock_s is not None:
                self.g_clock.content = f'clock {int(clock_s) // 60}:{int(clock_s) % 60:02d}'
            self._dent(contact if in_contact else None)

    def _dent(self, contact) -> None:
        """Dent the skin for ``contact`` (None: lifted); re-sends the skin when it moves or moved,
        nothing when the contact is the one drawn."""
        if self.deformation is None:
            return
        key = None if contact is None else np.concatenate([contact[0], contact[1],
                                                            [contact[2]]])
        last = getattr(self, '_dent_key', None)
        if (key is None and last is None) or (key is not None and last is not None
                                              and np.array_equal(key, last)):
            return
        self._dent_key = key
        if contact is None:
            self.displacement = None
            self._send_skin(self._moved.copy())
            return
        u = self.deformation.displacement(self.vertices, contact[0], contact[1], contact[2])
        self.displacement = u
        self._send_skin(self._moved | np.any(u != 0.0, axis=1))

    # -- debrief ----------------------------------------------------------------------------

    def _clear_debrief(self) -> None:
        for n in self._lesion_nodes + self._mark_nodes:
            n.remove()
        self._lesion_nodes, self._mark_nodes = [], []
        if self._path is not None:
            self._path.remove()
            self._path = None
        self.g_debrief.visible = False
        self.g_feel.visible = False
        if self.g_history is not None:
            self.g_history.visible = False
        self.debrief = None

    def show_debrief(self, debrief, trainee: str = '', db=None) -> None:
        """Reveal the lesions (hit / missed / below what this device renders), the marks, the search path and the
        report's numbers; the scrubber replays the session. ``trainee``: show the trainee's
        history (from the trainee record ``db``, None = its default file) beside it."""
        with self._lock:
            self._clear_debrief()
            self._clear_live_marks()   # the debrief draws them scored
            self._say_cue('', '')
            self.mode, self.debrief = 'debrief', debrief
            self.displacement, self._dent_key = None, None
            self.probe.visible = False
            if self.arrow is not None:
                self.arrow.visible = False
            n = debrief.numbers()
            r = debrief.report
            self._live_panel(False)
            if debrief.normal:
                self.g_legend.content = legend_html(debrief=True, background=True)
            self.g_numbers.content = numbers_markdown(n)
            sc = self.server.scene
            for k, les in enumerate(debrief.lesions):
                rgb = LESION_RGB[les.status]
                self._lesion_nodes.append(sc.add_icosphere(
                    f'/lesions/{k}', radius=max(les.radius, 0.003), color=rgb,
                    position=les.surface, opacity=0.85))
                self._lesion_nodes.append(sc.add_label(
                    f'/lesions/{k}_label', f'{les.name}: {les.status}',
                    position=tuple(np.asarray(les.surface) + (0.012, 0, 0.006))))
            self._draw_normal(debrief.normal)
            self.g_lesions.content = '\n'.join(
                f'- lesion **{md(les.name)}**: {md(les.status)}'
                + (f' ({md(les.why)})' if les.why else '')
                for les in debrief.lesions) or '- the case has no lesion'
            self.g_lesions.content += ''.join(f'\n- {md(line)}' for line in normal_lines(r))
            self.g_feedback.content = '\n'.join(f'- {md(line)}' for line in r['feedback']) \
                or '- pass: every lesion found, deep coverage met'
            feel = debrief.feel_again()
            self.g_feel_md.content = '\n'.join(
                f'- **{md(name)}**: {md(cmd)}' for name, cmd in feel.items())
            self.g_feel.visible = bool(feel)
            self.g_time.max = max(round(debrief.duration, 1), 0.1)
            self.g_time.value = self.g_time.max
            self.g_debrief.visible = True
            hist = trainee_history(trainee, db) if trainee else None
            if hist is not None:
                if self.g_history is None:
                    g = self.server.gui
                    with g.add_folder('Trainee history') as self.g_history:
                        self.g_history_md = g.add_markdown('')
                self.g_history_md.content = history_markdown(trainee, hist)
                self.g_history.visible = True
            self.g_status.content = (f"**debrief** — score {r['score']:.0f} ({md(r['verdict'])});"
                                     ' drag *replay time* to replay it')
            self.scrub(debrief.duration)

    def _draw_normal(self, markers) -> None:
        """The breast's normal lobules (spheres on the skin over them) and ribs (lines on the
        skin), blue, a confounder vermillion; labelled when it stands out or was marked."""
        sc = self.server.scene
        for k, nm in enumerate(markers):
            rgb = NORMAL_RGB[nm.status]
            if nm.kind == 'rib' and len(nm.line) > 1:
                p = _segments_lifted(nm.line, 0.001)
                self._lesion_nodes.append(sc.add_line_segments(
                    f'/normal/{k}', np.stack([p[:-1], p[1:]], axis=1), rgb, thickness=4.0,
                    thickness_units='screen'))
            else:
                self._lesion_nodes.append(sc.add_icosphere(
                    f'/normal/{k}', radius=max(nm.radius, 0.002), color=rgb,
                    position=nm.surface, opacity=0.9 if nm.status == 'confounder' else 0.6))
            if nm.label:
                self._lesion_nodes.append(sc.add_label(
                    f'/normal/{k}_label', nm.label,
                    position=tuple(np.asarray(nm.surface) + (0.010, 0, -0.004))))

    def scrub(self, t: float) -> None:
        """Show the debrief as it was ``t`` [s] into the session: coverage, path, marks."""
        with self._lock:
            d = self.debrief
            if d is None:
                return
            end = t >= d.duration - 1e-9
            lv = d.face_levels(None) if end else d.face_levels(t)
            if end:   # exactly the report's grid
                lv = d.session.grid.level_per_face()
            new = self.paint.vertex_levels(lv)
            changed = (new != self.vertex_levels) | self._moved
            self.vertex_levels = new
            self.g_cov.content = self._coverage_text(coverage_fractions(d.session.grid, lv))
            self._send_skin(changed)
            p = d.path(None if end else t)
            if self._path is not None:
                self._path.remove()
                self._path = None
            seg = _segments(p, lift=0.0015)
            if len(seg):
                self._path = self.server.scene.add_line_segments(
                    '/path', seg, (40, 40, 120), thickness=2.0, thickness_units='screen')
            for node in self._mark_nodes:
                node.remove()
            self._mark_nodes = [self.server.scene.add_icosphere(
                f'/marks/{i}', radius=0.0025, color=MARK_RGB.get(res, MARK_RGB['false']),
                position=tuple(map(float, pt + np.array([0.002, 0, 0]))))
                for i, (pt, res) in enumerate(d.marks(None if end else t))]
            self.g_clock.content = f'replay {t:.1f} s of {d.duration:.1f} s'

    # -- for tests and benches --------------------------------------------------------------

    def state(self) -> dict:
        """What the page shows now, as the server holds it (tests compare it with the report)."""
        return {'mode': self.mode, 'url': self.url,
                'numbers': self.debrief.numbers() if self.debrief is not None else None,
                'numbers_text': self.g_numbers.content,
                'coverage_text': self.g_cov.content, 'gauge_text': self.g_gauge.content,
                'cue': self.cue, 'banner': self.g_banner.content,
                'live_marks': len(self._live_marks), 'status': self.g_status.content,
                'lesions': [(le.name, le.status) for le in self.debrief.lesions]
                if self.debrief is not None else [],
                'lesions_visible': bool(self._lesion_nodes),
                'normal': [(nm.name, nm.status, nm.label) for nm in self.debrief.normal]
                if self.debrief is not None else [],
                'feel_again': self.g_feel_md.content if self.g_feel.visible else '',
                'skin_frames': self.stats.skin_frames, 'clients': len(self.server.get_clients())}

    def close(self) -> None:
        self.server.stop()
        close_door(self.door)


def coverage_fractions(grid, face_levels) -> dict:
    """{level: area share 0..1} of the coverage ``grid``'s region pressed at that level or
    deeper, from ``face_levels`` (m,) 0..3 (as ``CoverageGrid.fraction`` for its own state)."""
    a = grid.areas / grid.areas.sum()
    return {k: float(a[face_levels > i].sum()) for i, k in enumerate(LEVELS)}


def _segments_lifted(points: np.ndarray, lift: float) -> np.ndarray:
    """``points`` (..., 3) [m] each moved ``lift`` [m] outward (away from the chest-wall
    centre) so what is drawn there shows above the skin."""
    n = np.linalg.norm(points, axis=-1, keepdims=True)
    return points + lift * points / np.where(n > 0, n, 1.0)


def _segments(path: np.ndarray, lift: float) -> np.ndarray:
    """(n, 2, 3) segments of a NaN-split polyline, lifted ``lift`` [m] above the skin."""
    if len(path) < 2:
        return np.zeros((0, 2, 3))
    p = _segments_lifted(path, lift)
    a, b = p[:-1], p[1:]
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    return np.stack([a[ok], b[ok]], axis=1)

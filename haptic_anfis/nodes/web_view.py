"""``web_view``: the trainee's screen in a browser (``haptic_anfis.view``), in a process of its own.

Reads the loop topics at its own ``rate`` (default 30 Hz), best effort, polled from their DDS
readers (``nodes/polled.py``) as serialized bytes (``nodes/cdr.py``): the newest pose and force
command, and every contact sample still held (a bounded best-effort queue: the coverage map needs
the path, not just the newest point) — no callback per 1 kHz message and no acknowledgement the
loop's publishers would wait for. ``exam/marks`` is a plain subscription (rare, must not be lost).

The node wires topics and parameters to two ROS-free parts: the page of the live session
(:class:`~haptic_anfis.view.live.LivePage`: the trainee's page at ``http://host:port/``, the
instructor's console behind its token on ``console_port``, the exam session they show) and the
page's case against the loop nodes' (:class:`~haptic_anfis.session.case_choice.CaseChoices`: a
case chosen on the console switches every running case node and the falcon driver's force scale,
or none; a case set on a node from outside, seen on ``/parameter_events``, is followed or said).
The console's address is printed on stdout at start (the token stays out of ROS's log files).
"""
from __future__ import annotations

import collections
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from rcl_interfaces.msg import ParameterEvent
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import (HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_parameter_events)
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from . import cdr
from .. import interfaces as ifc
from ..cases import library
from ..device.falcon import RATED_FORCE
from ..device.loop_health import behind_text
from ..session.case_choice import CASE_NODE_NAMES, CaseChoices, case_force_scale
from ..session.case_switch import CaseSwitch
from ..view.browser import free_port
from ..view.live import ConsoleSettings, LivePage
from ._case import declare_case
from .base import HapticNode
from .executor import node_in_thread
from .parameters import CASE_PARAMS  # noqa: F401 (a case node: the registry reads it here)
from .parameters import CASE_KEYS, Param, declare_parameters, non_negative, positive
from .polled import PolledSubscription
from .runtime import run_node
from .session import STATUS_QOS, STATUS_TOPIC, inputs_matched, parse_status

#: newest sample, best effort
NEWEST = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.BEST_EFFORT)
#: the contact samples since the last frame (1 kHz / 30 Hz ~ 33), best effort; older ones drop
CONTACT_QUEUE = QoSProfile(depth=200, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.BEST_EFFORT)
#: [s] how long a closing page's last words get to reach the browsers (viser sends them from a
#: thread of its own; a server stopped at once drops them)
CLOSE_FLUSH = 0.3


def _port(v):
    return None if 0 < v < 65536 else 'expected 1..65535'


PARAMS = [
    Param('port', 8080, 'TCP port of the page (http://host:port/)', _port),
    Param('host', '127.0.0.1', "address the page listens on ('0.0.0.0': every interface)"),
    Param('rate', 30.0, 'frame rate of the page [Hz]: pose, force, dent, gauge', positive),
    Param('coverage_rate', 5.0, 'coverage map repaint rate [Hz]', positive),
    Param('exam_config', '', "scoring settings ('' = config/exam.yaml)"),
    Param('dent', True, 'draw the dent under the probe (FE skin displacements)'),
    Param('controls', True, "serve the instructor's console (case, trainee id, start / stop, "
          "the class's record) on console_port; false: the trainee's page alone"),
    Param('console_port', 8081, "TCP port of the instructor's console", _port),
    Param('console_host', '127.0.0.1', "address the instructor's console listens on "
          "('0.0.0.0': every interface; it still needs the token)"),
    Param('console_token_file', '', "file whose first line is the console's token (>= 16 "
          "letters, digits, - or _); '' = $HAPTIC_ANFIS_CONSOLE_TOKEN, else a new random one, "
          'printed at start'),
    Param('trainee', '', "trainee id preset on the instructor's console"),
    Param('db', '', "trainee record file for the sessions the page stops ('' = the record's "
                    'default: $HAPTIC_ANFIS_DB, else the user data directory)'),
    Param('case_switch_timeout', 15.0, "how long the instructor's case choice waits for the "
          'running case nodes to load the case [s], per phase (contact_detector, force_server, '
          'visualizer, examiner and the falcon driver; then the recorder); one that refuses or '
          'has not answered by then cancels the choice (the nodes that switched go back, the '
          'page says who failed)', positive),
    Param('max_force', RATED_FORCE, "the falcon driver's force clamp [N]: each case's force "
          'mapping is chosen against it, and the gauge marks the tissue force at it', positive),
    Param('force_scale', 0.0, "the falcon driver's tissue -> device force scale when the session "
          "set it (the gauge's clamp mark follows it, a case chosen here leaves it); 0 = each "
          "case's own force mapping (haptic_anfis.cases.force_mapping), which a case chosen "
          "here sets on the driver", non_negative),
]


class WebView(HapticNode):
    def __init__(self, name: str = 'web_view', **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        self._requests: collections.deque = collections.deque()
        case = declare_case(self, lambda c: self._requests.append(('switched', c)))
        console = (ConsoleSettings(p['console_port'], p['console_host'], p['console_token_file'],
                                   p['trainee'], p['db']) if p['controls'] else None)
        self.page = LivePage(case, self.get_parameter('random_case_seed').value >= 0,
                             p['exam_config'], p['dent'], p['port'], p['host'], console,
                             [c.name for c in library().ready()], self._requests,
                             p['max_force'], p['force_scale'], self.log)
        self.app, self.console = self.page.app, self.page.console
        self._param_clients: dict = {}
        self.choices = CaseChoices(self, self.page, p['case_switch_timeout'], self._requests,
                                   None if p['force_scale'] > 0
                                   else case_force_scale(p['max_force']))
        self._inputs = {k: PolledSubscription(self, t, topic, q) for k, t, topic, q in (
            ('pose', PoseStamped, ifc.TOPIC_POSE, NEWEST),
            ('force', WrenchStamped, ifc.TOPIC_COMMAND, NEWEST),
            ('contact', JointState, ifc.TOPIC_CONTACT, CONTACT_QUEUE))}
        self.create_subscription(PointStamped, ifc.TOPIC_MARKS, self._on_mark, 10)
        self.create_subscription(DiagnosticArray, ifc.TOPIC_DIAGNOSTICS, self._on_diagnostics, 10)
        self.create_subscription(String, STATUS_TOPIC, self._on_status, STATUS_QOS)
        # a case set on a node from outside the page (ros2 param set): follow it or say so
        self.create_subscription(ParameterEvent, '/parameter_events', self._on_parameter_event,
                                 qos_profile_parameter_events)
        self._pose = self._force = None   # newest (stamp [s], (x, y, z) [m] / [N])
        self._contact = None               # newest contact message's values
        self.malformed = 0                 # loop messages that could not be read
        self.timer = self.create_timer(1.0 / p['rate'], self._frame)
        self.cov_timer = self.create_timer(1.0 / p['coverage_rate'], self.page.draw_coverage)
        self.get_logger().info(f'page at {self.app.url}')
        print(f'web_view: open {self.app.url} in a browser', flush=True)
        if self.console is not None:   # stdout only: the token stays out of ROS's log files
            print(f"web_view: instructor's console at {self.console.url} (token from "
                  f'{self.page.token_from}; give it to the instructor only)', flush=True)

    # -- the graph, for the case choices (session/case_choice.py) ---------------------------

    def switch(self, phases, values: dict, per_node: dict, running: bool = False) -> CaseSwitch:
        return CaseSwitch(self, phases, values, self._param_clients, time.monotonic(),
                          self.params['case_switch_timeout'], running=running,
                          per_node=per_node)

    def set_own(self, values: dict) -> str:
        """Set the page's case parameters in one set (its case callback switches once)."""
        res = self.set_parameters_atomically([Parameter(k, value=v) for k, v in values.items()])
        return '' if res.successful else (res.reason or 'refused')

    def own(self) -> tuple[str, int]:
        return tuple(self.get_parameter(k).value for k in CASE_KEYS)

    def running_nodes(self) -> set[str]:
        return set(self.get_node_names())

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def log(self, level: str, msg: str) -> None:
        """``msg`` at ``level`` ('info', 'warning', 'error'; rclpy: one severity per call
        site)."""
        if level == 'error':
            self.get_logger().error(msg)
        elif level == 'warning':
            self.get_logger().warning(msg)
        else:
            self.get_logger().info(msg)

    # -- inputs -----------------------------------------------------------------------------

    def _on_status(self, m: String) -> None:
        d = parse_status(m.data) or {}
        self.choices.on_status(d.get('node'), d.get('pid'))

    def _on_parameter_event(self, ev) -> None:
        """A case node's case parameters declared (at its start) or set (while it runs)."""
        name = ev.node.rsplit('/', 1)[-1]
        if name not in CASE_NODE_NAMES:
            return
        for declared, params in ((True, ev.new_parameters), (False, ev.changed_parameters)):
            values = {p.name: parameter_value_to_python(p.value) for p in params
                      if p.name in CASE_KEYS}
            if values:
                stamp = ev.stamp.sec * 1_000_000_000 + ev.stamp.nanosec
                self._requests.append(('reported', (name, values, declared, stamp)))

    def _on_diagnostics(self, m: DiagnosticArray) -> None:
        """The falcon driver's report on its servo loop (ROS's diagnostics topic): when it fell
        behind (the force came late: :func:`~haptic_anfis.device.loop_health.behind_text`).
        Other statuses are not ours."""
        for st in m.status:
            if st.name == ifc.LOOP_DIAGNOSTIC:
                v = {kv.key: kv.value for kv in st.values}
                try:
                    text = behind_text(int(v.get('windows', 0)), int(v.get('windows_behind', 0)),
                                       v.get('cause', ''))
                except ValueError:   # not our driver's numbers: say nothing rather than wrong
                    continue
                self.page.show_loop_health(text)

    def _on_mark(self, m: PointStamped) -> None:
        if self._collecting():
            q = m.point
            self.page.add_mark(_stamp(m), (q.x, q.y, q.z))

    def _take(self) -> None:
        """The newest pose and force command, and every contact sample since the last frame,
        read from their serialized bytes (``nodes/cdr.py``): rclpy's message objects cost tens
        of microseconds of this node's interpreter per contact sample, a thousand a second."""
        for k, read in (('pose', cdr.read_pose_position), ('force', cdr.read_wrench_stamped)):
            b = self._inputs[k].take_newest()
            if b is not None:
                try:
                    stamp, _, v = read(b)
                except ValueError as exc:
                    self._malformed(exc)
                    continue
                setattr(self, '_' + k, (stamp * 1e-9, v))
        sub = self._inputs['contact']
        while (b := sub.take()) is not None:
            try:
                stamp, _, v, _ = cdr.read_joint_state(b)
            except ValueError as exc:
                self._malformed(exc)
                continue
            self._contact = v
            if self._collecting():
                self.page.session.add_contact_values(stamp * 1e-9, v)
        if self._collecting() and self._pose is not None:
            self.page.session.add_pose(*self._pose)

    def _collecting(self) -> bool:
        """Whether samples go into the session: while it runs, and not while a case choice is
        being loaded or the loop nodes' cases differ (set outside the page)."""
        return self.page.running and not self.choices.busy

    def _malformed(self, exc: ValueError) -> None:
        self.malformed += 1
        self.get_logger().warning(f'{exc}: not drawn ({self.malformed} so far)',
                                  throttle_duration_sec=5.0)

    # -- frames -----------------------------------------------------------------------------

    def _frame(self) -> None:
        while self._requests:
            self._handle(*self._requests.popleft())
        self._handle('tick', None)
        self._take()
        contact = None if self._contact is None else ifc.contact_geometry(self._contact)
        try:
            self.page.draw(None if self._pose is None else self._pose[1], contact,
                           None if self._force is None else self._force[1])
        except ValueError as exc:   # a bad sample: skip the frame, keep drawing
            self.get_logger().warning(f'frame skipped: {exc}', throttle_duration_sec=5.0)

    def _handle(self, what: str, arg) -> None:
        """One request (queued by the console's threads and this node's callbacks)."""
        page, c = self.page, self.choices
        try:
            if what == 'start':
                page.start()
            elif what == 'stop':
                page.stop()
            elif what == 'case':
                c.choose(arg)
            elif what == 'tick':   # a choice's answers; the nodes' cases every second
                c.tick()
            elif what == 'restarted':   # a case node in a new process: give it our case
                c.resync(arg)
            elif what == 'switched':   # our own case parameter was set
                page.load_case(arg)
                c.check()   # set from outside, on this node alone: the loop is not
            elif what == 'reported':   # a case node's case, as its parameter events say
                c.reported(*arg)
        except Exception as exc:   # keep serving: say it on the page
            self.get_logger().error(f'{what}: {exc}')
            self.page.tell(f'{what} failed: {exc}')

    def ready_condition(self) -> tuple[bool, str]:
        return inputs_matched(self, [self.resolve_topic_name(s.topic)
                                     for s in self._inputs.values()])

    def close(self) -> None:
        st = self.app.stats
        self.get_logger().info(f'{st.skin_frames} skin frames ({st.drawing_rate():.1f} Hz while '
                               f'drawing), {st.probe_updates} probe updates')
        for s in self._inputs.values():
            s.destroy()
        self.page.close(CLOSE_FLUSH)


def _stamp(m) -> float:
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def web_view_in_thread(parameters: dict, other: str = 'view_feeder'):
    """A :class:`WebView` with ``parameters`` ({name: value}) spun by a thread of its own, and a
    plain node ``other`` on its context (to publish the loop topics to it): a context manager
    yielding ``(web_view, other)`` (:func:`~haptic_anfis.nodes.executor.node_in_thread`). For
    tests and benches (the node's real home is its own process). The instructor's console
    gets a free port unless ``parameters`` name one (two tests at once on the default clash)."""
    return node_in_thread(WebView, {'console_port': free_port(), **parameters}, other)


def main(args=None) -> None:
    raise SystemExit(run_node(WebView, args))


if __name__ == '__main__':
    main()

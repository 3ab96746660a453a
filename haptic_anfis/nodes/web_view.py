"""``web_view``: the trainee's screen in a browser (``haptic_anfis.view``), in a process of its own.

Reads the loop topics at its own ``rate`` (default 30 Hz), best effort, polled from their DDS
readers (``nodes/polled.py``) as serialized bytes (``nodes/cdr.py``): the newest pose and force
command, and every contact sample still held (a bounded best-effort queue: the coverage map needs
the path, not just the newest point) — no callback per 1 kHz message and no acknowledgement the
loop's publishers would wait for. It draws the probe, the force, the dent from the FE skin
displacements, the coverage painted per pressure level (folded at ``coverage_rate``), the gauge
and cue, the exam clock; lesions stay hidden until the debrief. ``exam/marks`` is a plain
subscription (rare, must not be lost).

Two doors. The trainee's page (``http://host:port/``) shows the exam, live and its debrief, and
nothing else. The instructor's controls are on the instructor's console (``controls``: its own
page and port, ``console_port``, bound to ``console_host``, 127.0.0.1 by default, behind a secret
token: ``http://console_host:console_port/<token>/``; :mod:`haptic_anfis.view.console`): a case
or a blind random one (set on the loop nodes' writable ``case`` / ``random_case_seed``
parameters, and on this node), the trainee id, start (a fresh session, the clock from zero) and
stop (the session scored as ``exam report`` scores it, stored for the trainee, the debrief shown
on the trainee's page), and the class's record. The token comes from ``console_token_file``,
else ``$HAPTIC_ANFIS_CONSOLE_TOKEN``, else a new random one; the console's address is printed on
stdout at start (not into ROS's log files). Both servers answer only their own origin
(:mod:`haptic_anfis.view.doors`). A case set on a loop node from outside the page (``ros2 param
set``) is seen on ``/parameter_events`` (:mod:`.case_watch`): the page follows when every running
case node took one case, else the console says which node runs what and nothing is collected
until they agree.
"""
from __future__ import annotations

import collections
import random
import time
from dataclasses import dataclass, replace

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from . import cdr
from .. import interfaces as ifc
from ..cases import library
from ..cases.force_mapping import tissue_clamp
from ._case import CASE_PARAMS, declare_case  # noqa: F401 (CASE_PARAMS: in config)
from .parameters import Param, declare_parameters, positive
from .runtime import run_node
from .base import HapticNode
from ..session.case_switch import CaseSwitch
from ..session.case_watch import CASE_KEYS, CaseWatch
from .polled import PolledSubscription

#: newest sample, best effort
NEWEST = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.BEST_EFFORT)
#: the contact samples since the last frame (1 kHz / 30 Hz ~ 33), best effort; older ones drop
CONTACT_QUEUE = QoSProfile(depth=200, history=HistoryPolicy.KEEP_LAST,
                           reliability=ReliabilityPolicy.BEST_EFFORT)
#: nodes whose case the instructor's choice switches (those that are running), in phases: the
#: recorder (its case is the bag's label) only once every node of the loop has switched
CASE_PHASES = (('contact_detector', 'force_server', 'visualizer', 'examiner'), ('recorder',))
CASE_NODE_NAMES = frozenset(n for ph in CASE_PHASES for n in ph)
#: [s] how long a closing page's last words get to reach the browsers (viser sends them from a
#: thread of its own; a server stopped at once drops them)
CLOSE_FLUSH = 0.3
#: what the console says while the loop nodes load a case
SWITCHING = 'switching to {} ...'
#: what the trainee's page says meanwhile (no case name: a blind draw stays blind)
PAGE_SWITCHING = 'the case is being switched: nothing is collected meanwhile'
#: what the trainee's page says while the loop nodes' cases differ
PAGE_SPLIT = 'the loop nodes are not on one case: nothing is collected until the instructor ' \
    'chooses one'


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
          'visualizer, examiner; then the recorder); one that refuses or has not answered by '
          'then cancels the choice (the nodes that switched go back, the page says who failed)',
          positive),
]


class WebView(HapticNode):
    def __init__(self, name: str = 'web_view', **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        self._requests: collections.deque = collections.deque()
        case = declare_case(self, lambda c: self._requests.append(('switched', c)))
        self.blind = self.get_parameter('random_case_seed').value >= 0
        from ..view.build import case_view
        self.cv = case_view(case.name if case else None, p['exam_config'] or None, p['dent'])
        from ..view.app import ViewApp
        self.app = ViewApp(self.cv.vertices, self.cv.faces, self.cv.region_faces,
                           self.cv.config.thresholds, port=p['port'], host=p['host'],
                           title='haptic_anfis', deformation=self.cv.deformation,
                           max_force=tissue_clamp(case))
        self.console = None
        if p['controls']:
            self.console = self._open_console(p, [c.name for c in library().ready()], case)
        self._inputs = {k: PolledSubscription(self, t, topic, q) for k, t, topic, q in (
            ('pose', PoseStamped, ifc.TOPIC_POSE, NEWEST),
            ('force', WrenchStamped, ifc.TOPIC_COMMAND, NEWEST),
            ('contact', JointState, ifc.TOPIC_CONTACT, CONTACT_QUEUE))}
        self.create_subscription(PointStamped, ifc.TOPIC_MARKS, self._on_mark, 10)
        from diagnostic_msgs.msg import DiagnosticArray
        self.create_subscription(DiagnosticArray, ifc.TOPIC_DIAGNOSTICS, self._on_diagnostics, 10)
        from .session import STATUS_QOS, STATUS_TOPIC
        self._pids: dict[str, int] = {}   # case node -> the process it last said it runs in
        self._chosen = False   # the instructor chose a case here: a restarted node needs it
        self.create_subscription(String, STATUS_TOPIC, self._on_status, STATUS_QOS)
        # a case set on a node from outside the page (ros2 param set): follow it or say so
        from rcl_interfaces.msg import ParameterEvent
        from rclpy.qos import qos_profile_parameter_events
        self._watch = CaseWatch(self._page_case())
        self._split = ''   # which node runs what, while the loop nodes' cases differ
        self._checked = time.monotonic()
        self.create_subscription(ParameterEvent, '/parameter_events', self._on_parameter_event,
                                 qos_profile_parameter_events)
        self._pose = self._force = None   # newest (stamp [s], (x, y, z) [m] / [N])
        self._contact = None               # newest contact message's values
        self.malformed = 0                 # loop messages that could not be read
        self.loop_text = ''                # the haptic loop's health ('' while it keeps up)
        self.t_start = time.monotonic()
        self.running = True   # the session collects from the start; "start" begins afresh
        self._param_clients: dict = {}
        self._switch = None   # the instructor's case choice while the loop nodes load it
        self.timer = self.create_timer(1.0 / p['rate'], self._frame)
        self.cov_timer = self.create_timer(1.0 / p['coverage_rate'], self._coverage)
        self._running_shown(True)
        self.get_logger().info(f'page at {self.app.url}')
        print(f'web_view: open {self.app.url} in a browser', flush=True)
        if self.console is not None:   # stdout only: the token stays out of ROS's log files
            print(f"web_view: instructor's console at {self.console.url} (token from "
                  f'{self._token_from}; give it to the instructor only)', flush=True)

    def _open_console(self, p: dict, cases: list[str], case):
        """The instructor's console with its controls wired to this node's requests."""
        from ..view.app import BLIND
        from ..view.console import ConsoleApp
        from ..view.doors import load_token
        token, self._token_from = load_token(p['console_token_file'])
        console = ConsoleApp(p['console_port'], token, cases, host=p['console_host'],
                             db=p['db'] or None)
        console.g_trainee.value = p['trainee']
        if case is not None:
            console.show_case_choice(BLIND if self.blind else case.name)
        console.on_start = lambda: self._requests.append(('start', None))
        console.on_stop = lambda: self._requests.append(('stop', None))
        console.on_case = lambda name: self._requests.append(('case', name))
        return console

    def _tell(self, msg: str, page: str | None = None) -> None:
        """``msg`` to the instructor (the console; without one, the log has it), ``page`` (if
        given) on the trainee's page: what a trainee may read (no trainee id, no case a blind
        exam hides, no record)."""
        if self.console is not None:
            self.console.message(msg)
        if page is not None:
            self.app.message(page)

    def _running_shown(self, running: bool) -> None:
        """The trainee's page and the console's buttons for an exam running or not."""
        self.app.set_exam_running(running, self.blind, self.cv.name or '')
        if self.console is not None:
            self.console.set_running(running)

    # -- inputs -----------------------------------------------------------------------------

    def _on_status(self, m: String) -> None:
        """A case node in a new process (the session restarted it after it died) comes back on
        the session's first case: after a choice on this page, it is given the page's."""
        from .session import parse_status
        d = parse_status(m.data) or {}
        name, pid = d.get('node'), d.get('pid')
        if name not in CASE_NODE_NAMES or not isinstance(pid, int):
            return
        old, self._pids[name] = self._pids.get(name), pid
        if old is not None and old != pid and self._chosen:
            self._requests.append(('restarted', name))

    def _on_parameter_event(self, ev) -> None:
        """A case node's case parameters declared (at its start) or set (while it runs)."""
        name = ev.node.rsplit('/', 1)[-1]
        if name not in CASE_NODE_NAMES:
            return
        from rclpy.parameter import parameter_value_to_python
        for declared, params in ((True, ev.new_parameters), (False, ev.changed_parameters)):
            values = {p.name: parameter_value_to_python(p.value) for p in params
                      if p.name in CASE_KEYS}
            if values:
                stamp = ev.stamp.sec * 1_000_000_000 + ev.stamp.nanosec
                self._requests.append(('reported', (name, values, declared, stamp)))

    def _on_diagnostics(self, m) -> None:
        """The falcon driver's report on its servo loop (ROS's diagnostics topic): the
        instructor's console and the log say when the loop fell behind (the force came late:
        :func:`~haptic_anfis.device.loop_health.behind_text`); the trainee's page does not (a
        machine's health is not the trainee's to act on). Other statuses are not ours."""
        from ..device.loop_health import behind_text
        for st in m.status:
            if st.name == ifc.LOOP_DIAGNOSTIC:
                v = {kv.key: kv.value for kv in st.values}
                try:
                    text = behind_text(int(v.get('windows', 0)), int(v.get('windows_behind', 0)),
                                       v.get('cause', ''))
                except ValueError:   # not our driver's numbers: say nothing rather than wrong
                    continue
                if text and text != self.loop_text:
                    self.get_logger().warning(f'haptic loop behind: {text}')
                self.loop_text = text
                if self.console is not None:
                    self.console.show_loop_health(text)

    def _on_mark(self, m: PointStamped) -> None:
        if self._collecting():
            q = m.point
            self.cv.session.add_mark(_stamp(m), (q.x, q.y, q.z))
            self.app.show_mark((q.x, q.y, q.z))   # on the page at once: the trainee sees it

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
                self.cv.session.add_contact_values(stamp * 1e-9, v)
        if self._collecting() and self._pose is not None:
            self.cv.session.add_pose(*self._pose)

    def _collecting(self) -> bool:
        """Whether samples go into the session: while it runs, and not while a case choice is
        being loaded or the loop nodes' cases differ (set outside the page)."""
        return self.running and self._switch is None and not self._split

    def _malformed(self, exc: ValueError) -> None:
        self.malformed += 1
        self.get_logger().warning(f'{exc}: not drawn ({self.malformed} so far)',
                                  throttle_duration_sec=5.0)

    def _contact_state(self):
        return None if self._contact is None else ifc.contact_geometry(self._contact)

    # -- frames -----------------------------------------------------------------------------

    def _frame(self) -> None:
        while self._requests:
            self._handle(*self._requests.popleft())
        if self._switch is not None:
            self._handle('switching', None)
        elif time.monotonic() - self._checked > 1.0:   # a node that left or came back
            self._handle('check', None)
        self._take()
        pose = None if self._pose is None else np.array(self._pose[1])
        force = None if self._force is None else np.array(self._force[1])
        if self.app.mode == 'live':
            try:
                self.app.show_live(pose, self._contact_state(), force,
                                   time.monotonic() - self.t_start if self.running else None)
            except ValueError as exc:   # a bad sample: skip the frame, keep drawing
                self.get_logger().warning(f'frame skipped: {exc}', throttle_duration_sec=5.0)

    def _coverage(self) -> None:
        if self.running and self.app.mode == 'live':
            s = self.cv.session
            s.update_coverage()
            self.app.set_coverage(s.grid.level_per_face(), s.grid.fraction())

    # -- the instructor's requests (queued by the page's threads, handled here) -------------

    def _handle(self, what: str, arg) -> None:
        try:
            if what == 'start':
                self._restart()
                self._running_shown(True)
                self._tell('exam started')
            elif what == 'stop':
                self.running = False
                self.app.show_over()   # before the scoring: the page says so at once
                self._running_shown(False)
                from ..view.debrief import Debrief
                report = self.cv.session.report()
                report['case'] = 'blind case' if self.blind else (self.cv.name or 'default')
                trainee = self.console.trainee if self.console is not None else ''
                stored = self._store(trainee, report) if trainee else ''
                self.app.show_debrief(Debrief(report, self.cv.session))   # no record here
                self._tell("exam stopped: the debrief is on the trainee's page" + stored
                           + self._feel_again(report))
                if self.console is not None:
                    self.console.refresh(select=trainee or None)
            elif what == 'case':
                self._choose_case(arg)
            elif what == 'switching':   # the loop nodes' answers to a case choice
                self._follow_switch()
            elif what == 'restarted':   # a case node in a new process: give it our case
                self._resync(arg)
            elif what == 'switched':   # our own case parameter was set
                self._load_case(arg)
                self._check_cases()   # set from outside, on this node alone: the loop is not
            elif what == 'reported':   # a case node's case, as its parameter events say
                self._watch.report(*arg)
                self._check_cases()
            elif what == 'check':
                self._check_cases()
        except Exception as exc:   # keep serving: say it on the page
            self.get_logger().error(f'{what}: {exc}')
            self._tell(f'{what} failed: {exc}')

    def _feel_again(self, report: dict) -> str:
        """The instructor's "feel it again" commands of the stopped exam's lesions (a blind
        case's too: the console may name it), as a sentence ('' for none)."""
        from ..view.feel_again import feel_commands
        cmds = feel_commands(self.cv.name or 'default', report['lesions'],
                             self.cv.config.thresholds)
        return ''.join(f'; feel lesion {k} again: {v}' for k, v in cmds.items())

    def _store(self, trainee: str, report: dict) -> str:
        """Store the stopped exam in the trainee record under ``trainee``, with the
        case's real name (a blind case is named in the record, not on the page); returns what
        to say on the page. A record that cannot be written is said, never raised."""
        from ..record import level_of_case_name, store_session, utc_iso
        name = self.cv.name or 'default'
        started = time.time() - (time.monotonic() - self.t_start)   # wall clock at the start
        try:
            sid = store_session(self.params['db'] or None, trainee, dict(report, case=name),
                                source='run', case_level=level_of_case_name(name),
                                started_utc=utc_iso(started))
        except (ValueError, OSError) as exc:   # RecordError is a ValueError
            self.get_logger().error(f'trainee record: {exc}')
            return f'; NOT stored in the trainee record: {exc}'
        return f'; stored as session {sid} of trainee {trainee}'

    def _restart(self) -> None:
        from ..exam import ExamSession
        s = self.cv.session
        self.cv.session = ExamSession(s.surface, s.subject, s.config)
        self.t_start = time.monotonic()
        self.running = True
        self.app.set_coverage(self.cv.session.grid.level_per_face(),
                              self.cv.session.grid.fraction())

    def _choose_case(self, name: str) -> None:
        """The instructor chose ``name`` (or the blind entry): ask the running case nodes to
        switch (:class:`~.case_switch.CaseSwitch`); the page follows once they all have
        (:meth:`_follow_switch`). One choice at a time."""
        from rclpy.parameter import Parameter

        from ..view.app import BLIND
        if self._switch is not None:
            self._show_case_choice(self._switch.entry)   # the dropdown shows the pending one
            raise ValueError(f'{self._switch.label} is still being loaded; choose again when '
                             'it is done')
        blind = name == BLIND
        # both, set together: every node's parameters then say what it runs (a seed alone
        # would leave the old name readable with `ros2 param get`)
        params = [Parameter('case', value='' if blind else name),
                  Parameter('random_case_seed',
                            value=random.SystemRandom().randrange(2**31) if blind else -1)]
        before, shown = self._current_case()
        self._switch = _Choice(
            CaseSwitch(self, CASE_PHASES, params, self._param_clients, time.monotonic(),
                       self.params['case_switch_timeout']),
            'a blind random case' if blind else f'case {name}', blind, name, before, shown)
        self._tell(SWITCHING.format(self._switch.label), page=PAGE_SWITCHING)
        self._follow_switch()

    def _resync(self, name: str) -> None:
        """Set the page's case on the restarted node ``name`` (after a choice in progress, if
        one is: asked again then); no samples meanwhile, as for a choice."""
        if self._switch is not None:
            self._requests.append(('restarted', name))   # after the one in progress
            return
        params, entry = self._current_case()
        ch = _Choice(CaseSwitch(self, [[name]], params, self._param_clients, time.monotonic(),
                                self.params['case_switch_timeout'], running=True),
                     f'{name} (restarted) back on the case chosen', self.blind, entry, params,
                     entry, resync=True)
        self._switch = ch
        self._tell(SWITCHING.format(ch.label), page=PAGE_SWITCHING)

    def _current_case(self) -> tuple[list, str]:
        """The page's case: its ``case`` / ``random_case_seed`` parameters (as rclpy
        ``Parameter`` s) and its dropdown entry (a case name or the blind entry)."""
        from rclpy.parameter import Parameter

        from ..view.app import BLIND
        return ([Parameter(k, value=v) for k, v in zip(CASE_KEYS, self._page_case())],
                BLIND if self.blind else (self.cv.name or 'default'))

    def _page_case(self) -> tuple[str, int]:
        """The page's own ``(case, random_case_seed)`` parameter values."""
        return tuple(self.get_parameter(k).value for k in CASE_KEYS)

    def _follow_switch(self) -> None:
        """The case nodes' answers: all switched, the page switches too; one refused or silent,
        the others are sent back to the case before (no samples collected until they answered),
        then the exam starts afresh on it; a node that cannot be sent back stops the exam.
        ``_switch`` changes once, at the end (other threads read it: never None in between)."""
        ch = self._switch
        nxt = None   # what follows: the revert of a refused choice, else nothing
        try:
            out = ch.switch.poll(time.monotonic())
            if out is not None:   # what they run now (their events may come later: older)
                values = {p.name: p.value for p in ch.switch.params}
                now = self.get_clock().now().nanoseconds
                for name in out.switched:
                    self._watch.report(name, values, stamp_ns=now)
            if out is None:
                nxt = ch
            elif ch.resync:   # a restarted node given the page's case
                self._resynced(ch, out)
            elif ch.failed:   # the revert of a refused choice has been answered
                self._reverted(ch, out)
            else:
                nxt = self._answered(ch, out)
        finally:   # an error ends the choice (_handle says it on the page)
            self._switch = nxt
        if nxt is None:   # the choice's own line stays (it says what it left split, if any)
            self._check_cases(quiet=True)

    def _check_cases(self, quiet: bool = False) -> None:
        """The cases the loop nodes reported against the page's (not during a choice: its own
        answers decide): all on it, the page goes on (collecting again after a split); every
        running one set from outside to one other case, the page takes it and the exam starts
        afresh; else samples stop until they agree, and the page says which node runs what."""
        if self._switch is not None:
            return
        self._checked = time.monotonic()
        running = set(self.get_node_names()) & CASE_NODE_NAMES
        v = self._watch.verdict(self._page_case(), running, self.blind)
        if v.action == 'follow':
            from rclpy.parameter import Parameter
            res = self.set_parameters_atomically([Parameter(k, value=x)
                                                  for k, x in zip(CASE_KEYS, v.case)])
            if res.successful:   # the page loads it at the next frame ('switched')
                self.blind, self._chosen, self._split = v.case[1] >= 0, True, ''
                from ..view.app import BLIND
                entry = BLIND if self.blind else v.case[0] or 'default'
                self._show_case_choice(entry)
                what = 'a random case' if self.blind else f'case {entry}'
                self._say(f'every loop node was switched to {what} outside this page: the page '
                          'follows, the exam starts afresh')
                return
            text = f'the page cannot show it ({res.reason})'
            if text != self._split:
                self._split = text  # before it is said: whoever reads the line sees the state
                self._say(f'every loop node was switched to another case outside this page, but '
                          f'{text}. Nothing is collected: choose a case here', error=True)
            return
        if v.action == 'split' and v.text != self._split:
            self._split = v.text  # before it is said (a reader of the line saw it collecting)
            if not quiet:
                self._say(f'the loop nodes are on different cases (set outside this page): '
                          f'{v.text}. Nothing is collected: choose a case here to put them on '
                          'one', error=True)
        elif v.action == 'ok' and self._split:
            self._split = ''
            if not quiet and self.running:
                self._say("every loop node is on the page's case again: collecting again")

    def _say(self, msg: str, error: bool = False) -> None:
        """``msg`` in the log and to the instructor; an error says on the trainee's page that
        nothing is collected (without the node and case names)."""
        if error:   # rclpy: one severity per call site
            self.get_logger().warning(msg)
        else:
            self.get_logger().info(msg)
        self._tell(msg, page=PAGE_SPLIT if error else None)

    def _show_case_choice(self, entry: str) -> None:
        if self.console is not None:
            self.console.show_case_choice(entry)

    def _answered(self, ch: _Choice, out) -> _Choice | None:
        """Every case node answered ``ch``: the page switches, or the choice is refused and the
        nodes that may have switched are sent back (returned: the revert to follow)."""
        # ours, in one set: declare_case's callback switches once
        res = self.set_parameters_atomically(ch.switch.params) if out.ok else None
        if res is not None and res.successful:
            self.blind, self._chosen = ch.blind, True
            self.get_logger().info(f'{ch.label}: {out.describe()}')
            self._show_case_choice(ch.entry)
            self._tell(('blind random case chosen' if self.blind else ch.label)
                       + f' ({out.describe()})')
            return None
        why = out.describe() if res is None else f'the page cannot show it: {res.reason}'
        msg = f'{ch.label} NOT chosen: {why}'
        self.get_logger().error(msg)
        self._show_case_choice(ch.shown)
        back = ch.switch.revert(ch.before, time.monotonic())
        if back is None:
            self._reverted(replace(ch, failed=msg), None)
            return None
        self._tell(f'{msg}; sending back: {", ".join(back.names)} ...')
        return replace(ch, switch=back, failed=msg, label=f'the return to {self._kept(ch)}')

    def _resynced(self, ch: _Choice, out) -> None:
        """The restarted node answered: on the page's case again, or (refused, silent) the
        loop is split: the exam stops, as when a revert fails."""
        if out.ok:
            self._say(f'{ch.label}: {out.describe()}')
            return
        self._stop_split(ch, f'{ch.label} FAILED ({out.describe()})')

    def _stop_split(self, ch: _Choice, msg: str) -> None:
        """A node could not be put on the page's case: the loop may be split between two, so
        the exam stops (nothing more collected) and the page says ``msg`` and why."""
        msg += (f': the loop may not be on {self._kept(ch)}; the exam is stopped: choose a case '
                'again')
        self.running = False
        self._running_shown(False)
        self.get_logger().error(msg)
        self._tell(msg, page='the exam is stopped: the instructor chooses a case again')

    def _kept(self, ch: _Choice) -> str:
        from ..view.app import BLIND
        return 'its blind case' if ch.shown == BLIND else f'case {ch.shown}'

    def _reverted(self, ch: _Choice, out) -> None:
        """A refused choice's end: the nodes sent back answered (``out``; None: none to send
        back). The samples of the attempt were not collected: a running exam starts afresh on
        the case kept; a node that could not be sent back stops it (the loop may be split)."""
        msg = ch.failed
        if out is not None and not out.ok:
            self._stop_split(ch, f'{msg}; sending back FAILED ({out.describe()})')
            return
        if out is not None:
            msg += f'; sent back: {", ".join(out.switched)}'
        if self.running:
            self._restart()
            msg += f'; the exam starts afresh on {self._kept(ch)}'
        self._tell(msg)

    def _load_case(self, case) -> None:
        from ..view.build import case_view
        self.cv = case_view(case.name if case else None, self.params['exam_config'] or None,
                            self.params['dent'])
        self.app.deformation = self.cv.deformation
        self.app.max_force = tissue_clamp(case)
        self.app.set_surface(self.cv.vertices, self.cv.faces, self.cv.region_faces)
        self._restart()
        self._running_shown(True)

    def ready_condition(self) -> tuple[bool, str]:
        from .session import inputs_matched
        return inputs_matched(self, [self.resolve_topic_name(s.topic)
                                     for s in self._inputs.values()])

    def close(self) -> None:
        st = self.app.stats
        self.get_logger().info(f'{st.skin_frames} skin frames ({st.drawing_rate():.1f} Hz while '
                               f'drawing), {st.probe_updates} probe updates')
        for s in self._inputs.values():
            s.destroy()
        if self.app.mode == 'live':   # the session ends (exam run --view): its debrief follows
            self.app.show_over()
            time.sleep(CLOSE_FLUSH)
        self.app.close()
        if self.console is not None:
            self.console.close()


@dataclass(frozen=True)
class _Choice:
    """The instructor's case choice while the loop nodes load it: the switch, what the page
    calls it, whether it is blind, its dropdown entry, the parameters before (to go back to),
    the dropdown entry before (a case name or the blind entry); ``failed``: the page's line
    once the choice was refused and ``switch`` is its revert."""
    switch: CaseSwitch
    label: str
    blind: bool
    entry: str
    before: list
    shown: str
    failed: str = ''
    resync: bool = False   # a restarted node given the page's case (no choice of its own)


def _stamp(m) -> float:
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def web_view_in_thread(parameters: dict, other: str = 'view_feeder'):
    """A :class:`WebView` with ``parameters`` ({name: value}) spun by a thread of its own, and a
    plain node ``other`` on its context (to publish the loop topics to it): a context manager
    yielding ``(web_view, other)`` (:func:`~haptic_anfis.nodes.executor.node_in_thread`). For
    tests and benches (the node's real home is its own process). The instructor's console
    gets a free port unless ``parameters`` name one (two tests at once on the default clash)."""
    from ..view.browser import free_port
    from .executor import node_in_thread
    return node_in_thread(WebView, {'console_port': free_port(), **parameters}, other)


def main(args=None) -> None:
    raise SystemExit(run_node(WebView, args))


if __name__ == '__main__':
    main()

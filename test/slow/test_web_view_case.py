"""The instructor's case choice on the browser page: every running case node switches and the
page follows, or none switches and the page says who failed (the trainee must not press on one
case while the page scores another)."""
from __future__ import annotations

import threading
import time

import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('viser')
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.nodes._case import declare_case  # noqa: E402
from haptic_anfis.view.app import BLIND  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402

pytestmark = pytest.mark.ros
LOOP = ('contact_detector', 'force_server')


class FakeCaseNode:
    """A node named like a case node with the case parameters: its switch waits for ``gate``
    (a threading.Event, when given) and raises ``refuse`` when given (a node that cannot load
    the case), ``refuse_back`` for its own default scene; ``loaded``: the cases it switched
    to."""

    def __init__(self, ctx, name: str, refuse: str = '', gate: threading.Event | None = None,
                 case: str = '', refuse_back: str = '') -> None:
        self.node = rclpy.create_node(name, context=ctx,
                                      parameter_overrides=[Parameter('case', value=case)])
        self.loaded: list = []
        self.refuse, self.gate, self.refuse_back = refuse, gate, refuse_back
        self.asked = threading.Event()
        declare_case(self.node, self._switch)

    def _switch(self, case) -> None:
        self.asked.set()
        if self.gate is not None:
            assert self.gate.wait(60.0)
        if self.refuse:
            raise ValueError(self.refuse)
        if self.refuse_back and case is None:   # takes a case, cannot go back to its own
            raise ValueError(self.refuse_back)
        self.loaded.append(None if case is None else case.name)

    def param(self, name: str):
        return self.node.get_parameter(name).value


@pytest.fixture
def page_with():
    """``page_with(timeout=15.0)``: a web_view node (its own context, spun by a thread) whose
    case choice waits ``timeout`` [s] for the case nodes."""
    from contextlib import ExitStack

    from haptic_anfis.nodes.web_view import web_view_in_thread
    with ExitStack() as stack:
        def make(timeout: float = 15.0):
            return stack.enter_context(web_view_in_thread(
                {'port': free_port(), 'case_switch_timeout': timeout}, 'instructor'))[0]
        yield make


@pytest.fixture
def loop_nodes():
    """``loop_nodes(page, names=LOOP, **{name: dict(refuse=, gate=, case=)})``: fake case
    nodes spun beside the page (each on a thread of its own: a slow one does not hold the
    others); the page's graph lists them on return."""
    made: list = []
    stop = threading.Event()
    executors: list = []

    def make(page, names=LOOP, **how) -> dict:
        ex = MultiThreadedExecutor(num_threads=4, context=page.context)
        executors.append(ex)
        fakes = {n: FakeCaseNode(page.context, n, **how.get(n, {})) for n in names}
        for f in fakes.values():
            ex.add_node(f.node)
            f.executor = ex
            made.append(f)

        def spin() -> None:
            while not stop.is_set():
                ex.spin_once(timeout_sec=0.01)
        th = threading.Thread(target=spin, daemon=True)
        th.start()
        made.append(th)
        wait_for(lambda: set(names) <= {n for n, _ in page.get_node_names_and_namespaces()},
                 30.0)
        return fakes

    yield make
    stop.set()
    for m in made:
        if isinstance(m, FakeCaseNode) and m.gate is not None:
            m.gate.set()
    for m in made:
        if isinstance(m, threading.Thread):
            m.join(5)
    for ex in executors:
        ex.shutdown(timeout_sec=1.0)
    for m in made:
        if isinstance(m, FakeCaseNode) and not getattr(m, 'dead', False):
            m.node.destroy_node()


def wait_for(cond, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        time.sleep(0.02)
    assert cond()


def choose(page, name: str) -> str:
    """The instructor picks ``name`` in the dropdown; returns the page's line once the choice
    is settled."""
    time.sleep(0.2)   # the page has taken what the nodes reported at their start
    wait_for(lambda: not page._requests, 10.0)
    time.sleep(0.1)
    before = page.console.last_message
    page.console.on_case(name)
    wait_for(lambda: page.console.last_message not in (before, '')
             and 'switching' not in page.console.last_message and page.choices.switch is None, 60.0)
    return page.console.last_message


def test_every_running_case_node_switches_then_the_page(page_with, loop_nodes):
    page = page_with()
    fakes = loop_nodes(page, (*LOOP, 'recorder'))
    loads, load = [], page.page.load_case
    page.page.load_case = lambda case: (loads.append(case), load(case))
    msg = choose(page, 'normal')
    assert 'switched: contact_detector, force_server, recorder' in msg, msg
    assert 'not running: visualizer, examiner' in msg, msg
    for f in fakes.values():
        assert f.loaded == ['normal'] and f.param('case') == 'normal'
        assert f.param('random_case_seed') == -1
    wait_for(lambda: page.page.cv.name == 'normal', 30.0)   # the page shows the case it scores
    assert page.get_parameter('case').value == 'normal' and not page.page.blind
    assert page.console.g_case.value == 'normal'
    time.sleep(0.3)
    assert [c.name for c in loads] == ['normal']   # loaded once (both parameters in one set)


def test_a_case_chosen_live_brings_its_own_force_scale_to_the_driver(page_with, loop_nodes):
    """Each case has its own tissue -> device force mapping: the driver (a node with the
    driver's writable force_scale) is set to the chosen case's with the loop, and the page's
    gauge marks the tissue force at the clamp under that mapping; a refused choice sends the
    driver back to the kept case's scale."""
    from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult

    from haptic_anfis.cases import library
    from haptic_anfis.cases.force_mapping import case_force_mapping, tissue_clamp
    page = page_with()
    fakes = loop_nodes(page)
    drv = rclpy.create_node('falcon_driver', context=page.context)
    drv.declare_parameter('force_scale', 1.0, ParameterDescriptor(read_only=False))
    seen: list[float] = []
    drv.add_on_set_parameters_callback(lambda ps: (seen.extend(q.value for q in ps),
                                                   SetParametersResult(successful=True))[1])
    fakes['force_server'].executor.add_node(drv)
    try:
        wait_for(lambda: 'falcon_driver' in page.get_node_names(), 30.0)
        dense = 'lib_m_dense_idc20_d12'
        msg = choose(page, dense)
        assert 'falcon_driver' in msg.split('switched: ')[1].split(';')[0], msg
        want = case_force_mapping(library().get(dense)).force_scale
        assert drv.get_parameter('force_scale').value == pytest.approx(want) and want < 1.0
        wait_for(lambda: page.page.cv.name == dense, 30.0)
        assert page.app.max_force == pytest.approx(tissue_clamp(library().get(dense)))
        assert page.app.max_force == pytest.approx(8.9 / want)
        fakes['force_server'].refuse = 'model file unreadable'
        msg = choose(page, 'normal')
        assert 'NOT chosen' in msg and 'sent back: ' in msg, msg
        normal = case_force_mapping(library().get('normal')).force_scale
        assert seen == pytest.approx([want, normal, want]) and normal != pytest.approx(want)
        assert drv.get_parameter('force_scale').value == pytest.approx(want)
    finally:
        fakes['force_server'].executor.remove_node(drv)
        drv.destroy_node()


def test_a_blind_choice_draws_the_same_case_everywhere(page_with, loop_nodes):
    page = page_with()
    fakes = loop_nodes(page, force_server={'case': 'normal'})   # started with case:=normal
    msg = choose(page, BLIND)
    assert msg.startswith('blind random case chosen'), msg
    seed = page.get_parameter('random_case_seed').value
    assert seed >= 0 and page.page.blind and page.console.g_case.value == BLIND
    wait_for(lambda: page.page.cv.name == fakes['force_server'].loaded[-1], 30.0)   # the same draw
    for f in fakes.values():   # no old name left readable on any node
        assert f.param('random_case_seed') == seed and f.param('case') == ''
        assert f.loaded[-1] == page.page.cv.name


def test_a_refusal_sends_the_others_back_and_the_page_keeps_its_case(page_with, loop_nodes):
    """The loop refuses: the switched nodes go back, the recorder is never asked (its bag
    keeps one case), the dropdown shows the case kept, and the exam starts afresh on it (the
    samples of the attempt were not collected)."""
    page = page_with()
    fakes = loop_nodes(page, (*LOOP, 'recorder'),
                       force_server={'refuse': 'model file unreadable'})
    page.console.g_case.value = 'normal'   # as the instructor's dropdown shows it
    t0 = page.page.t_start
    msg = choose(page, 'normal')
    assert msg.startswith('case normal NOT chosen'), msg
    assert 'force_server refused: model file unreadable' in msg, msg
    assert 'not asked: recorder' in msg and 'sent back: contact_detector' in msg, msg
    assert 'the exam starts afresh on case default' in msg, msg
    cd = fakes['contact_detector']
    assert cd.param('case') == '' and cd.loaded == ['normal', None]   # answered before that
    assert fakes['recorder'].loaded == [] and not fakes['recorder'].asked.is_set()
    assert page.get_parameter('case').value == '' and page.page.cv.name in (None, 'default')
    assert page.console.g_case.value == 'default' and page.page.t_start > t0
    time.sleep(0.5)   # the dropdown set by the page is no choice: nothing more happens
    assert page.choices.switch is None and page.console.last_message == msg


def test_a_node_that_does_not_answer_in_time_cancels_the_choice(page_with, loop_nodes):
    """contact_detector is still loading at the timeout: the choice is refused, both are sent
    back, and the page collects nothing until the late switch and then the revert landed."""
    page = page_with(timeout=10.0)   # force_server answers within it, even on a loaded machine
    gate = threading.Event()   # contact_detector loads the case only when the test says so
    fakes = loop_nodes(page, contact_detector={'gate': gate})
    page.console.on_case('normal')
    wait_for(lambda: 'sending back: force_server, contact_detector' in page.console.last_message,
             60.0)
    msg = page.console.last_message
    assert 'NOT chosen' in msg and 'switched: force_server' in msg, msg
    assert 'no answer from contact_detector' in msg, msg
    time.sleep(0.3)
    assert page.choices.switch is not None and not page._collecting()   # still on the new case
    gate.set()
    wait_for(lambda: page.choices.switch is None, 60.0)
    msg = page.console.last_message
    assert 'sent back: force_server, contact_detector' in msg, msg
    assert 'the exam starts afresh on case default' in msg and page._collecting(), msg
    for f in fakes.values():   # the late switch landed, then the revert after it
        assert f.param('case') == '' and f.loaded[-1:] == [None]
    assert fakes['contact_detector'].loaded == ['normal', None]
    assert page.get_parameter('case').value == ''


def test_a_node_that_cannot_be_sent_back_stops_the_exam(page_with, loop_nodes):
    """force_server refuses the choice; contact_detector switched but then refuses the way
    back: the loop may be split, so the page stops the exam and says so."""
    page = page_with()
    loop_nodes(page, force_server={'refuse': 'no model'},
               contact_detector={'refuse_back': 'mesh file gone'})
    msg = choose(page, 'normal')
    assert 'sending back FAILED' in msg and 'contact_detector refused: mesh file gone' in msg
    assert 'the exam is stopped' in msg and not page.page.running and not page._collecting()


def test_samples_are_not_collected_while_the_nodes_switch(page_with, loop_nodes):
    """The loop may be on either case until every node answered: nothing goes into the
    session then; a second choice meanwhile is refused and the dropdown shows the first."""
    page = page_with()
    gate = threading.Event()
    fakes = loop_nodes(page, contact_detector={'gate': gate})
    page.console.on_case('normal')
    assert fakes['contact_detector'].asked.wait(30.0)
    assert page.choices.switch is not None and not page._collecting()
    page.console.on_case('two_lesions')
    wait_for(lambda: 'still being loaded' in page.console.last_message, 10.0)
    assert page.console.g_case.value == 'normal'
    gate.set()
    wait_for(lambda: page.choices.switch is None, 30.0)
    assert page.get_parameter('case').value == 'normal' and page._collecting()
    assert page.console.g_case.value == 'normal'


def test_a_page_started_blind_shows_the_blind_entry():
    from haptic_anfis.nodes.web_view import web_view_in_thread
    with web_view_in_thread({'port': free_port(), 'random_case_seed': 3}, 'x') as (node, _):
        assert node.page.blind and node.console.g_case.value == BLIND


def test_a_restarted_case_node_is_given_the_case_chosen(page_with, loop_nodes):
    """After a choice on the page, force_server dies and the session starts it again (a new
    process, on the session's first case): the page gives it the case chosen."""
    import json

    from std_msgs.msg import String

    from haptic_anfis.nodes.session import STATUS_QOS, STATUS_TOPIC
    page = page_with()
    fakes = loop_nodes(page)
    feeder = rclpy.create_node('status_feeder', context=page.context)
    try:
        pub = feeder.create_publisher(String, STATUS_TOPIC, STATUS_QOS)

        def say(pid: int) -> None:   # what force_server's process says when it is up
            pub.publish(String(data=json.dumps({'node': 'force_server', 'state': 'ready',
                                                'detail': '', 't': 1.0, 'pid': pid})))
        wait_for(lambda: say(1001) or page.choices.pids.get('force_server') == 1001, 30.0)
        assert 'switched: contact_detector, force_server' in choose(page, 'normal')
        old = fakes['force_server']
        old.executor.remove_node(old.node)
        old.node.destroy_node()
        old.dead = True
        wait_for(lambda: 'force_server' not in {
            n for n, _ in page.get_node_names_and_namespaces()}, 30.0)
        new = loop_nodes(page, ('force_server',))['force_server']   # on the first case again
        assert new.param('case') == '' and new.loaded == []
        say(1002)
        wait_for(lambda: new.param('case') == 'normal', 60.0)
        assert new.loaded == ['normal']
        wait_for(lambda: page.choices.switch is None, 30.0)
        msg = page.console.last_message
        assert 'force_server (restarted) back on the case chosen' in msg, msg
        assert page.page.running and page._collecting()
    finally:
        feeder.destroy_node()


def test_a_restart_before_any_choice_is_left_alone(page_with, loop_nodes):
    """Without a choice on the page the restarted node's own case is the session's: no set."""
    import json

    from std_msgs.msg import String

    from haptic_anfis.nodes.session import STATUS_QOS, STATUS_TOPIC
    page = page_with()
    fakes = loop_nodes(page)
    feeder = rclpy.create_node('status_feeder', context=page.context)
    try:
        pub = feeder.create_publisher(String, STATUS_TOPIC, STATUS_QOS)
        for pid in (1001, 1002):
            msg = String(data=json.dumps({'node': 'force_server', 'state': 'ready', 'pid': pid}))
            wait_for(lambda: pub.publish(msg) or page.choices.pids.get('force_server') == pid, 30.0)
        time.sleep(0.3)
        assert page.choices.switch is None and not page._requests and fakes['force_server'].loaded == []
    finally:
        feeder.destroy_node()


def test_a_case_set_on_one_node_outside_the_page_stops_collecting_until_they_agree(
        page_with, loop_nodes):
    """``ros2 param set /force_server case normal`` beside the page: the trainee would press on
    one case while the page scores another. The page says which node runs what and collects
    nothing until the nodes agree again."""
    page = page_with()
    fakes = loop_nodes(page)
    assert page._collecting()
    fs = fakes['force_server'].node
    assert fs.set_parameters([Parameter('case', value='normal')])[0].successful
    wait_for(lambda: 'different cases' in page.console.last_message, 30.0)
    msg = page.console.last_message
    assert 'force_server on case normal' in msg, msg
    assert "contact_detector on the page's case" in msg and not page._collecting()
    assert page.page.cv.name != 'normal'   # the page keeps its case
    assert fs.set_parameters([Parameter('case', value='')])[0].successful
    wait_for(lambda: 'collecting again' in page.console.last_message, 30.0)
    assert page.choices.split == '' and page._collecting()


def test_a_case_set_on_the_page_alone_from_outside_says_the_loop_did_not_follow(
        page_with, loop_nodes):
    """``ros2 param set /web_view case normal``: the page draws the case, the loop nodes it
    never heard from still run the session's: said, nothing collected."""
    page = page_with()
    loop_nodes(page)
    assert page.set_parameters([Parameter('case', value='normal')])[0].successful
    wait_for(lambda: 'different cases' in page.console.last_message, 30.0)
    msg = page.console.last_message
    assert 'contact_detector on the default scene; force_server on the default scene' in msg
    wait_for(lambda: page.page.cv.name == 'normal', 30.0)   # loaded (the check may come first)
    assert not page._collecting()


def test_every_loop_node_set_outside_to_one_case_is_followed_by_the_page(page_with, loop_nodes):
    page = page_with()
    fakes = loop_nodes(page)
    for f in fakes.values():
        assert f.node.set_parameters([Parameter('case', value='normal')])[0].successful
    wait_for(lambda: page.page.cv.name == 'normal', 60.0)
    assert page.get_parameter('case').value == 'normal' and page.console.g_case.value == 'normal'
    assert 'switched to case normal outside this page' in page.console.last_message
    wait_for(lambda: not page._requests, 10.0)
    assert page.choices.split == '' and page._collecting()
    # then a choice on the page puts every node on its case, as before
    assert 'switched: contact_detector, force_server' in choose(page, 'default')
    assert all(f.param('case') == 'default' for f in fakes.values())


def test_the_console_not_the_page_says_when_the_drivers_loop_fell_behind():
    """The falcon driver's report on ROS's diagnostics topic (status 'falcon_driver: servo
    loop'): a line on the instructor's console (and the log) once any window fell behind, none
    while none did, nothing on the trainee's page; another
    node's status and numbers that are not ours change nothing."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from haptic_anfis import interfaces as ifc
    from haptic_anfis.nodes.web_view import web_view_in_thread

    def report(windows, behind, name=ifc.LOOP_DIAGNOSTIC):
        st = DiagnosticStatus(name=name, level=DiagnosticStatus.WARN if behind else
                              DiagnosticStatus.OK, message='...')
        st.values = [KeyValue(key='windows', value=str(windows)),
                     KeyValue(key='windows_behind', value=str(behind)),
                     KeyValue(key='cause', value='the servo runs under the normal scheduler')]
        return DiagnosticArray(status=[st])
    with web_view_in_thread({'port': free_port()}, 'x') as (node, _):
        assert ifc.TOPIC_DIAGNOSTICS in {s.topic_name for s in node.subscriptions}
        node._on_diagnostics(report(2, 0))
        assert node.console.g_loop.content == '' and node.page.loop_text == ''
        node._on_diagnostics(report(3, 1))
        text = node.console.g_loop.content
        assert text.startswith('**haptic loop behind**: the force came late in 1 of 3 check '
                               'windows so far') and text.endswith('normal scheduler')
        assert node.page.loop_text.startswith('the force came late')
        # the machine's health is the instructor's: nothing of it on the trainee's page
        s = node.app.state()
        assert not any('haptic loop' in str(v) or 'check windows' in str(v) for v in s.values())
        node._on_diagnostics(report(9, 9, name='some_other_node: status'))
        node._on_diagnostics(report('x', 'y'))
        assert node.console.g_loop.content == text

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

from haptic_anfis.nodes._case import declare_case  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402

pytestmark = pytest.mark.ros


class FakeCaseNode:
    """A node named like a loop node with the case parameters: its switch takes ``delay`` [s]
    and raises ``refuse`` when given (a node that cannot load the case)."""

    def __init__(self, ctx, name: str, refuse: str = '', delay: float = 0.0,
                 case: str = '') -> None:
        from rclpy.parameter import Parameter
        self.node = rclpy.create_node(name, context=ctx,
                                      parameter_overrides=[Parameter('case', value=case)])
        self.loaded: list = []
        self.refuse, self.delay = refuse, delay
        declare_case(self.node, self._switch)

    def _switch(self, case) -> None:
        time.sleep(self.delay)
        if self.refuse:
            raise ValueError(self.refuse)
        self.loaded.append(None if case is None else case.name)

    def param(self, name: str):
        return self.node.get_parameter(name).value


@pytest.fixture
def page():
    from haptic_anfis.nodes.web_view import web_view_in_thread
    with web_view_in_thread({'port': free_port(), 'case_switch_timeout': 2.0},
                            'instructor') as (node, _):
        yield node


@pytest.fixture
def loop_nodes(page):
    """contact_detector and force_server (fakes) spun beside the page; visualizer and recorder
    not running. Returns a function making them: ``make(**{name: dict(refuse=, delay=)})``."""
    made: list = []
    stop = threading.Event()
    ex = MultiThreadedExecutor(num_threads=4, context=page.context)   # a slow node alone

    def spin() -> None:
        while not stop.is_set():
            ex.spin_once(timeout_sec=0.01)

    def make(**how) -> dict:
        fakes = {n: FakeCaseNode(page.context, n, **how.get(n, {}))
                 for n in ('contact_detector', 'force_server')}
        for f in fakes.values():
            ex.add_node(f.node)
            made.append(f)
        th = threading.Thread(target=spin, daemon=True)
        th.start()
        made.append(th)
        wait_for(lambda: {'contact_detector', 'force_server'} <= {
            n for n, _ in page.get_node_names_and_namespaces()}, 20.0)
        return fakes

    yield make
    stop.set()
    for m in made:
        if isinstance(m, threading.Thread):
            m.join(5)
    ex.shutdown(timeout_sec=1.0)
    for m in made:
        if isinstance(m, FakeCaseNode):
            m.node.destroy_node()


def wait_for(cond, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        time.sleep(0.02)
    assert cond()


def choose(page, name: str) -> str:
    """The instructor picks ``name`` in the dropdown; returns the page's line once the choice
    is settled."""
    before = page.app.g_msg.content
    page.app.on_case(name)
    wait_for(lambda: page.app.g_msg.content not in (before, '')
             and 'switching' not in page.app.g_msg.content and page._switch is None, 30.0)
    return page.app.g_msg.content


def test_every_running_case_node_switches_then_the_page(page, loop_nodes):
    fakes = loop_nodes()
    loads, load = [], page._load_case
    page._load_case = lambda case: (loads.append(case), load(case))
    msg = choose(page, 'normal')
    assert 'switched: contact_detector, force_server' in msg, msg
    assert 'not running: visualizer, recorder' in msg, msg
    for f in fakes.values():
        assert f.loaded == ['normal'] and f.param('case') == 'normal'
        assert f.param('random_case_seed') == -1
    wait_for(lambda: page.cv.name == 'normal', 30.0)   # the page shows the case it scores
    assert page.get_parameter('case').value == 'normal' and not page.blind
    time.sleep(0.3)
    assert [c.name for c in loads] == ['normal']   # loaded once (both parameters in one set)


def test_a_blind_choice_draws_the_same_case_everywhere(page, loop_nodes):
    fakes = loop_nodes(force_server={'case': 'normal'})   # started with case:=normal
    from haptic_anfis.view.app import BLIND
    msg = choose(page, BLIND)
    assert msg.startswith('blind random case chosen'), msg
    seed = page.get_parameter('random_case_seed').value
    assert seed >= 0 and page.blind
    wait_for(lambda: page.cv.name == fakes['force_server'].loaded[-1], 30.0)   # the same draw
    for f in fakes.values():   # no old name left readable on any node
        assert f.param('random_case_seed') == seed and f.param('case') == ''
        assert f.loaded[-1] == page.cv.name


def test_a_refusal_sends_the_others_back_and_the_page_keeps_its_case(page, loop_nodes):
    fakes = loop_nodes(force_server={'refuse': 'model file unreadable'})
    page.app.g_case.value = 'normal'   # as the instructor's dropdown shows it
    msg = choose(page, 'normal')
    assert 'case normal NOT chosen' in msg and 'stays on default' in msg, msg
    assert 'force_server refused: model file unreadable' in msg, msg
    assert 'sent back to it: contact_detector' in msg, msg
    cd = fakes['contact_detector']
    wait_for(lambda: cd.param('case') == '', 10.0)   # the revert landed
    assert cd.loaded == ['normal', None]
    assert page.get_parameter('case').value == '' and page.cv.name in (None, 'default')
    assert page.app.g_case.value == 'default'   # the dropdown shows the case kept ...
    time.sleep(0.5)
    assert page._switch is None and page.app.g_msg.content == msg   # ... without choosing it


def test_a_node_that_does_not_answer_in_time_cancels_the_choice(page, loop_nodes):
    fakes = loop_nodes(contact_detector={'delay': 3.0})   # case_switch_timeout is 2 s
    msg = choose(page, 'normal')
    assert 'NOT chosen' in msg and 'switched: force_server' in msg, msg
    assert 'no answer from contact_detector' in msg, msg
    assert 'sent back to it: force_server, contact_detector' in msg, msg
    for f in fakes.values():   # the late switch lands, then the revert after it
        wait_for(lambda f=f: f.param('case') == '' and f.loaded[-1:] == [None], 20.0)
    assert page.get_parameter('case').value == ''


def test_a_second_choice_while_one_is_loading_is_refused_on_the_page(page, loop_nodes):
    loop_nodes(contact_detector={'delay': 1.0})
    page.app.on_case('normal')
    wait_for(lambda: page._switch is not None, 10.0)
    page.app.on_case('two_lesions')
    wait_for(lambda: 'still being loaded' in page.app.g_msg.content, 10.0)
    wait_for(lambda: page.get_parameter('case').value == 'normal', 30.0)


def test_a_page_started_blind_shows_the_blind_entry():
    from haptic_anfis.nodes.web_view import web_view_in_thread
    from haptic_anfis.view.app import BLIND
    with web_view_in_thread({'port': free_port(), 'random_case_seed': 3}, 'x') as (node, _):
        assert node.blind and node.app.g_case.value == BLIND

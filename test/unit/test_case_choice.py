"""The browser page's case against the loop nodes' (session/case_choice.py), without ROS: the
instructor's choice switches every running case node and the falcon driver's force scale, or
none; a restarted node is given the page's case; a case set outside splits the loop."""
from __future__ import annotations

import collections

import pytest

from haptic_anfis.session.case_choice import (DRIVER, PAGE_SPLIT, PAGE_SWITCHING, CaseChoices)
from haptic_anfis.session.case_switch import SwitchOutcome
from haptic_anfis.view.app import BLIND

LOOP = ['contact_detector', 'force_server']
#: each case's force scale, as cases/force_mapping.py would give it (distinct on purpose)
SCALES = {'': 0.8, 'normal': 0.5, 'dense': 0.3}


class FakeSwitch:
    """A switch whose answer the test sets (None: still waiting)."""

    def __init__(self, phases, values, per_node, running):
        self.phases, self.values, self.per_node, self.running = phases, values, per_node, running
        self.outcome: SwitchOutcome | None = None
        self.back: FakeSwitch | None = None

    @property
    def names(self):
        return [n for ph in self.phases for n in ph]

    def poll(self, now):
        return self.outcome

    def revert(self, values, now, per_node=None):
        sent = [n for n in self.outcome.switched + self.outcome.silent]
        if not sent:
            return None
        self.back = FakeSwitch([sent], values, per_node or {}, True)
        return self.back


class FakeGraph:
    def __init__(self, nodes=(*LOOP, DRIVER)):
        self.switches: list[FakeSwitch] = []
        self.case = ('', -1)
        self.nodes = set(nodes)
        self.refuse_own = ''
        self.logs: list = []

    def switch(self, phases, values, per_node, running=False):
        self.switches.append(FakeSwitch([list(p) for p in phases], dict(values),
                                        dict(per_node), running))
        return self.switches[-1]

    def set_own(self, values):
        if self.refuse_own:
            return self.refuse_own
        self.case = (values['case'], values['random_case_seed'])
        return ''

    def own(self):
        return self.case

    def running_nodes(self):
        return set(self.nodes)

    def now_ns(self):
        return 10**18 + len(self.logs)

    def log(self, level, msg):
        self.logs.append((level, msg))


class FakePage:
    def __init__(self):
        self.blind, self.running, self.name = False, True, ''
        self.lines: list[str] = []
        self.page_lines: list[str] = []
        self.shown: list[str] = []
        self.restarts = 0

    def tell(self, msg, page=None):
        self.lines.append(msg)
        if page is not None:
            self.page_lines.append(page)

    def show_case_choice(self, entry):
        self.shown.append(entry)

    def restart(self):
        self.restarts += 1

    def stop_exam(self, msg):
        self.running = False
        self.tell(msg, page='stopped')


def choices(scaled: bool = True, **graph):
    g, p = FakeGraph(**graph), FakePage()
    asked: list = []

    def scale(name, seed):
        asked.append((name, seed))
        return SCALES['dense' if seed >= 0 else name]
    c = CaseChoices(g, p, 15.0, collections.deque(), scale if scaled else None)
    c.asked = asked
    return c, g, p


def answer(switch: FakeSwitch, refused: dict | None = None):
    names = switch.names
    switch.outcome = SwitchOutcome([n for n in names if n not in (refused or {})],
                                   dict(refused or {}))


def test_a_choice_gives_the_driver_the_chosen_cases_force_scale_with_the_loop():
    c, g, p = choices()
    c.choose('normal')
    s = g.switches[0]
    assert s.phases[0] == ['contact_detector', 'force_server', 'visualizer', 'examiner', DRIVER]
    assert s.phases[1] == ['recorder']
    assert s.values == {'case': 'normal', 'random_case_seed': -1}
    assert s.per_node == {DRIVER: {'force_scale': SCALES['normal']}}
    assert c.busy and p.page_lines == [PAGE_SWITCHING]   # nothing collected meanwhile
    answer(s)
    c.tick()
    assert not c.busy and g.case == ('normal', -1) and c.chosen
    assert p.lines[-1].startswith('case normal (switched: contact_detector') and DRIVER in \
        p.lines[-1]
    assert p.shown[-1] == 'normal'


def test_a_blind_choice_gives_the_driver_the_drawn_cases_scale():
    c, g, p = choices()
    c.choose(BLIND)
    s = g.switches[0]
    seed = s.values['random_case_seed']
    assert s.values['case'] == '' and seed >= 0 and c.asked == [('', seed)]
    assert s.per_node == {DRIVER: {'force_scale': SCALES['dense']}}
    answer(s)
    c.tick()
    assert p.blind and g.case == ('', seed) and p.lines[-1].startswith('blind random case chosen')


def test_a_refused_choice_sends_the_driver_back_to_the_kept_cases_scale():
    c, g, p = choices()
    c.choose('normal')
    answer(g.switches[0], refused={'force_server': 'model file unreadable'})
    c.tick()
    back = g.switches[0].back
    assert back.values == {'case': '', 'random_case_seed': -1}
    assert back.per_node == {DRIVER: {'force_scale': SCALES['']}}
    assert DRIVER in back.names and 'force_server' not in back.names
    assert c.busy and g.case == ('', -1) and p.shown[-1] == 'default'
    answer(back)
    c.tick()
    assert not c.busy and p.restarts == 1
    assert 'NOT chosen: ' in p.lines[-1] and 'the exam starts afresh on case default' in \
        p.lines[-1]


def test_without_the_cases_own_scale_the_driver_is_left_alone():
    """The session set the driver's scale (a user's ``force_scale``): a case chosen keeps it."""
    c, g, _ = choices(scaled=False)
    c.choose('normal')
    s = g.switches[0]
    assert DRIVER not in s.names and s.per_node == {}
    c.on_status(DRIVER, 1)
    c.on_status(DRIVER, 2)
    assert not c.requests


def test_a_restarted_driver_is_given_the_scale_of_the_case_chosen():
    c, g, p = choices()
    c.on_status(DRIVER, 100)
    c.on_status(DRIVER, 101)
    assert not c.requests   # no choice here yet: the session's first case is the page's
    c.choose('normal')
    answer(g.switches[0])
    c.tick()
    c.on_status(DRIVER, 102)   # the session restarted it: back on the session's first scale
    assert list(c.requests) == [('restarted', DRIVER)]
    c.resync(DRIVER)
    s = g.switches[-1]
    assert s.phases == [[DRIVER]] and s.running
    assert s.per_node == {DRIVER: {'force_scale': SCALES['normal']}}
    answer(s)
    c.tick()
    assert not c.busy and p.lines[-1].startswith(f'{DRIVER} (restarted) back on the case chosen')


def test_one_choice_at_a_time():
    c, g, p = choices()
    c.choose('normal')
    with pytest.raises(ValueError, match='case normal is still being loaded'):
        c.choose('dense')
    assert len(g.switches) == 1 and p.shown[-1] == 'normal'


def test_a_case_set_outside_on_one_node_stops_collecting_until_they_agree():
    c, g, p = choices()
    c.reported('force_server', {'case': 'normal'}, False, 5)
    assert c.busy and p.page_lines[-1] == PAGE_SPLIT
    assert 'force_server on case normal' in p.lines[-1]
    assert "contact_detector on the page's case" in p.lines[-1]
    c.reported('force_server', {'case': ''}, False, 6)
    assert not c.busy and p.lines[-1].endswith('collecting again')


def test_every_loop_node_set_outside_to_one_case_is_followed():
    c, g, p = choices(nodes=LOOP)
    for n in LOOP:
        c.reported(n, {'case': 'normal'}, False, 5)
    assert not c.busy and g.case == ('normal', -1) and p.shown[-1] == 'normal'
    assert 'the page follows' in p.lines[-1]


def test_a_case_followed_from_outside_gives_the_driver_its_scale():
    """The loop nodes set from outside (ros2 param set): the page follows, and the driver, no
    case node, is given the case's force scale; nothing is collected until it answered."""
    c, g, p = choices()
    for n in LOOP:
        c.reported(n, {'case': 'normal'}, False, 5)
    s = g.switches[-1]
    assert s.phases == [[DRIVER]] and s.per_node == {DRIVER: {'force_scale': SCALES['normal']}}
    assert c.busy
    answer(s)
    c.tick()
    assert not c.busy and p.lines[-1].startswith(f"{DRIVER} on case normal's force scale")


def test_the_scale_given_the_driver_is_the_cases_own_mapping_against_the_drivers_clamp():
    from haptic_anfis.cases.force_mapping import case_force_mapping
    from haptic_anfis.cases.library import DEFAULT_CASE, library
    from haptic_anfis.session.case_choice import case_force_scale
    lib = library()
    scale, half = case_force_scale(8.9), case_force_scale(4.45)
    drawn = lib.random(7)
    assert scale('', 7) == scale(drawn.name, -1) == case_force_mapping(drawn).force_scale
    assert scale('', -1) == case_force_mapping(lib.get(DEFAULT_CASE)).force_scale
    dense = 'lib_m_dense_idc20_d12'
    assert scale(dense, -1) < 1.0 and half(dense, -1) == pytest.approx(scale(dense, -1) / 2)


def test_the_session_gives_the_page_the_drivers_clamp_and_a_scale_the_user_set():
    """The page chooses each case's scale against the driver's clamp; a scale the user set is
    the page's too (a case chosen then leaves the driver's alone)."""
    from haptic_anfis.session import SessionSpec
    plain = SessionSpec(view=True).view_arguments(controls=True)
    assert not any(a.startswith(('max_force', 'force_scale')) for a in plain)
    user = SessionSpec(view=True, ros_args=('-p', 'falcon_driver:force_scale:=0.5',
                                            '-p', 'max_force:=4.0')).view_arguments(True)
    assert 'force_scale:=0.5' in user and 'max_force:=4.0' in user
    no_driver = SessionSpec(view=True, nodes=('contact_detector', 'force_server'),
                            ros_args=('-p', 'force_scale:=0.5')).view_arguments(True)
    assert not any(a.startswith('force_scale') for a in no_driver)

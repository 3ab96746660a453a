"""The page's watch on the case each loop node reports (no ROS): a case set on one node from
outside the page splits the loop; set on every running node, the page follows."""
from __future__ import annotations

from haptic_anfis.nodes.parameters import effective_case
from haptic_anfis.session.case_watch import CaseWatch

PAGE = ('', -1)
LOOP = {'contact_detector', 'force_server'}


def test_a_name_set_alone_ends_the_draw_and_a_seed_set_alone_replaces_the_name():
    assert effective_case({'case': 'normal'}, ('', 7)) == ('normal', -1)
    assert effective_case({'random_case_seed': 7}, ('normal', -1)) == ('', 7)
    assert effective_case({'case': '', 'random_case_seed': 7}, ('normal', -1)) == ('', 7)
    assert effective_case({'random_case_seed': -1}, ('normal', -1)) == ('normal', -1)
    assert effective_case({'case': ''}, ('', 7)) == ('', 7)   # '' alone keeps the draw


def test_a_node_declaring_its_two_parameters_one_at_a_time_reports_its_case_once_whole():
    """Half a declaration (``case`` '' without its seed) against a blind page is no split: the
    watch waits for the other parameter."""
    w = CaseWatch(start=('', 7))
    w.report('force_server', {'case': ''}, declared=True)
    assert 'force_server' not in w.reported
    assert w.verdict(('', 7), LOOP, blind=True).action == 'ok'
    w.report('force_server', {'random_case_seed': 7}, declared=True)
    assert w.reported['force_server'] == ('', 7)
    assert w.verdict(('', 7), LOOP, blind=True).action == 'ok'
    w.report('force_server', {'use_sim_time': False}, declared=True)   # not a case parameter
    assert w.reported == {'force_server': ('', 7)}


def test_an_event_older_than_the_last_report_of_its_node_is_dropped():
    w = CaseWatch()
    w.report('force_server', {'case': 'normal', 'random_case_seed': -1}, stamp_ns=200)
    w.report('force_server', {'case': 'other'}, stamp_ns=100)   # arrived late: older
    assert w.reported['force_server'] == ('normal', -1)
    w.report('force_server', {'case': ''}, stamp_ns=300)
    assert w.reported['force_server'] == ('', -1)


def test_a_node_that_never_reported_runs_the_session_s_case_not_the_page_s():
    """``ros2 param set /web_view case normal``: the page moved alone; the nodes it never heard
    from still run the session's case."""
    w = CaseWatch(start=PAGE)
    v = w.verdict(('normal', -1), LOOP)
    assert v.action == 'split'
    assert v.text == 'contact_detector on the default scene; force_server on the default scene'
    w.report('contact_detector', {'case': 'normal'})
    w.report('force_server', {'case': 'normal'})
    assert w.verdict(('normal', -1), LOOP).action == 'ok'


def test_every_node_on_the_page_s_case_is_ok_and_the_default_case_is_no_case():
    w = CaseWatch()
    assert w.verdict(PAGE, LOOP).action == 'ok'   # nothing reported: taken as the page's
    w.report('contact_detector', {'case': ''})
    w.report('recorder', {'case': 'default'}, declared=True)   # a session's label of no case
    assert w.verdict(PAGE, LOOP | {'recorder'}).action == 'ok'
    assert w.verdict(('default', -1), LOOP | {'recorder'}).action == 'ok'


def test_one_node_set_outside_splits_the_loop_and_the_page_says_who_runs_what():
    w = CaseWatch()
    w.report('force_server', {'case': 'normal'})
    v = w.verdict(PAGE, LOOP)
    assert v.action == 'split'
    assert v.text == "force_server on case normal; contact_detector on the page's case"
    blind = w.verdict(('', 5), LOOP, blind=True)   # no name on a blind session's page
    assert 'normal' not in blind.text and 'force_server on another case' in blind.text
    w.report('force_server', {'random_case_seed': 9})
    assert 'force_server on a random case' in w.verdict(PAGE, LOOP).text
    w.report('force_server', {'case': '', 'random_case_seed': -1})   # set back: agreed again
    assert w.verdict(PAGE, LOOP).action == 'ok'


def test_every_running_node_set_to_one_case_is_followed_but_a_declared_one_is_not():
    w = CaseWatch()
    w.report('force_server', {'case': 'normal'})
    w.report('contact_detector', {'case': 'normal'})
    w.report('visualizer', {'case': 'other'})    # not running any more: left out
    v = w.verdict(PAGE, LOOP)
    assert (v.action, v.case) == ('follow', ('normal', -1))
    # a node (re)started on another case than the page's is not followed: the page's choice
    # stands (the session gives it the page's case), the loop is split meanwhile
    w.report('contact_detector', {'case': 'normal', 'random_case_seed': -1}, declared=True)
    assert w.verdict(PAGE, LOOP).action == 'split'
    w.report('recorder', {'case': 'normal'})
    assert w.verdict(PAGE, LOOP | {'recorder'}).action == 'split'
    assert w.verdict(PAGE, None).action == 'split'   # unknown running set: every reported node

"""The end of an exam on the trainee's page: "exam over — debrief loading" at once (before the
session is scored, which takes seconds), then the debrief with its "feel it again" commands
(also on the instructor's console); a mark placed during the exam shows on the page as it is
placed."""
from __future__ import annotations

import time

import pytest

pytest.importorskip('rclpy')
pytest.importorskip('viser')

from haptic_anfis.view.browser import free_port  # noqa: E402

pytestmark = pytest.mark.ros


def test_stop_says_exam_over_before_scoring_then_shows_the_debrief(monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_DOMAIN_ID', '117')
    from geometry_msgs.msg import PointStamped

    from haptic_anfis.nodes.web_view import web_view_in_thread
    from haptic_anfis.view.app import OVER
    with web_view_in_thread({'port': free_port()}, 'x') as (node, _):
        m = PointStamped()
        m.point.x, m.point.y, m.point.z = 0.045, 0.0, 0.0
        node._on_mark(m)
        assert node.app.state()['live_marks'] == 1   # drawn as it is placed
        seen = {}
        report = node.page.cv.session.report

        def slow_report(*a, **k):   # what the page says while the session is scored
            seen['status'] = node.app.state()['status']
            seen['cue'] = node.app.state()['cue']
            return report(*a, **k)
        monkeypatch.setattr(node.page.cv.session, 'report', slow_report)
        node._requests.append(('stop', None))
        end = time.monotonic() + 30.0
        while time.monotonic() < end and node.app.mode != 'debrief':
            time.sleep(0.05)
        assert node.app.mode == 'debrief'
        assert OVER in seen['status'] and seen['cue'] == OVER and 'running' not in seen['status']
        s = node.app.state()
        assert s['banner'] == '' and s['live_marks'] == 0   # the debrief draws the marks scored
        # "feel it again": the command on the instructor's console and in the debrief
        end = time.monotonic() + 30.0   # said after the debrief is shown
        while time.monotonic() < end and 'exam stopped' not in node.console.last_message:
            time.sleep(0.05)
        msg = node.console.last_message
        assert 'feel lesion idc again: haptic-anfis sim --case default --view' in msg, msg
        # the debrief's panels are filled after the mode turns: read them once it is all said
        assert 'haptic-anfis sim --case default' in node.app.state()['feel_again']


def test_the_gauge_says_the_clamp_in_tissue_force_at_the_cases_scale():
    """The gauge shows tissue force; the device clamps at its rated force over the case's force
    scale, so "beyond the device's force" is said there (a case with no dataset: the rated
    force itself)."""
    from haptic_anfis.cases import library
    from haptic_anfis.cases.force_mapping import case_force_mapping
    from haptic_anfis.device.falcon import RATED_FORCE
    from haptic_anfis.cases.force_mapping import tissue_clamp
    lib = library()
    dense = lib.get('lib_m_dense_idc25_d15')
    assert tissue_clamp(dense) == pytest.approx(RATED_FORCE / case_force_mapping(dense).force_scale)
    assert tissue_clamp(dense) > RATED_FORCE
    assert tissue_clamp(None) == pytest.approx(tissue_clamp(lib.get('default')))
    assert tissue_clamp(lib.get('benign_fibrous')) == RATED_FORCE   # not ready: no dataset

"""The live session's page (view/live.py) without ROS: the gauge's clamp mark under the force
mapping in force, a case loaded afresh, start / stop and the marks collected."""
from __future__ import annotations

import collections

import pytest

pytest.importorskip('viser', reason='the view extra (pip install .[view]) is not installed')

from haptic_anfis.cases.force_mapping import tissue_clamp  # noqa: E402
from haptic_anfis.cases.library import library  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402
from haptic_anfis.view.live import LivePage  # noqa: E402

DENSE = 'lib_m_dense_idc20_d12'


def page(case=None, **kw):
    kw.setdefault('max_force', 8.9)
    return LivePage(case, False, '', False, free_port(), '127.0.0.1', None, [],
                    collections.deque(), **kw)


def test_the_gauge_marks_the_clamp_in_tissue_force_under_the_mapping_in_force():
    dense, normal = library().get(DENSE), library().get('normal')
    p = page(dense, max_force=4.0)
    try:
        assert p.app.max_force == pytest.approx(tissue_clamp(dense, 4.0)) and p.name == DENSE
        assert p.app.max_force > 4.0   # the case's scale is < 1: the clamp is further in tissue
        p.load_case(normal)   # a case switched live: its own mapping
        assert p.app.max_force == pytest.approx(tissue_clamp(normal, 4.0)) and p.name == 'normal'
    finally:
        p.close(0.0)
    fixed = page(dense, force_scale=0.5)   # the session set the driver's scale
    try:
        assert fixed.app.max_force == pytest.approx(8.9 / 0.5)
        fixed.load_case(normal)
        assert fixed.app.max_force == pytest.approx(8.9 / 0.5)
    finally:
        fixed.close(0.0)


def test_a_stopped_exam_shows_its_debrief_and_a_start_begins_afresh():
    p = page()
    try:
        p.add_mark(1.0, (0.04, 0.01, 0.0))
        assert len(p.session.marks) == 1
        p.stop()
        assert not p.running and p.app.mode != 'live'
        p.start()
        assert p.running and p.app.mode == 'live' and len(p.session.marks) == 0
    finally:
        p.close(0.0)

"""The class overview's flags: stalled (no progress in the last sessions) and drifting (deep
coverage falling), from sessions as the record gives them."""
from __future__ import annotations

from haptic_anfis.record import store_session
from haptic_anfis.record.overview import DRIFT_POINTS, drifting, overview, overview_csv, stalled


def s(score: float, deep: float) -> dict:
    return {'score': score, 'coverage_pct': {'light': 90.0, 'medium': 80.0, 'deep': deep}}


def test_stalled_is_no_new_best_score_and_no_new_level_in_the_last_three():
    flat = [s(50, 60), s(60, 60), s(55, 60), s(58, 60), s(60, 60)]
    assert stalled(flat, [0] * 5)
    assert not stalled(flat, [0, 0, 0, 0, 1])          # a level mastered: progress
    assert not stalled(flat[:-1] + [s(61, 60)], [0] * 5)   # a new best score: progress
    assert not stalled(flat[:3], [0] * 3)             # too few sessions to judge


def test_drifting_is_mean_deep_coverage_falling_by_the_threshold():
    assert DRIFT_POINTS == 10.0
    assert drifting([s(50, d) for d in (90, 90, 90, 80, 80, 80)])   # 10 points lower
    assert not drifting([s(50, d) for d in (90, 90, 90, 85, 85, 85)])
    assert not drifting([s(50, d) for d in (90, 50, 40)])   # too few sessions


def test_the_overview_reads_the_record_and_writes_csv(tmp_path):
    db = tmp_path / 'r.sqlite'
    rep = {'coverage_pct': {'light': 90.0, 'medium': 70.0, 'deep': 40.0}, 'hits': 1, 'misses': 0,
           'false_marks': 0, 'score': 55.0, 'verdict': 'needs practice', 'duration_s': 60.0,
           'lesions': []}
    store_session(db, 'Zoë', rep)
    (row,) = overview(db)
    assert row['trainee'] == 'Zoë' and row['sessions'] == 1 and row['last_score'] == 55.0
    assert row['mastered_level'] == 0 and not row['stalled'] and not row['drifting']
    assert overview_csv([row]).splitlines()[1].startswith('Zoë,1,')
    assert overview(tmp_path / 'none.sqlite') == []

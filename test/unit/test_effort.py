"""What predicts finding lumps (haptic_anfis.exam.effort): time per pressure level and per area,
the force palpating vs searching; in the report, the debrief's numbers and the trainee record."""
import numpy as np
import pytest

from haptic_anfis.exam.effort import effort

LEVELS = (0.002, 0.005, 0.008)


def _samples():
    """4 s dwelling at (y, z) = (20, 20) mm 9 mm deep at 6 N, then 4 s sliding along z at
    y = -20 mm, 40 mm/s, 4 mm deep at 4 N; 1 kHz; then 1 s off the skin."""
    t = np.arange(0.0, 9.0, 0.001)
    still, slide = t < 4.0, (t >= 4.0) & (t < 8.0)
    y = np.where(still, 0.02, -0.02)
    z = np.where(still, 0.02, -0.08 + 0.04 * (t - 4.0))
    d = np.where(still, 0.009, np.where(slide, 0.004, 0.0))
    c = np.c_[t, np.full_like(t, 0.04), y, z, d, (still | slide).astype(float)]
    f = np.c_[t, np.where(still, 6.0, np.where(slide, 4.0, 0.0)), np.zeros((len(t), 2))]
    return c, f


def test_time_per_level_and_area_and_force_palpating_vs_searching():
    c, f = _samples()
    e = effort(c, f, LEVELS, 0.008)
    assert e['time_at_level_s'] == pytest.approx(
        {'below_light': 0.0, 'light': 4.0, 'medium': 0.0, 'deep': 4.0}, abs=0.01)
    a = e['area_time_s']
    assert a['y+ z+'] == pytest.approx(4.0, abs=0.01) and a['centre'] == 0.0
    assert a['y- z-'] + a['y- z+'] == pytest.approx(4.0, abs=0.01)
    assert a['y- z-'] == pytest.approx(2.0, abs=0.05)   # z < 0 for the slide's first half
    assert e['palpating_s'] == pytest.approx(4.0, abs=0.6)
    assert e['searching_s'] == pytest.approx(4.0, abs=0.6)
    assert e['force_palpating_n'] == pytest.approx(6.0, abs=0.3)
    assert e['force_searching_n'] == pytest.approx(4.0, abs=0.3)
    assert e['palpating_vs_searching_pct'] == pytest.approx(50.0, abs=10.0)


def test_no_samples_give_zeros_and_none():
    e = effort(np.zeros((0, 6)), np.zeros((0, 4)), LEVELS, 0.008)
    assert set(e['time_at_level_s'].values()) == {0.0} and set(e['area_time_s'].values()) == {0.0}
    assert e['force_palpating_n'] is None and e['palpating_vs_searching_pct'] is None


def test_the_report_the_debrief_and_the_record_carry_them(tmp_path):
    from haptic_anfis.record.store import history, session_row, store_session
    from haptic_anfis.view.panel import numbers_markdown
    from haptic_anfis.view.debrief import panel_numbers
    c, f = _samples()
    e = effort(c, f, LEVELS, 0.008)
    report = {'coverage_pct': {'light': 90.0, 'medium': 80.0, 'deep': 70.0}, 'hits': 1,
              'misses': 0, 'false_marks': 0, 'score': 80.0, 'verdict': 'retry',
              'pattern': 'vertical_strip', 'duration_s': 9.0, 'contact_s': 8.0,
              'lesions': [{'name': 'idc', 'found': True, 'level': 'medium',
                           'level_depth_mm': 5.0}], **e}
    n = panel_numbers(report)
    assert n['time_at_level_s'] == e['time_at_level_s']
    text = numbers_markdown(n)
    assert 'deep 4 s' in text and 'force palpating / searching' in text
    row = session_row(report, source='run')
    assert row['force_palpating_n'] == e['force_palpating_n']
    db = tmp_path / 'r.sqlite'
    store_session(db, 'ann', report)
    h = history(db, 'ann')[0]
    assert h['time_at_level_s'] == e['time_at_level_s'] and h['area_time_s'] == e['area_time_s']
    assert h['force_searching_n'] == e['force_searching_n']
    assert h['lesion_levels'] == {'idc': 'medium'}


def test_touching_down_is_neither_mode_and_a_moment_of_dwelling_gives_no_ratio():
    """A strip search with no palpation: each strip starts with 0.3 s touching down in place
    (1 mm deep, 0.5 N), then slides 40 mm/s at 9 mm and 8 N. The touch-downs are not
    palpating (shallower than the light level), and with no palpating time there is no ratio."""
    rows, frows, t = [], [], 0.0
    for k in range(6):
        y = -0.02 + 0.008 * k
        for _ in range(300):   # touch-down in place
            rows.append((t, 0.04, y, -0.04, 0.001, 1.0))
            frows.append((t, 0.5, 0.0, 0.0))
            t += 0.001
        for z in np.arange(-0.04, 0.04, 0.00004):   # slide at depth
            rows.append((t, 0.04, y, z, 0.009, 1.0))
            frows.append((t, 8.0, 0.0, 0.0))
            t += 0.001
    e = effort(np.array(rows), np.array(frows), LEVELS, 0.008)
    assert e['palpating_s'] < 0.5 and e['searching_s'] == pytest.approx(12.0, abs=0.6)
    assert e['force_searching_n'] == pytest.approx(8.0, abs=0.1)
    assert e['palpating_vs_searching_pct'] is None

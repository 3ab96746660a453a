"""Specificity in the trainee record: false marks on normal tissue kept per session (schema v6,
an older file migrated and still read), the trainee's false marks per session, and the higher
levels' mastery limited to false marks per case over the mastery window."""
from __future__ import annotations

import io
import json
import sqlite3

import pytest

from haptic_anfis.record import export_csv, history, load_mastery_config, mastery, store_session
from haptic_anfis.record.db import SCHEMA_VERSION, connect, migrate
from haptic_anfis.record.mastery import MasteryConfig, MasteryLevel, specificity


def report(false_marks=0, on_normal=None, found=True, lesions=('idc',)) -> dict:
    """An exam report as the record reads it; ``on_normal`` None: made before the split."""
    les = [{'name': n, 'found': found} for n in lesions]
    r = {'coverage_pct': {'light': 100.0, 'medium': 100.0, 'deep': 95.0}, 'duration_s': 60.0,
         'contact_s': 50.0, 'hits': sum(x['found'] for x in les),
         'misses': sum(not x['found'] for x in les), 'false_marks': false_marks, 'score': 80.0,
         'verdict': 'pass', 'pattern': 'vertical_strip', 'lesions': les, 'marks': [],
         'notes': [], 'case': 'nod_s_fatty_free'}
    if on_normal is not None:
        r['false_marks_normal'] = on_normal
    return r


def _insert_v5(conn, report_json: str) -> None:
    conn.execute("INSERT INTO sessions (trainee_id, started_utc, stored_utc, source, "
                 "coverage_light, coverage_medium, coverage_deep, lesions, hits, misses, "
                 "false_marks, score, verdict, duration_s, report_json) VALUES ('ann', "
                 "'2026-01-01T00:00:00Z', '2026-01-01T00:00:00Z', 'run', 100, 100, 95, 0, 0, 0, "
                 "3, 80, 'retry', 60, ?)", (report_json,))


def test_a_v5_record_is_migrated_and_takes_the_split_from_the_reports_that_say_it(tmp_path):
    db = tmp_path / 'old.sqlite'
    conn = sqlite3.connect(str(db), isolation_level=None)
    migrate(conn, to=5)   # the schema before specificity
    conn.execute("INSERT INTO trainees VALUES ('ann', '2026-01-01T00:00:00Z')")
    _insert_v5(conn, json.dumps(report(3, on_normal=2)))   # scored since marks name the nodule
    _insert_v5(conn, '{}')                                  # scored before: not known
    _insert_v5(conn, 'not json')                            # a damaged report: still migrated
    conn.close()
    old = history(db, 'ann')
    with connect(db) as c:
        assert c.execute('PRAGMA user_version').fetchone()[0] == SCHEMA_VERSION >= 6
    assert [(s['false_marks'], s['false_marks_normal'], s['false_marks_elsewhere'])
            for s in old] == [(3, 2, 1), (3, None, None), (3, None, None)]
    # a new session stores its split; the CSV has the column, empty where not known
    store_session(db, 'ann', report(2, on_normal=0))
    assert history(db, 'ann')[-1]['false_marks_normal'] == 0
    out = io.StringIO()
    export_csv(db, 'ann', out)
    rows = out.getvalue().splitlines()
    col = rows[0].split(',').index('false_marks_normal')
    assert [r.split(',')[col] for r in rows[1:]] == ['2', '', '', '0']
    sp = mastery(history(db, 'ann'))['specificity']   # every session, whatever its level
    assert (sp['sessions'], sp['clean'], sp['false_marks_per_session']) == (4, 0, 2.75)
    assert (sp['split_sessions'], sp['normal_per_session'], sp['elsewhere_per_session']) == (
        2, 1.0, 1.5)


def test_the_trainees_specificity_over_sessions():
    def s(fm, on):
        return {'false_marks': fm, 'false_marks_normal': on}
    sp = specificity([s(0, 0), s(2, 1), s(0, None), s(1, None)])
    assert sp == {'sessions': 4, 'clean': 2, 'clean_pct': 50.0, 'false_marks_per_session': 0.75,
                  'split_sessions': 2, 'normal_per_session': 0.5, 'elsewhere_per_session': 0.5}
    assert specificity([])['false_marks_per_session'] is None


def sess(false_marks=0, lesions=1, level=1, on_normal=0):
    return {'case_level': level, 'coverage_pct': {'deep': 95.0}, 'palpable_missed': 0,
            'false_marks': false_marks, 'false_marks_normal': on_normal, 'lesions': lesions,
            'not_palpable': []}


def test_the_higher_levels_need_few_false_marks_per_case_over_the_window():
    cfg = MasteryConfig({1: MasteryLevel(max_false_marks_per_case=0.34)})
    free = lambda fm: sess(fm, lesions=0)   # noqa: E731 - a lesion-free (specificity) case
    # one false mark in three cases: 0.33 per case, within the limit
    m = mastery([sess(1), sess(0), sess(0)], cfg)['levels'][1]
    assert m['mastered'] and (m['window_cases'], m['window_false_marks']) == (3, 1)
    # two in three: each session meets its own limit (1), the window does not
    m = mastery([sess(1), sess(1), sess(0)], cfg)
    v = m['levels'][1]
    assert m['mastered_level'] == 0 and v['streak'] == 3 and not v['mastered']
    assert v['false_marks_per_case'] == pytest.approx(2 / 3, abs=1e-4)
    # the streak goes on: the window slides past the first mark and the level is mastered
    v = mastery([sess(1), sess(1), sess(0), sess(0)], cfg)['levels'][1]
    assert v['mastered'] and v['window_false_marks'] == 1 and v['window_cases'] == 3
    # a lesion-free case in the window counts: its false mark too, and it lengthens the window
    v = mastery([sess(0), free(1), sess(1), sess(0)], cfg)['levels'][1]
    assert (v['window_cases'], v['window_false_marks']) == (4, 2) and not v['mastered']
    v = mastery([sess(0), free(0), sess(1), sess(0)], cfg)['levels'][1]
    assert (v['window_cases'], v['window_false_marks']) == (4, 1) and v['mastered']
    # without a window limit (levels 1-2) the same history is mastered
    plain = MasteryConfig({1: MasteryLevel()})
    assert mastery([sess(1), sess(1), sess(0)], plain)['mastered_level'] == 1
    # a session over its own limit still ends the streak and empties the window
    v = mastery([sess(0), sess(0), sess(2), sess(0)], cfg)['levels'][1]
    assert v['streak'] == 1 and v['window_cases'] == 1 and not v['mastered']
    assert v['false_marks'] == 2 and v['cases'] == 4


def test_the_shipped_levels_3_to_5_limit_false_marks_per_case_and_bad_values_are_named(tmp_path):
    cfg = load_mastery_config()
    assert [cfg.levels[L].max_false_marks_per_case for L in (1, 2, 3, 4, 5)] == [
        None, None, 0.34, 0.34, 0.34]
    assert all(cfg.levels[L].max_false_marks == 1 for L in cfg.levels)
    bad = tmp_path / 'exam.yaml'
    for value in ('-0.1', 'yes', '.nan'):
        bad.write_text(f'mastery: {{levels: {{1: {{max_false_marks_per_case: {value}}}}}}}')
        with pytest.raises(ValueError, match='max_false_marks_per_case: expected a number') as e:
            load_mastery_config(bad)
        assert str(bad) in str(e.value)


def test_trainees_progress_says_the_window_and_the_specificity(tmp_path, capsys):
    from haptic_anfis.cli import main
    db = tmp_path / 'rec.sqlite'
    for fm, on in ((1, 1), (0, 0), (0, 0)):
        store_session(db, 'bea', report(fm, on_normal=on), case_level=3)
    assert main(['trainees', 'progress', 'bea', '--db', str(db)]) == 0
    out = capsys.readouterr().out
    assert 'false marks 0.33 per case over the last 3 (at most 0.34)' in out
    assert ('specificity: 2 of 3 session(s) without a false mark (67 %); 0.33 false marks per '
            'session (0.33 on normal tissue, 0.00 elsewhere, of 3 session(s) that tell)') in out


def test_the_progress_figure_shows_the_false_marks_on_normal_tissue(tmp_path, monkeypatch):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex

    from haptic_anfis import palette
    from haptic_anfis.record.figure import save_progress_figure
    figs = []
    monkeypatch.setattr(plt, 'close', figs.append)

    def s(fm, on):
        return {'coverage_pct': {'light': 99.0, 'medium': 95.0, 'deep': 91.0},
                'sensitivity': 1.0, 'false_marks': fm, 'false_marks_normal': on,
                'duration_s': 100.0, 'contact_s': 80.0, 'case_level': 3, 'verdict': 'pass',
                'void': None}
    save_progress_figure('t', [s(2, 1), s(1, None), s(0, 0)], tmp_path / 'p.png', None, 90.0)
    ax = figs[0].axes[2]
    blue = [p.get_height() for p in ax.patches
            if to_hex(p.get_facecolor()) == palette.NORMAL['normal']]
    assert blue == [1, 0, 0]
    assert 'of them on a normal lobule or rib' in [t.get_text()
                                                   for t in ax.get_legend().get_texts()]

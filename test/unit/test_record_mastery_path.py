"""The mastery path needs lumps found: blind draws per trainee, lesion-free cases at every level,
blind case names kept from the trainee, void sessions left out (several simulated trainees)."""
from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from haptic_anfis.cli import main
from haptic_anfis.exam.void import void_reason
from haptic_anfis.record import history, mastery, store_session
from haptic_anfis.record.draw import LESION_FREE_SHARE, draw_seed, next_case
from haptic_anfis.record.mastery import MasteryConfig, MasteryLevel


def graded(name: str, level: int, palpable: bool):
    """A library case as next_case reads it: its graded level and its lesions' palpability."""
    les = [{'lesion': 'idc1', 'palpable': True}] if palpable else []
    return SimpleNamespace(name=name, level=level, tumours=(),
                           grading=lambda: {'level': level, 'lesions': les})


#: three lump cases per level 1-3 and four lesion-free cases (the graded library puts those at 1)
LIB = [graded(f'lump{L}_{k}', L, True) for L in (1, 2, 3) for k in range(3)] + [
    graded(f'free{k}', 1, False) for k in range(4)]
BY_NAME = {c.name: c for c in LIB}
CFG = MasteryConfig({L: MasteryLevel(consecutive_sessions=3) for L in (1, 2, 3)})


def report(case, found=True, deep=95.0, false_marks=0, **extra) -> dict:
    """What exam run stores for a session on ``case`` (a lump found or missed; none to find on
    a lesion-free case)."""
    palpable = any(les['palpable'] for les in case.grading()['lesions'])
    les = [{'name': 'idc1', 'found': found}] if palpable else []
    hits = sum(x['found'] for x in les)
    return {'coverage_pct': {'light': 100.0, 'medium': 100.0, 'deep': deep},
            'duration_s': 120.0, 'contact_s': 90.0, 'hits': hits, 'misses': len(les) - hits,
            'false_marks': false_marks, 'score': 90.0, 'verdict': 'pass', 'pattern': 'strips',
            'lesions': les, 'marks': [], 'notes': [], 'case': case.name, 'blind': True, **extra}


def run_trainee(db, tid: str, sessions: int, skill=lambda case, rng: True, seed=0):
    """``sessions`` blind sessions of trainee ``tid`` (found = skill(case, rng)); the cases drawn
    and their levels."""
    lib = SimpleNamespace(ready=lambda: LIB)
    rng = np.random.default_rng(seed)
    drawn = []
    for _ in range(sessions):
        case, level, _ = next_case(db, tid, lib, CFG)
        store_session(db, tid, report(case, found=skill(case, rng)), case_level=case.level)
        drawn.append((case.name, level))
    return drawn


def test_draws_differ_between_trainees_and_never_repeat_while_a_case_is_unseen(tmp_path):
    db = tmp_path / 'rec.sqlite'
    runs = {t: run_trainee(db, t, 12) for t in ('t01', 't02', 't03', 't04', 't05')}
    assert len({tuple(r[:6]) for r in runs.values()}) == 5   # five trainees, five orders
    for t, drawn in runs.items():
        seen: dict[int, list[str]] = {}
        for name, level in drawn:
            pool = [c.name for c in LIB if (c.level == level) == name.startswith('lump')
                    and name.startswith('lump') == any(
                        x['palpable'] for x in c.grading()['lesions'])]
            mine = seen.setdefault(level if name.startswith('lump') else 0, [])
            if name in mine:    # seen before: every case of its pool was seen as often
                assert all(mine.count(p) >= mine.count(name) for p in pool), (t, drawn)
            mine.append(name)


def test_lumps_must_be_found_to_master_and_lesion_free_cases_come_at_every_level(tmp_path):
    db = tmp_path / 'rec.sqlite'
    good = {t: run_trainee(db, t, 24) for t in ('g1', 'g2', 'g3', 'g4', 'g5', 'g6')}
    drawn = [d for run in good.values() for d in run]
    assert {lv for name, lv in drawn if name.startswith('free')} == {1, 2, 3}
    share = sum(name.startswith('free') for name, _ in drawn) / len(drawn)
    assert 0.1 < share < 0.4 and LESION_FREE_SHARE == 0.25
    for t in good:   # every level passed with three lumps found in a row
        m = mastery(history(db, t), CFG)
        assert m['mastered_level'] == 3 and all(v['met'] >= 3 for v in m['levels'].values())
    # a trainee who covers well and marks nothing never finds a lump: no level is mastered,
    # however many lesion-free sessions it passes
    never = run_trainee(db, 'never', 15, skill=lambda case, rng: False)
    m = mastery(history(db, 'never'), CFG)
    assert m['mastered_level'] == 0 and all(lv == 1 for _, lv in never)
    assert m['levels'][1]['lesion_free'] > 0 and m['levels'][1]['met'] == 0


def test_a_failed_lesion_free_session_ends_the_working_levels_streak():
    lump, free = BY_NAME['lump1_0'], BY_NAME['free0']

    def s(case, **kw):
        r = report(case, **kw)
        return {'case_level': case.level, 'coverage_pct': r['coverage_pct'],
                'palpable_missed': r['misses'], 'false_marks': r['false_marks'],
                'lesions': len(r['lesions']), 'not_palpable': [], 'void': None}
    ok, free_ok, free_bad = s(lump), s(free), s(free, false_marks=2)
    assert mastery([ok, ok, free_ok, ok], CFG)['mastered_level'] == 1   # neutral
    assert mastery([ok, ok, free_bad, ok], CFG)['mastered_level'] == 0  # a benign recall
    # void sessions (the loop fell behind) count neither way
    void_bad = dict(s(lump, deep=40.0), void='the haptic loop fell behind')
    void_ok = dict(ok, void='the haptic loop fell behind')
    m = mastery([ok, ok, void_bad, void_ok, ok], CFG)
    assert m['mastered_level'] == 1 and m['levels'][1]['void'] == 2
    assert m['levels'][1]['sessions'] == 3
    assert mastery([ok, void_ok, void_ok], CFG)['mastered_level'] == 0


def test_draw_seed_depends_on_trainee_and_session():
    seeds = {draw_seed(t, n) for t in ('a', 'b', 'c') for n in range(5)}
    assert len(seeds) == 15 and draw_seed('a', 3) == draw_seed('a', 3)


def test_the_trainee_sees_no_blind_case_name_the_instructor_does(tmp_path, capsys):
    db = tmp_path / 'rec.sqlite'
    run_trainee(db, 'kim', 4)
    store_session(db, 'kim', dict(report(BY_NAME['lump1_1']), blind=False), case_level=1)
    mine = history(db, 'kim', full=True)
    assert [s['case'] for s in mine[:4]] == ['blind'] * 4 and mine[4]['case'] == 'lump1_1'
    assert all(s['report']['case'] == 'blind' for s in mine[:4])
    assert all(s['case'].startswith(('lump', 'free'))
               for s in history(db, 'kim', instructor=True))
    for action in ('show', 'progress'):
        assert main(['trainees', '--db', str(db), action, 'kim']) == 0
        out = capsys.readouterr().out
        assert re.findall(r'lump\d_\d|free\d', out) == ['lump1_1'], out
        assert main(['trainees', '--db', str(db), action, 'kim', '--instructor']) == 0
        assert len(re.findall(r'lump\d_\d|free\d', capsys.readouterr().out)) == 5


def test_void_sessions_are_said_in_the_record(tmp_path, capsys):
    db = tmp_path / 'rec.sqlite'
    loop = {'rate_hz': 934.5, 'loop_windows': 7, 'loop_windows_behind': 5,
            'gaps_past_watchdog': 0}
    why = void_reason(loop)
    assert why.startswith('the haptic loop fell behind (5 of 7 check windows behind at '
                          '934.5 Hz)') and 'does not count toward mastery' in why
    assert void_reason(dict(loop, loop_windows_behind=0)) is None and void_reason(None) is None
    assert '2 gaps past the watchdog' in void_reason(dict(loop, gaps_past_watchdog=2))
    store_session(db, 'vic', report(BY_NAME['lump1_0'], found=False, void_reason=why),
                  case_level=1)
    (s,) = history(db, 'vic')
    assert s['void'] == why
    assert main(['trainees', '--db', str(db), 'show', 'vic']) == 0
    out = capsys.readouterr().out
    assert ' '.join(why.split()) in ' '.join(out.split()) and '1 void' in out
    assert max(map(len, out.splitlines()[1:])) <= 100   # the trainee's table: 100 columns


@pytest.mark.parametrize('where', ['new/deeper', 'file'])
def test_progress_figure_into_a_missing_folder(tmp_path, capsys, where):
    db = tmp_path / 'rec.sqlite'
    run_trainee(db, 'fig', 3)
    if where == 'file':   # a file stands where the folder should be: one line naming it
        (tmp_path / 'file').write_text('x')
    png = tmp_path / where / 'curve.png'
    code = main(['trainees', '--db', str(db), 'progress', 'fig', '--figure', str(png)])
    err = capsys.readouterr().err
    if where == 'file':
        assert code == 1 and err.count('\n') == 1 and str(png) in err and 'Errno' not in err
    else:
        assert code == 0 and png.stat().st_size > 10_000 and 'created folder' in err

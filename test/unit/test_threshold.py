"""A trainee's own threshold: the 3-down-1-up staircase converges on a simulated observer of
known threshold, through presses rendered on the simulated Falcon too; the result goes into the
trainee record (schema v4, an older file migrated) and grades the library for --next."""
import json
import math
import sqlite3

import numpy as np
import pytest

from haptic_anfis.device.stiffness_press import (DevicePresses, SimulatedPresses,
                                                 simulated_press)
from haptic_anfis.exam.staircase import (TARGET_CORRECT, SimulatedObserver, Staircase,
                                         noise_for_threshold)
from haptic_anfis.exam.threshold_run import run_threshold


def _run(threshold: float, seed: int) -> float:
    obs = SimulatedObserver(threshold, seed)
    order = np.random.default_rng(seed + 100)
    s = Staircase()
    while not s.done:
        first = order.random() < 0.5
        a, b = (1 + s.delta, 1.0) if first else (1.0, 1 + s.delta)
        s.answer((obs.choose(400 * a, 400 * b) == 0) == first)
    return s.threshold()


@pytest.mark.parametrize('threshold', [0.10, 0.22, 0.40])
def test_the_staircase_converges_on_a_known_observer_within_20_percent(threshold):
    runs = [_run(threshold, seed) for seed in range(5)]
    est = math.exp(np.mean(np.log(runs)))
    assert abs(est / threshold - 1) <= 0.20, (est, runs)


def test_the_observer_is_right_as_often_as_its_threshold_says():
    from statistics import NormalDist
    sigma = noise_for_threshold(0.22)
    p = NormalDist().cdf(math.log1p(0.22) / (math.sqrt(2) * sigma))
    assert p == pytest.approx(TARGET_CORRECT) and TARGET_CORRECT == pytest.approx(0.7937, abs=1e-4)
    obs = SimulatedObserver(0.22, seed=1)
    hits = np.mean([obs.choose(400 * 1.22, 400.0) == 0 for _ in range(4000)])
    assert hits == pytest.approx(TARGET_CORRECT, abs=0.02)


def test_presses_rendered_on_the_simulated_falcon_measure_the_spring_and_converge():
    p = simulated_press(400.0)
    assert p.stiffness == pytest.approx(400.0, rel=1e-3) and 3.0 < p.peak_force < 8.9
    runs = []
    for seed in range(3):
        obs = SimulatedObserver(0.22, seed)
        res = run_threshold(simulated_press, lambda a, b: obs.choose(a.stiffness, b.stiffness),
                            seed=seed)
        assert abs(res['rendered_ratio_error_pct']) < 0.5   # the device renders the asked ratio
        runs.append(res['threshold_pct'] / 100)
    est = math.exp(np.mean(np.log(runs)))
    assert abs(est / 0.22 - 1) <= 0.20, runs


def test_both_press_kinds_are_context_managers_called_with_a_stiffness():
    """The command says ``with press:`` for the simulated and the real device alike."""
    for kind in (SimulatedPresses, DevicePresses):
        assert callable(kind.__enter__) and callable(kind.__exit__) and callable(kind.__call__)
    sim = SimulatedPresses()
    with sim as p:
        assert p is sim
        assert p(400.0) == simulated_press(400.0)


def test_bad_staircase_input_names_the_field():
    with pytest.raises(ValueError, match='staircase start'):
        Staircase(start=0.0)
    with pytest.raises(ValueError, match='staircase reversals'):
        Staircase(reversals=4, averaged=8)
    with pytest.raises(ValueError, match='observer threshold'):
        SimulatedObserver(-1.0)
    s = Staircase(reversals=2, averaged=2, max_trials=3)
    for _ in range(3):
        s.answer(False)
    assert s.done
    with pytest.raises(ValueError, match='done'):
        s.answer(True)
    with pytest.raises(ValueError, match='reversals, the threshold needs 2'):
        s.threshold()


def test_the_threshold_goes_into_the_record_and_an_old_record_is_migrated(tmp_path, capsys):
    from haptic_anfis.cli import main
    from haptic_anfis.record.db import SCHEMA_VERSION, connect, migrate
    from haptic_anfis.record.store import history
    from haptic_anfis.record.thresholds import latest_threshold
    db = tmp_path / 'old.sqlite'
    # a record written by the schema before this one (v3), with one session
    conn = sqlite3.connect(str(db), isolation_level=None)
    migrate(conn, to=3)
    conn.execute("INSERT INTO trainees VALUES ('ann', '2026-01-01T00:00:00Z')")
    conn.execute("INSERT INTO sessions (trainee_id, started_utc, stored_utc, source, "
                 "coverage_light, coverage_medium, coverage_deep, lesions, hits, misses, "
                 "false_marks, score, verdict, duration_s, report_json) VALUES ('ann', "
                 "'2026-01-01T00:00:00Z', '2026-01-01T00:00:00Z', 'run', 1, 1, 0.9, 1, 1, 0, 0, "
                 "90, 'pass', 300, '{}')")
    conn.close()
    assert latest_threshold(db, 'ann') is None
    with connect(db) as c:
        assert c.execute('PRAGMA user_version').fetchone()[0] == SCHEMA_VERSION >= 5
    old = history(db, 'ann')
    assert len(old) == 1 and old[0]['score'] == 90   # the old session still reads
    assert old[0]['time_at_level_s'] is None and old[0]['force_palpating_n'] is None
    assert main(['threshold', '--trainee-id', 'ann', '--db', str(db), '--observer', '22',
                 '--json']) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res['device'] == 'sim' and res['trials'] >= 16
    assert latest_threshold(db, 'ann') == pytest.approx(res['threshold_pct'])
    assert latest_threshold(db, 'nobody') is None


def test_next_grades_the_library_at_the_trainees_threshold(tmp_path):
    from haptic_anfis.cases import library
    from haptic_anfis.record.draw import next_case
    lib = library()
    # a fresh trainee starts at level 1; at a 1000 % threshold no lesion is rendered to them,
    # so every graded case is level 1 and the draw may be any of them
    case, level, _ = next_case(tmp_path / 'r.sqlite', 'bo', lib=lib, threshold_pct=1000.0)
    assert level == 1 and (case.level_at(1000.0) in (None, 1))
    # at the finger's 7 % the 10 mm carcinoma 10 mm deep is level 2, at 22 % below the device
    c = lib.get('lib_m_dense_idc10_d10')
    assert c.level_at(7.0) == 2 and c.level_at(22.0) == 1


def test_exam_run_next_draws_at_the_trainees_measured_threshold(tmp_path, capsys):
    import argparse

    from haptic_anfis.commands._record import prepare_record
    from haptic_anfis.record.thresholds import store_threshold
    db = tmp_path / 'r.sqlite'
    store_threshold(db, 'cy', 7.0, 80, 'sim', {'threshold_pct': 7.0})
    args = argparse.Namespace(trainee_id='cy', db=str(db), next=True, case='',
                              exam_config=None)
    prepare_record(args)
    assert args.blind and args.case
    assert "graded at the trainee's own threshold, 7.0 %" in capsys.readouterr().out

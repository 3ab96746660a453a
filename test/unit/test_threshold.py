"""A trainee's own threshold: the staircase (4-down-1-up track, maximum-likelihood fit)
converges on a simulated observer of known threshold, a single run within 20 % for most seeds,
through presses rendered on the simulated Falcon too; the result goes into the trainee record (schema v4, an older file migrated) and grades the library for --next."""
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


@pytest.mark.parametrize('threshold', [0.07, 0.22, 0.40])
def test_a_single_default_run_lands_within_20_percent_for_a_clear_majority(threshold):
    runs = np.array([_run(threshold, seed) for seed in range(40)])
    within = np.mean(np.abs(runs / threshold - 1) <= 0.20)
    assert within >= 0.75, (within, runs)


def test_the_fit_finds_the_threshold_of_answers_drawn_from_the_model():
    from haptic_anfis.exam.staircase import ml_threshold, p_correct
    rng = np.random.default_rng(3)
    deltas = np.exp(rng.uniform(np.log(0.05), np.log(0.8), 3000))
    correct = rng.random(3000) < p_correct(deltas, 0.22)
    assert ml_threshold(list(zip(deltas, correct))) == pytest.approx(0.22, rel=0.05)
    assert float(p_correct(0.22, 0.22, lapse=0.0)) == pytest.approx(TARGET_CORRECT)
    with pytest.raises(ValueError, match='no trials'):
        ml_threshold([])


def test_the_observer_is_right_as_often_as_its_threshold_says():
    from statistics import NormalDist
    sigma = noise_for_threshold(0.22)
    p = NormalDist().cdf(math.log1p(0.22) / (math.sqrt(2) * sigma))
    assert p == pytest.approx(TARGET_CORRECT) and TARGET_CORRECT == pytest.approx(0.7937, abs=1e-4)
    obs = SimulatedObserver(0.22, seed=1)
    hits = np.mean([obs.choose(400 * 1.22, 400.0) == 0 for _ in range(4000)])
    assert hits == pytest.approx(TARGET_CORRECT, abs=0.02)


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
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
    with pytest.raises(ValueError, match='staircase down'):
        Staircase(down=0)
    with pytest.raises(ValueError, match='staircase lapse'):
        Staircase(lapse=0.7)
    s = Staircase(reversals=2, averaged=2, max_trials=3)
    for _ in range(3):
        s.answer(False)
    assert s.done
    with pytest.raises(ValueError, match='done'):
        s.answer(True)
    with pytest.raises(ValueError, match='reversals, the threshold needs 2'):
        s.threshold()


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
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


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_next_grades_the_library_at_the_trainees_threshold(tmp_path):
    from haptic_anfis.cases import library
    from haptic_anfis.record.draw import next_case
    lib = library()
    # at a 1000 % threshold no graded lesion is rendered (palpability and level read at the
    # same threshold): the only lump case left is one no FE grading covers
    for k in range(5):
        case, _, _ = next_case(tmp_path / 'r.sqlite', f'bo{k}', lib=lib, threshold_pct=1000.0)
        assert case.grading() is None or not case.scene.tumours
    # at the finger's 7 % the 10 mm carcinoma 10 mm deep is level 2; at 22 % it is below what
    # the device renders: no level (not an easy "no lump" case) and never drawn blind
    c = lib.get('lib_m_dense_idc10_d10')
    assert c.level_at(7.0) == 2 and not c.below_device_at(7.0)
    assert c.level_at(22.0) is None and c.below_device_at(22.0)
    drawn = {next_case(tmp_path / 'r.sqlite', f't{k}', lib=lib, threshold_pct=22.0)[0].name
             for k in range(30)}
    assert c.name not in drawn and not any(lib.get(n).below_device_at(22.0) for n in drawn)
    assert any(not lib.get(n).scene.tumours for n in drawn)   # lesion-free cases still drawn
    drawn7 = {next_case(tmp_path / 'r.sqlite', f't{k}', lib=lib, threshold_pct=7.0)[0].name
              for k in range(30)}
    assert not any(lib.get(n).below_device_at(7.0) for n in drawn7)


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

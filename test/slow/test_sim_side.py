"""``haptic-anfis sim`` with its side nodes (visualizer, recorder) in processes of their own."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytest.importorskip('rclpy')
pytestmark = pytest.mark.ros


def _last_json(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def test_sim_records_from_a_recorder_process_and_draws_from_a_visualizer_process(capfd, tmp_path):
    from haptic_anfis.bag.reader import bag_info
    from haptic_anfis.bag.topics import ALL_LOOP_TOPICS, absolute
    from haptic_anfis.cli import main
    bag = tmp_path / 'session'
    assert main(['sim', '--duration', '3', '--record', str(bag), '--recorder-process',
                 '--json']) == 0
    cap = capfd.readouterr()
    out = cap.out
    assert 'recorder in pid' in out and 'visualizer in pid' in out, out
    assert 'visualizer     own process, exit code 0' in out, out
    assert 'recorder       own process, exit code 0' in out, out
    last = _last_json(out)
    info = bag_info(bag)
    assert last['recorded_messages'] == info.message_count > 0
    assert last['dropped_messages'] == 0 == int(info.custom_data['dropped_messages'])
    assert info.custom_data['case'] == 'default'   # for exam report
    assert {t.topic for t in info.topics} >= {absolute(t) for t in ALL_LOOP_TOPICS
                                               if 'marks' not in t and 'buttons' not in t}
    # the side nodes' output went to standard error: the JSON line is still the last of stdout
    assert '[visualizer]' in cap.err and '[recorder]' in cap.err


def test_sim_in_process_keeps_the_one_interpreter_layout(capfd, tmp_path):
    """--in-process: the visualizer in the loop's process; the recorder is there by default."""
    from haptic_anfis.cli import main
    bag = tmp_path / 'session'
    assert main(['sim', '--duration', '2', '--in-process', '--record', str(bag), '--json']) == 0
    out = capfd.readouterr().out
    assert 'own process' not in out and 'visualizer     ' in out, out
    last = _last_json(out)
    assert last['recorded_messages'] > 0 and last['dropped_messages'] == 0


def test_a_side_node_that_fails_to_start_is_named_and_the_sim_stops(capfd, tmp_path):
    from haptic_anfis.cli import main
    # a mesh for the visualizer alone (its own section); a missing file is found only when the
    # node loads it (the parameter check before the start sees a string, as it should)
    params = tmp_path / 'vis.yaml'
    params.write_text(f"visualizer:\n  ros__parameters:\n    mesh_path: "
                      f"'{tmp_path / 'no_such_mesh.stl'}'\n")
    assert main(['sim', '--duration', '1', '--ready-timeout', '60', '--params-file',
                 str(params)]) == 1
    cap = capfd.readouterr()
    assert 'not ready: visualizer exited with code 1 while starting' in cap.out, cap.out
    assert 'no_such_mesh' in cap.err


def test_a_bad_parameter_value_is_refused_before_any_node_starts(capfd):
    from haptic_anfis.cli import main
    assert main(['sim', '--duration', '1', '--', '--ros-args', '-p', 'mesh_alpha:=5.0']) == 1
    cap = capfd.readouterr()
    assert cap.err.strip().splitlines() == [
        'haptic-anfis sim: error: -p mesh_alpha:=5.0: visualizer: mesh_alpha: 5.0: expected '
        '0 <= value <= 1'], cap.err
    assert 'started' not in cap.out + cap.err


def test_a_hand_set_while_held_keeps_the_start_gate():
    """exam run hands the simulated Falcon a trainee while the hand is held (its side examiner
    not subscribed yet): the trainee must wait at the gate, not start unwatched."""
    import threading

    from haptic_anfis.device.palpation import PalpationScript
    from haptic_anfis.device.start_gate import HeldScript
    from haptic_anfis.nodes.graph import build_graph
    g = build_graph(None, visualizer=False)
    try:
        gate = threading.Event()
        g.driver.release_gate = gate.is_set
        trainee = PalpationScript.from_yaml(str(ROOT / 'config' / 'palpation.yaml'))
        g.set_hand(trainee)
        s = g.driver.device.script
        assert isinstance(s, HeldScript) and s.script is trainee and s.held
        assert g.wait_ready(120.0) is not None
        g.spin_for(0.5)
        assert g.driver.device.script.held   # force commands came, the gate is shut
        gate.set()
        assert g.spin_for(5.0, until=lambda: not g.driver.device.script.held)
    finally:
        g.shutdown()


def test_the_release_gate_holds_the_hand_after_the_first_force_command():
    """sim holds the hand until the recorder (own process) is subscribed: the driver's
    release_gate keeps the script held although force commands arrive."""
    import threading

    from haptic_anfis.nodes.graph import build_graph
    g = build_graph(None, visualizer=False)
    try:
        gate = threading.Event()
        g.driver.release_gate = gate.is_set
        assert g.wait_ready(120.0) is not None  # force commands reach the driver
        g.spin_for(0.5)
        assert g.driver.device.script.held  # ... but the gate is shut
        gate.set()
        assert g.spin_for(5.0, until=lambda: not g.driver.device.script.held)
    finally:
        g.shutdown()


class _Subs:
    """A driver node's graph view for hold_until_examiner: who subscribes to each topic."""

    def __init__(self, names: list[str]) -> None:
        self.names, self.release_gate = names, None

    def get_subscriptions_info_by_topic(self, topic: str):
        from types import SimpleNamespace
        return [SimpleNamespace(node_name=n) for n in self.names]


class _Graph:
    """Spins ``until`` at most ``limit`` times (its timeout), counting the spins."""

    def __init__(self, driver: _Subs, limit: int = 10_000) -> None:
        self.driver, self.limit, self.spins = driver, limit, 0

    def spin_for(self, seconds: float, until=None) -> bool:
        for _ in range(self.limit):
            if until():
                return True
            self.spins += 1
        return False


def test_the_exam_stops_waiting_for_an_examiner_whose_process_exited():
    """exam run holds the trainee's hand until its examiner process has subscribed, up to the
    session's ready timeout (minutes): an examiner that exits meanwhile ends the wait at once,
    not at the timeout, and the hand stays held."""
    from haptic_anfis.nodes.exam_side import hold_until_examiner
    g = _Graph(_Subs(['recorder']))   # no examiner subscribed
    dead: list[tuple[str, int]] = []

    def gone() -> bool:
        if g.spins == 5:
            dead.append(('examiner', 1))
        return bool(dead)
    assert hold_until_examiner(g, 300.0, gone=gone) is False
    assert g.spins == 5 and not g.driver.release_gate()
    # subscribed: released, gone or not
    g = _Graph(_Subs(['examiner']))
    assert hold_until_examiner(g, 300.0, gone=lambda: False) is True
    assert g.spins == 0 and g.driver.release_gate()
    # never subscribed, never gone: the timeout (the fake graph's spin limit)
    g = _Graph(_Subs([]), limit=50)
    assert hold_until_examiner(g, 300.0) is False and g.spins == 50

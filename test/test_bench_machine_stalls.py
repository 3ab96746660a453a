"""The machine-stall benchmark's matching of the two cores' stalls and the servo gaps (synthetic
times: no real-time right needed)."""
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_machine_stalls import gaps_matched, together  # noqa: E402
import bench_machine_stalls  # noqa: E402


def test_stalls_of_both_cores_are_those_close_in_time():
    core0 = [(1.000, 0.021), (2.000, 0.003), (3.000, 0.005)]
    core1 = [(1.002, 0.019), (2.500, 0.004), (3.010, 0.006)]
    assert together(core0, core1) == [(1.000, 0.019)]   # the shorter length of the pair
    assert together(core0, []) == []


def test_a_gap_is_matched_when_it_ends_at_a_stall_of_both():
    both = [(1.000, 0.019)]
    assert gaps_matched([(1.001, 0.021), (5.0, 0.006)], both) == 1
    assert gaps_matched([(1.001, 0.021)], []) == 0


def test_without_the_right_to_real_time_it_says_so_and_writes_no_page(monkeypatch, capsys):
    monkeypatch.setattr(bench_machine_stalls, 'can_run_canary', lambda: 'refused here')
    written = []
    monkeypatch.setattr(bench_machine_stalls, 'run_with_page', lambda *a, **k: written.append(a))
    assert bench_machine_stalls.run() == 0   # make bench goes on
    assert 'skipped: refused here' in capsys.readouterr().out
    assert written == []

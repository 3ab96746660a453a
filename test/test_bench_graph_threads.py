"""The graph-threads benchmark's runnable streaks from a synthetic sampler file (no run)."""
import json
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_graph_threads import streaks  # noqa: E402


def _write(path: Path, rows: list[dict]) -> Path:
    path.write_text(''.join(json.dumps(r) + '\n' for r in rows))
    return path


def test_a_streak_is_runnable_without_cpu_time_from_the_sample_before_to_the_one_after(tmp_path):
    """Thread 11 of the force server: runnable with no CPU time from 0.04 s to 0.30 s (the
    sample before 0.02 s, the one after 0.32 s: 300 ms); thread 12 runnable but running (its
    run time grows: no streak); a sleeping thread is no streak; a thread seen once is none."""
    rows = []
    for i in range(20):
        t = i * 0.02
        stuck = 2 <= i <= 15
        fs = {'11': [1000 if stuck or i < 2 else 1000 + i, 'R' if stuck else 'S', 'dds.rx'],
              '12': [10 * i, 'R', 'python'],
              '13': [5, 'S', 'idle']}
        if i == 7:
            fs['14'] = [0, 'R', 'short']
        rows.append({'t': t, 'force_server': fs, 'contact_detector': {'21': [i, 'R', 'x']}})
    s = streaks(_write(tmp_path / 's.jsonl', rows))
    assert s['force_server'] == {'longest_ms': 300, 'thread': 'dds.rx', 'streaks_100ms': 1}
    assert s['contact_detector'] == {'longest_ms': 0, 'thread': '', 'streaks_100ms': 0}
    assert s['recorder']['streaks_100ms'] == 0


def test_a_streak_still_open_at_the_end_is_not_counted(tmp_path):
    rows = [{'t': i * 0.02, 'recorder': {'5': [7, 'R', 'rec']}} for i in range(10)]
    assert streaks(_write(tmp_path / 's.jsonl', rows))['recorder']['longest_ms'] == 0

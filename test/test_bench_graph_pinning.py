"""bench/bench_graph_pinning.py's arithmetic: the median of each arm over its runs (a run that
failed left out, a column a run lacks skipped), in the order the arms first ran."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from bench_graph_pinning import MEDIAN_COLS, medians  # noqa: E402


def test_median_per_arm_without_failed_runs():
    rows = [{'config': 'servo 0, pinning on', 'rate_hz': 986.0, 'periods_lost': 233,
             'max_gap_ms': 14.9, 'held': 548},
            {'config': 'servo 0, pinning off', 'rate_hz': 992.0, 'periods_lost': 142,
             'max_gap_ms': 12.9, 'held': 255},
            {'config': 'servo 0, pinning on', 'rate_hz': 990.0, 'periods_lost': 170,
             'max_gap_ms': 16.9, 'held': 734},
            {'config': 'servo 0, pinning off', 'error': 'exit 1: ...', 'rate_hz': None},
            {'config': 'servo 0, pinning on', 'rate_hz': 989.0, 'periods_lost': 187,
             'max_gap_ms': 18.2, 'held': 878}]
    m = medians(rows)
    assert [r['config'] for r in m] == ['servo 0, pinning on', 'servo 0, pinning off']
    on, off = m
    assert on['runs'] == 3 and on['rate_hz'] == 989.0 and on['periods_lost'] == 187
    assert on['max_gap_ms'] == 16.9 and on['held'] == 734
    assert off['runs'] == 1 and off['rate_hz'] == 992.0
    assert off['err_rms_pct'] is None   # no run had the column
    assert set(MEDIAN_COLS) <= set(on)

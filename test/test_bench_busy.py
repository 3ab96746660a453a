"""bench/_busy.py's LoadSampler: the load average read through a block, its median after; the
hypervisor's steal over it."""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from _busy import LoadSampler, steal_pct  # noqa: E402


def test_samples_through_the_block_and_stops_after_it():
    with LoadSampler(every=0.01) as s:
        deadline = time.monotonic() + 5.0
        while len(s.samples) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    n = len(s.samples)
    assert n >= 3 and all(x >= 0.0 for x in s.samples)
    assert min(s.samples) <= s.median <= max(s.samples)
    time.sleep(0.05)
    assert len(s.samples) == n   # the thread ended with the block


def test_median_of_even_and_odd_counts_and_none_without_samples():
    s = LoadSampler()
    assert s.median is None
    s.samples = [3.0, 1.0, 2.0]
    assert s.median == 2.0
    s.samples = [4.0, 1.0, 2.0, 3.0]
    assert s.median == 2.5


def test_steal_is_the_eighth_counters_share_of_all_eight():
    """/proc/stat's cpu line: user nice system idle iowait irq softirq steal guest guest_nice;
    guest time is inside user already, so the total is the first eight."""
    before = [100, 0, 50, 800, 0, 0, 0, 50, 30, 0]
    after = [200, 0, 100, 1550, 0, 0, 0, 150, 90, 0]   # 1000 ticks, 100 of them stolen
    assert steal_pct(before, after) == 10.0
    assert steal_pct(before, before) is None   # no time passed
    assert steal_pct(None, after) is None and steal_pct([1, 2, 3], after) is None
    with LoadSampler(every=10.0) as s:
        sum(range(10 ** 6))
    assert s.steal is None or 0.0 <= s.steal <= 100.0

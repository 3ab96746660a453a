"""bench/_busy.py's LoadSampler: the load average read through a block, its median after."""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from _busy import LoadSampler  # noqa: E402


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

"""RowLog: float64 rows in preallocated chunks, read as the list of tuples it replaces."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_anfis.rows import RowLog

# a batch of k rows appended one by one (True) or extended at once (False)
_batches = st.lists(st.tuples(st.integers(0, 9), st.booleans()), max_size=12)


@settings(derandomize=True, max_examples=200, deadline=None)
@given(_batches, st.integers(1, 4), st.sampled_from([0, 1, 5, 8]), st.integers(-12, 40),
       st.integers(-12, 40))
def test_a_rowlog_reads_as_the_newest_rows_of_a_list(batches, chunk, max_rows, a, b):
    """Whatever the chunk size, bound and order of appends and extends: the rows held are the
    newest of what went in (all of it when unbounded), whole chunks dropped, oldest first;
    len, iteration, indexing, slicing and np.asarray agree with a list of tuples."""
    log, ref, n = RowLog(3, chunk=chunk, max_rows=max_rows), [], 0
    for k, one in batches:
        rows = [(float(n + i), -float(n + i), 0.5) for i in range(k)]
        n += k
        if one:
            for r in rows:
                log.append(r)
        else:
            log.extend(np.array(rows).reshape(-1, 3))
        ref += rows
    kept = ref[log.dropped:]
    assert log.dropped + len(log) == len(ref)
    assert log.dropped % chunk == 0
    if max_rows:   # within the bound but for the newest chunk's rows
        assert len(log) <= max(max_rows, 0) + 2 * chunk
    else:
        assert log.dropped == 0
    assert len(log) == len(kept) and list(log) == kept
    assert np.array_equal(np.asarray(log).reshape(-1, 3), np.array(kept).reshape(-1, 3))
    assert np.array_equal(log[a:b].reshape(-1, 3), np.array(kept[a:b]).reshape(-1, 3))
    assert np.array_equal(log.array(max(a, 0), b).reshape(-1, 3),
                          np.array(kept[max(a, 0):b]).reshape(-1, 3))
    if kept:
        assert log[-1] == kept[-1] and log[0] == kept[0]


def test_a_rowlog_refuses_what_a_list_refuses_and_bad_shapes():
    log = RowLog(2)
    with pytest.raises(IndexError):
        log[0]
    log.append((1.0, 2.0))
    with pytest.raises(ValueError):
        log.append((1.0, 2.0, 3.0))       # a row of the wrong width
    with pytest.raises(ValueError, match='slices with a step'):
        log[::2]
    with pytest.raises(ValueError, match='expected columns >= 1'):
        RowLog(0)
    assert len(log) == 1 and log[0] == (1.0, 2.0)
    log.clear()
    assert len(log) == 0 and log.array().shape == (0, 2)

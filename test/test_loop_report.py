"""The loop report of a driver trace (``haptic-anfis loop``, ``launch``'s end): rates of the
counts the driver kept for the whole run when its trace kept only the newest rows."""
from __future__ import annotations

import numpy as np
import pytest

from haptic_anfis.commands.loop import trace_report
from haptic_anfis.device.trace import save_trace


@pytest.mark.parametrize('dropped', [0, 2000])
def test_received_rates_cover_the_rows_the_trace_dropped(tmp_path, dropped):
    """1 s of 1 kHz ticks kept, ``dropped`` older ones dropped by the ring; the driver received
    as many commands as ticks over the whole run: about 1000 commands/s either way (the run's
    commands over the kept rows' span gave 3000/s for a run three times the trace)."""
    n = 1000
    rows = np.zeros((n, 8))
    rows[:, 0] = np.arange(n) * 1e-3
    rows[:, 1:4] = (0.0, 0.0, 0.5)      # far above the tissue: free space, zero force
    rows[:, 7] = 4                      # free
    stats = {'commands_received': n + dropped, 'models_received': n + dropped,
             'periods_lost': 0, 'max_gap_ms': 1.0, 'ticks_taken_over': 0}
    path = save_trace(tmp_path / 't.npz', rows, stats=stats, ticks_dropped=dropped,
                      max_force=8.9)
    r = trace_report(path)
    assert r['rates_hz']['falcon/servo_cf'] == pytest.approx(1000.0, rel=2e-3)
    assert r['rates_hz']['falcon/servo_cf_local'] == pytest.approx(1000.0, rel=2e-3)
    assert r['rates_hz']['falcon/measured_cp'] == pytest.approx(1000.0, rel=2e-3)

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


def test_a_window_from_start_counts_its_own_ticks_and_names_the_whole_runs_counters(tmp_path):
    """2 s of 1 kHz ticks with 50 periods lost at 0.5 s and 3 at 1.5 s, and 7 expired ticks
    after 1 s: from 1 s on the window has its own rate, periods lost, longest gap and expired
    count; the driver's counters (latency, held ...) are the whole run's and say so."""
    from haptic_anfis.device.local_model import STATUS_NAMES
    from haptic_anfis.device.stats import tick_gaps
    t = np.arange(2000) * 1e-3
    t[500:] += 50e-3
    t[1500:] += 3e-3
    rows = np.zeros((len(t), 8))
    rows[:, 0] = t
    rows[:, 1:4] = (0.0, 0.0, 0.5)
    rows[:, 7] = STATUS_NAMES.index('free')
    rows[1600:1607, 7] = STATUS_NAMES.index('expired')
    rows[:3, 7] = -2                    # safety off before start: not counted
    lost, gap = tick_gaps(rows[3:, 0], 1e-3)
    assert lost == 53 and gap == pytest.approx(0.051)
    stats = {'periods_lost': lost, 'max_gap_ms': gap * 1e3, 'latency_p99_ms': 2.0,
             'ticks_held': 4, 'commands_received': 1997}
    path = save_trace(tmp_path / 't.npz', rows, stats=stats, max_force=8.9, period=1e-3)
    whole = trace_report(path)
    assert whole['periods_lost'] == 53 and 'whole_run' not in whole
    w = trace_report(path, start=1.0)
    assert w['periods_lost'] == 3 and w['max_gap_ms'] == pytest.approx(4.0)
    assert w['ticks_expired'] == 7 and w['from_s'] == 1.0
    assert w['rates_hz']['falcon/servo_cf'] is None    # the received count is the whole run's
    assert {'latency_p99_ms', 'ticks_held'} <= set(w['whole_run'])
    assert w['ticks'] == int(np.sum(rows[3:, 0] >= rows[3, 0] + 1.0))
    with pytest.raises(ValueError, match='--from 5 s: the trace has 2.0 s'):
        trace_report(path, start=5.0)
    rows[:, 7] = -1   # zero-order hold: no local model, so no expired count
    zoh = save_trace(tmp_path / 'z.npz', rows, stats=dict(stats, mode='zoh'), max_force=8.9)
    assert trace_report(zoh, start=1.0)['ticks_expired'] is None


def test_tick_gaps_counts_a_gap_of_k_periods_as_k_minus_1_lost():
    from haptic_anfis.device.stats import tick_gaps
    assert tick_gaps(np.array([]), 1e-3) == (0, 0.0)
    assert tick_gaps(np.array([0.0, 1.4e-3, 2.4e-3, 5.0e-3]), 1e-3) == (2, pytest.approx(2.6e-3))


def test_a_trace_that_kept_only_its_newest_ticks_says_so_and_refuses_a_window(tmp_path):
    """A long run's trace keeps its last ``trace_seconds``: the report names the dropped ticks,
    and ``--from`` (seconds after the run's first tick) is refused rather than counted from the
    first tick kept."""
    rows = np.zeros((1000, 8))
    rows[:, 0] = np.arange(1000) * 1e-3
    rows[:, 1:4] = (0.0, 0.0, 0.5)
    rows[:, 7] = 4
    path = save_trace(tmp_path / 't.npz', rows, stats={}, ticks_dropped=5000, max_force=8.9)
    from haptic_anfis.commands.loop import format_report
    r = trace_report(path)
    assert r['ticks_dropped'] == 5000 and r['ticks'] == 1000
    assert '5000 older not kept: trace_seconds' in format_report(r)
    with pytest.raises(ValueError, match='5000 older ones dropped'):
        trace_report(path, start=0.5)


@pytest.mark.parametrize('seconds, rows', [(2.0, 2000), (0.0, 0)])
def test_the_drivers_trace_keeps_trace_seconds_of_ticks(seconds, rows):
    """``trace_seconds`` bounds the driver's trace to that many seconds at its rate; 0 keeps
    every tick; no ``trace_path``, no trace."""
    from haptic_anfis.device.driver_loops import tick_trace
    t = tick_trace({'trace_path': 'x.npz', 'rate': 1000.0, 'trace_seconds': seconds})
    assert t.max_rows == rows
    assert tick_trace({'trace_path': '', 'rate': 1000.0, 'trace_seconds': seconds}) is None


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_the_ideal_force_is_the_sessions_own_case(tmp_path):
    """A press rendered exactly as a random case renders it: against that case's surface and
    model the applied-force error is 0 % with no dropout; against the default scene (what the
    report took before it read the session's case) the same ticks have no contact. The seed is
    the first that draws a breast taller than the default one (the library decides which)."""
    from haptic_anfis.cases.library import random_case
    from haptic_anfis.commands.loop import ideal_forces, ideal_overrides
    from haptic_anfis.device.local_model import STATUS_NAMES
    from haptic_anfis.session import SessionSpec
    from haptic_anfis.tissue.scene import SCENE_DIR, load_scene
    default_apex = load_scene(SCENE_DIR / 'default.yaml').radii[0]
    seed = next(s for s in range(200) if random_case(s).scene.radii[0] > default_apex + 0.008)
    apex = random_case(seed).scene.radii[0]
    spec = SessionSpec(command='sim', random_case=True, seed=seed)
    overrides = ideal_overrides(spec.case_arguments())
    assert overrides['force_server'] == {'random_case_seed': seed}
    n = 1500   # 1.5 s at 1 kHz: down 12 mm through the surface's apex and back up
    x = apex + 0.007 - 0.012 * np.sin(np.linspace(0.0, np.pi, n))
    positions = np.column_stack([x, np.zeros(n), np.zeros(n)])
    F, contact = ideal_forces(positions, (), overrides)
    assert contact.sum() > 500 and np.abs(F).max() > 1.0
    rows = np.zeros((n, 8))
    rows[:, 0] = np.arange(n) * 1e-3
    rows[:, 1:4], rows[:, 4:7] = positions, F
    rows[:, 7] = STATUS_NAMES.index('fresh')
    path = save_trace(tmp_path / 't.npz', rows, stats={'mode': 'local_model'}, max_force=8.9,
                      period=1e-3)
    own = trace_report(path, overrides=overrides)
    assert own['force_error_rms_pct'] == pytest.approx(0.0, abs=1e-9)
    assert own['zero_force_ticks'] == 0 and own['contact_ticks'] == int(contact.sum())
    default = trace_report(path)
    # the default surface lies below this press: none of its ticks is in contact there
    assert default['contact_ticks'] == 0 and default['force_error_rms_pct'] is None

"""The servo-load benchmark's settled rows (``--settle``): the window's figures from the tick
trace, the first seconds' in columns of their own (a synthetic trace: no run needed)."""
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_servo_load import driver_settings, graph_words, params_file, sched_words, \
    settled  # noqa: E402

from haptic_anfis.device.local_model import STATUS_NAMES  # noqa: E402
from haptic_anfis.device.trace import save_trace  # noqa: E402


def test_the_window_s_figures_and_a_gap_across_the_boundary_counted_in_the_settle(tmp_path):
    """4 s at 1 kHz after 3 disabled ticks: 20 periods lost at 1.0 s, 5 straddling the 2 s
    boundary, 2 at 3.0 s. Settled at 2 s: the window has 2 lost, the settle 25 (the boundary's
    gap included there, not lost between the two); the driver's whole-run counters stay."""
    t = np.arange(4000) * 1e-3
    t[1000:] += 20e-3
    k = int(np.searchsorted(t, t[0] + 2.0)) - 2
    t[k:] += 5e-3   # the gap ends just after the boundary
    t[3000:] += 2e-3
    t = np.concatenate([[-0.003, -0.002, -0.001], t])
    rows = np.zeros((len(t), 8))
    rows[:, 0] = t
    rows[:, 1:4] = (0.0, 0.0, 0.5)       # free space
    rows[:, 7] = STATUS_NAMES.index('free')
    rows[:3, 7] = -2                      # safety off: not counted
    path = save_trace(tmp_path / 't.npz', rows, stats={'ticks_held': 9}, max_force=8.9,
                      period=1e-3, passivity_window=0.03)
    j = {'rate_hz': 990.0, 'periods_lost': 27, 'ticks_held': 9, 'latency_p99_ms': 3.0}
    pf = params_file(tmp_path, 0, 'auto')
    s = settled(j, path, pf, 2.0, browser_at=t[3] - 1.5)
    assert s['settle_lost'] == 25 and s['periods_lost'] == 2
    assert s['settle_gap_ms'] == pytest.approx(21.0) and s['max_gap_ms'] == pytest.approx(3.0)
    assert s['rate_hz'] == pytest.approx(1000 * (1 - 2 / 2000), abs=2.0)
    assert s['ticks_held'] == 9 and s['latency_p99_ms'] == 3.0   # whole run, from the driver
    assert s['browser_s'] == -1.5
    assert s['passivity_window'] == 0.03 and 'model_blend_time' not in s   # as the trace says


def test_the_page_names_the_driver_settings_the_runs_recorded():
    """Distinct values joined by /, the driver's default where no run recorded one."""
    from haptic_anfis.nodes.falcon_driver import PARAMS
    from haptic_anfis.nodes.parameters import default_of
    text = driver_settings([{'passivity_window': 0.05}, {'passivity_window': 0.02},
                            {'passivity_window': 0.05, 'model_blend_time': None}])
    assert text == (f'model_blend_time {default_of(PARAMS, "model_blend_time"):g} s (the '
                    'default), passivity_window 0.02/0.05 s')


def test_the_sched_column_says_what_the_servo_thread_got():
    words = sched_words
    assert words('compiled tick in servo process 7 (own session); SCHED_FIFO priority 50; '
                 '2 tick workers on cores 0, 1') == 'FIFO 50'
    assert words('compiled tick in servo process 7 (own session); SCHED_RR priority 20 from '
                 'rtkit, in place of SCHED_FIFO 50; 2 tick workers') == 'RR 20 rtkit'
    assert words('compiled tick in servo process 7 (own session); normal scheduler: SCHED_FIFO '
                 '50 refused (Operation not permitted; rtkit: no system D-Bus); allow it with '
                 '`ulimit -r 50` ..., time slice 0.1 ms requested; 2 tick workers') == 'normal'
    assert words(None) is None


def test_the_graph_column_says_what_the_haptic_path_nodes_got():
    """sim: one process's words; launch: {node: words}, the distinct answers joined."""
    rr = ('SCHED_RR priority 10 from rtkit for 4 of its threads (executor, DDS receive, servo '
          'bridge), in place of SCHED_FIFO 10')
    pinned = ('normal scheduler: SCHED_FIFO 10 refused (Operation not permitted; rtkit: no '
              'rtkit-daemon on this machine); allow it ...; threads kept on CPU 1')
    assert graph_words('SCHED_FIFO priority 10') == 'FIFO 10'
    assert graph_words({'force_server': rr, 'falcon_driver': rr}) == 'RR 10 rtkit'
    assert graph_words({'force_server': rr, 'recorder': pinned}) == 'RR 10 rtkit/normal pinned'
    assert graph_words('normal scheduler (graph priority 0)') == 'normal'
    assert graph_words({}) is None and graph_words(None) is None

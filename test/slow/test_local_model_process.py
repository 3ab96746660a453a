"""Cross-process: the local force model carries a press through a slow force server, and a
driver paused and resumed after the force server died applies no stale force (issue 22).

Nodes run as subprocesses on their own ROS domain; the driver writes its servo tick trace
(``trace_path``) and the assertions read it. Waits are generous; nothing asserts timings.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip('rclpy')

from haptic_anfis.commands.loop import ideal_forces  # noqa: E402
from haptic_anfis.device.local_model import EXPIRED  # noqa: E402
from haptic_anfis.device.trace import DISABLED, load_trace  # noqa: E402

from geometry_msgs.msg import WrenchStamped  # noqa: E402

from haptic_anfis import interfaces as ifc  # noqa: E402
from haptic_anfis.nodes.falcon_driver import PARAMS as DRIVER_PARAMS  # noqa: E402
from haptic_anfis.nodes.parameters import default_of  # noqa: E402
from haptic_anfis.realtime.processes import node_env  # noqa: E402
from delay_relay import FORCE_SERVER_REMAP  # noqa: E402
from test_nodes_process import Observer, _domains, launch, stop  # noqa: E402

#: [s] the driver's default model_hold_time
HOLD_S = default_of(DRIVER_PARAMS, 'model_hold_time')

pytestmark = pytest.mark.ros

PRESS = {'loop': True, 'start_delay': 0.2, 'approach_height': 0.006, 'pattern': [
    {'press': {'points': [[0.0, 0.0]], 'depth': 0.012, 'hold': 1.0}}, {'pause': {'duration': 0.6}}]}


def press_script(tmp_path):
    p = tmp_path / 'press.yaml'
    p.write_text(yaml.safe_dump(PRESS))
    return str(p)


@pytest.mark.parametrize('mode', ['local_model', 'zoh'])
def test_force_follows_a_press_through_a_delayed_force_server(tmp_path, mode):
    """Every force command / model arrives 20 ms late, past the 10 ms watchdog. The local model
    follows the press (once risen, never zero while pressing; close to the ideal force; no
    watchdog trip in contact); the zero-order hold refuses every command as stale and renders
    nothing."""
    domain = next(_domains)
    trace = tmp_path / 'trace.npz'
    procs = {}
    obs = Observer(domain)
    commands = []
    obs.node.create_subscription(WrenchStamped, ifc.TOPIC_COMMAND, commands.append, 100)
    try:
        # the force server's outputs reach the driver through a relay 20 ms late
        procs['force_server'] = launch('force_server', ['-r', *FORCE_SERVER_REMAP], domain,
                                       tmp_path / 'force_server.log')
        procs['delay_relay'] = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve().parents[1] / 'support' / 'delay_relay.py'),
             '0.02'],
            env=node_env(domain), stdout=(tmp_path / 'delay_relay.log').open('w'),
            stderr=subprocess.STDOUT)
        procs['contact_detector'] = launch('contact_detector', [], domain,
                                           tmp_path / 'contact_detector.log')
        procs['falcon_driver'] = launch('falcon_driver', [
            '-p', f'palpation_script:={press_script(tmp_path)}', '-p', f'force_mode:={mode}',
            '-p', f'trace_path:={trace}',
            # 0.2 s: the 20 ms delay plus this shared machine's scheduling (p99 ~50 ms at load 25)
            '-p', 'model_validity_time:=0.2'], domain, tmp_path / 'falcon_driver.log')
        # ~4 s of commands (the zoh driver takes none, so it cannot time its own run); with the
        # local model also 0.5 s of applied force above 1 N (measured_cf every 10 ticks): the
        # trace starts at the first model taken, which on a loaded machine can come seconds
        # after the hand was released by a stale one, past the script's press (CI, once: 29
        # pressing ticks in a 3.4 s trace)
        pressed = lambda: sum(f[0] ** 2 + f[1] ** 2 + f[2] ** 2 > 1.0  # noqa: E731
                              for f in obs.forces) >= 50
        assert obs.wait(lambda: len(commands) > 2000 and (mode == 'zoh' or pressed()),
                        240.0), 'the graph did not run'
    finally:
        for p in procs.values():
            stop(p)  # the driver writes its trace
        obs.close()
    log = (tmp_path / 'falcon_driver.log').read_text()
    assert trace.is_file(), log[-3000:]
    rows, meta = load_trace(trace)
    st = meta['stats']
    # the safety layer is off (0 N on purpose) only before start and at shutdown, whose tick may
    # fall in a press when the two nodes stopped before the driver did; never in between
    on = np.flatnonzero(rows[:, 7] != DISABLED)
    assert len(on) and np.all(rows[on[0]:on[-1] + 1, 7] != DISABLED), st
    rows = rows[on[0]:on[-1] + 1]
    F, contact = ideal_forces(rows[:, 1:4])
    fi, fa = np.linalg.norm(F, axis=1), np.linalg.norm(rows[:, 4:7], axis=1)
    pressing = contact & (fi > 1.0)
    assert pressing.sum() > 200, (pressing.sum(), st)
    if mode == 'zoh':
        assert fa.max() == 0.0 and st['rejected_stale'] > 100, st
        return
    # Onset: the first in-contact model arrives >= 20 ms after contact (a model computed out of
    # contact renders zero). Once the force has risen in a press it never drops to zero.
    held = np.zeros(len(rows), dtype=bool)
    risen = False
    for i in range(len(rows)):
        risen = pressing[i] and (risen or fa[i] > 0.5)
        held[i] = risen
    assert held.sum() > 200, (held.sum(), pressing.sum(), st)  # it did follow presses
    # A drop is allowed only where the model expired: no model younger than 0.2 s, a scheduling
    # stall (on this shared 2-core machine at load ~20, 0-19 % of the pressing ticks; the trace
    # showed the probe slower than 0.06 m/s, so not the radius). The safe answer then is the
    # watchdog's ramp; how often it happens is the machine's, not asserted.
    drops = np.flatnonzero(held & (fa <= 0.5))
    assert np.all(rows[drops, 7] == EXPIRED), (drops[:10], rows[drops[:10], 7], st)
    print(f'expired drops: {len(drops)} of {held.sum()} pressing ticks')
    ok = held & (rows[:, 7] != EXPIRED)
    err = np.linalg.norm(rows[:, 4:7] - F, axis=1)[ok]
    assert np.sqrt(np.mean(err ** 2)) < 0.1 * np.sqrt(np.mean(fi[ok] ** 2)), st
    assert st['ticks_extrapolated'] > 200, st
    # the watchdog trips in contact only after a model expired (a stall), never otherwise; the
    # trip may fall on a tick outside `held` (a light contact, fi <= 1 N, or before the force has
    # risen), so look for an expired tick anywhere in contact, not only among the drops
    expired_in_contact = np.count_nonzero(contact & (rows[:, 7] == EXPIRED))
    assert st['watchdog_trips_in_contact'] == 0 or expired_in_contact > 0, \
        (expired_in_contact, len(drops), st)
    assert st['ticks_fresh'] == 0  # every model was >= 20 ms old: all ticks extrapolated


@pytest.mark.parametrize('mode', ['local_model', 'zoh'])
def test_stall_and_kill_across_processes(tmp_path, mode):
    """Issue 22: SIGSTOP the driver while it applies force, kill -9 the force server 0.5 s later,
    SIGCONT the driver ``model_hold_time`` after that: no force above 0.05 N after the resume.
    Issue 32: the servo tick runs in the driver's servo process (``servo_loop: auto``), which the
    SIGSTOP does not stop: it zeroes the force while the node is frozen — after the watchdog in
    zoh, after the held model's ``model_hold_time`` in local_model — and keeps it there."""
    domain = next(_domains)
    trace = tmp_path / 'trace.npz'
    procs = {}
    obs = Observer(domain)
    try:
        procs['force_server'] = launch('force_server', [], domain, tmp_path / 'force_server.log')
        procs['contact_detector'] = launch('contact_detector', [], domain,
                                           tmp_path / 'contact_detector.log')
        procs['falcon_driver'] = launch('falcon_driver', [
            '-p', f'palpation_script:={press_script(tmp_path)}', '-p', f'force_mode:={mode}',
            '-p', f'trace_path:={trace}', '-p', 'measured_cf_every:=1'], domain,
            tmp_path / 'falcon_driver.log')
        drv = procs['falcon_driver']
        assert obs.wait(lambda: obs.force > 2.0, 180.0), 'no force while pressing'
        t_stop = time.monotonic()
        drv.send_signal(signal.SIGSTOP)
        time.sleep(0.5)
        procs['force_server'].kill()
        procs['force_server'].wait(10)
        time.sleep(HOLD_S)   # the last model is then past the hold: expired, never taken again
        t_cont = time.monotonic()
        drv.send_signal(signal.SIGCONT)
        obs.wait(lambda: False, 1.0)
        assert drv.poll() is None
    finally:
        for p in procs.values():
            if p.poll() is None:
                os.kill(p.pid, signal.SIGCONT)
            stop(p)
        obs.close()
    log = (tmp_path / 'falcon_driver.log').read_text()
    assert trace.is_file(), log[-3000:]
    rows, meta = load_trace(trace)
    before = rows[rows[:, 0] < t_stop]
    after = rows[rows[:, 0] >= t_cont]
    assert np.linalg.norm(before[-50:, 4:7], axis=1).max() > 1.0  # it was pressing at the stop
    # while the node was frozen the servo process went on ticking and zeroed the force (0.1 s
    # margin for this shared machine's scheduling beyond the 10 ms watchdog / the hold time)
    zero_from = t_stop + 0.1 + (0.0 if mode == 'zoh' else HOLD_S)
    frozen = rows[(rows[:, 0] > zero_from) & (rows[:, 0] < t_cont)]
    assert len(frozen) > 200, len(frozen)
    assert np.linalg.norm(frozen[:, 4:7], axis=1).max() <= 0.05
    assert len(after) > 100
    fa = np.linalg.norm(after[:, 4:7], axis=1)
    assert fa.max() <= 0.05, (fa.max(), json.dumps(meta['stats']))

"""A restarted node's first seconds are in the bag (issue 27.2): ``launch --record``, the force
server killed with SIGKILL while the probe presses, and from the bag alone: when the first force
command of the restarted server was recorded, and what force the driver applied (its
``falcon/measured_cf``, recorded too) between the kill and that command.

A restarted node is held until the recorder has matched its publishers, so the driver can apply
no force from it that the bag does not have: the applied force between the kill and the first
recorded command must stay at the watchdog's zero (before issue 27 it reached 6.7 N for 1-2.3 s).

Usage: ``python bench/bench_restart_record.py [--kills 3] [--gap 12]``; prints the table and writes
docs/measurements/restart_record.md.
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _page import run_with_page  # noqa: E402

sys.path.insert(0, str(ROOT))
from haptic_anfis.nodes.falcon_driver import PARAMS as DRIVER_PARAMS  # noqa: E402
from haptic_anfis.nodes.parameters import default_of  # noqa: E402

#: [N] applied force above this counts as force on the hand
FORCE_ON = 0.05
#: [s] the driver's model_hold_time (its default): the killed server's last local model
#: (recorded) may be rendered this long after its last command
HOLD_S = default_of(DRIVER_PARAMS, 'model_hold_time')
#: [s] margin for the watchdog's ramp to zero and the applied-force topic's own latency
RAMP_S = 0.1


def _wait(out: Path, pattern: str, timeout: float) -> re.Match:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = list(re.finditer(pattern, out.read_text()))
        if m:
            return m[-1]
        time.sleep(0.2)
    raise SystemExit(f'no {pattern!r} in {timeout:g} s:\n{out.read_text()[-2000:]}')


def _stamps(bag, topic, value):
    from haptic_anfis.bag import read_messages
    rows = [(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, value(m))
            for *_, m in read_messages(bag, [topic])]
    return np.array(rows, dtype=float).reshape(-1, 2)


def measure(kills: int, gap: float) -> list[dict]:
    d = Path(tempfile.mkdtemp(prefix='bench-restart-'))
    bag, out = d / 'bag', d / 'launch.out'
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    duration = 20 + kills * (gap + 5)
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', 'launch', '--nodes',
                          'falcon_driver,contact_detector,force_server', '--duration',
                          str(duration), '--localhost', '--domain-id', str(120 + os.getpid() % 90),
                          '--record', str(bag), '--log-dir', str(d / 'logs')],
                         cwd=ROOT, env=env, stdout=out.open('w'), stderr=subprocess.STDOUT)
    t_kills = []
    try:
        _wait(out, r'ready after', 300)
        for _ in range(kills):
            pid = int(re.findall(r'(?:started force_server +pid|node force_server, pid) (\d+)',
                                 out.read_text())[-1])
            time.sleep(3.0)
            t_kills.append(time.time())
            os.kill(pid, signal.SIGKILL)
            _wait(out, r'restarted, .*node force_server', 120)
            time.sleep(gap)
        p.wait(duration + 300)
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            p.wait(60)
    cmds = _stamps(bag, '/falcon/servo_cf', lambda m: float(np.linalg.norm(
        (m.wrench.force.x, m.wrench.force.y, m.wrench.force.z))))
    applied = _stamps(bag, '/falcon/measured_cf', lambda m: float(np.linalg.norm(
        (m.wrench.force.x, m.wrench.force.y, m.wrench.force.z))))
    rows = []
    for k, tk in enumerate(t_kills):
        later = cmds[cmds[:, 0] > tk + 0.05]
        if not len(later):
            rows.append({'kill': k + 1, 'first_cmd_s': None})
            continue
        # the old server's last answers may still be queued: the restarted server's first
        # command is the first after the outage (a gap of > 0.3 s in the recorded commands)
        t = later[:, 0]
        gaps = np.flatnonzero(np.diff(np.concatenate([[tk], t])) > 0.3)
        t_first = t[gaps[0]] if len(gaps) else t[0]
        # the last command of the killed server (recorded): the driver may render its local
        # model for model_hold_time after it, then the watchdog ramps the force to zero
        before = cmds[cmds[:, 0] < t_first - 0.3]
        t_last = before[-1, 0] if len(before) else tk
        after_hold = t_last + HOLD_S + RAMP_S
        between = applied[(applied[:, 0] > after_hold) & (applied[:, 0] < t_first)]
        on = between[between[:, 1] > FORCE_ON]
        held = applied[(applied[:, 0] > t_last) & (applied[:, 0] <= after_hold)]
        rows.append({'kill': k + 1, 'first_cmd_s': t_first - tk,
                     'held_max_n': float(held[:, 1].max()) if len(held) else 0.0,
                     'applied_max_n': float(between[:, 1].max()) if len(between) else 0.0,
                     'applied_on_s': float(on[-1, 0] - on[0, 0]) if len(on) > 1 else 0.0,
                     'applied_samples': len(between)})
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--kills', type=int, default=3)
    ap.add_argument('--gap', type=float, default=12.0,
                    help='seconds between a restart and the next kill (default 12)')
    a = ap.parse_args()
    load = os.getloadavg()[0]
    rows = measure(a.kills, a.gap)
    head = ('| kill | first recorded command of the restarted server after the kill [s] | applied '
            'while the last recorded model was held: max [N] | applied after the hold, before that '
            f'command: max [N] | time above {FORCE_ON} N [s] | applied samples |\n'
            '|---|---|---|---|---|---|\n')
    body = head + ''.join(
        f"| {r['kill']} | {r['first_cmd_s']:.2f} | {r['held_max_n']:.3f} | {r['applied_max_n']:.3f} | "
        f"{r['applied_on_s']:.2f} | {r['applied_samples']} |\n" if r.get('first_cmd_s') is not None
        else f"| {r['kill']} | none recorded | | | | |\n" for r in rows)
    body = (f'`launch --nodes falcon_driver,contact_detector,force_server --record BAG`, the force '
            f'server killed with SIGKILL {a.kills} times while the simulated hand presses; '
            'figures read from the bag alone (`falcon/servo_cf`, `falcon/measured_cf`). Load at '
            f'the start: {load:.1f}.\n\n' + body +
            '\nAfter the killed server\'s last (recorded) local model the driver renders it for '
            f'at most model_hold_time ({HOLD_S:g} s) while the probe stays near it, then the '
            "watchdog ramps to zero. A restarted node is held until the recorder matched its "
            'publishers: the driver applies no force from it that the bag lacks, so after the '
            "hold the applied force stays at zero until the first recorded command.\n")
    print(body)
    return 0 if rows else 1


if __name__ == '__main__':
    raise SystemExit(run_with_page(main, __file__, __doc__))

"""DDS transport and the slowest force answer of a launch. The longest pose -> force-command
latency of ``haptic-anfis launch`` starts, with the DDS transport the nodes use (UDP only, the
default: nodes/middleware.py) and with Fast DDS's shared-memory transport
(``HAPTIC_ANFIS_DDS_SHM=1``), and with a late joiner: a plain ROS 2 process (shared memory and
UDP, as ``ros2 topic echo`` is) subscribing to the loop's topics one second after the session is
ready.

Why: opening another process's shared-memory port makes Fast DDS check the port's health; when
its listener was idle and checked a moment before, the opening thread sleeps one listener period
(~333 ms) — a publishing thread, or the discovery thread holding the writer's lock. The local
model then expires mid-press (``rejected_stale``). Each start: ``launch --duration D --localhost
--record BAG --json`` (the recorder and the view node running, as a session runs). Usage:
``python bench/bench_dds_stall.py [--starts 20] [--duration 5] [--configs udp,shm,udp+join,shm+join]``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from _page import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
HAPTIC = str(Path(sys.executable).with_name('haptic-anfis'))

JOINER = """
import rclpy, time
from rclpy.node import Node
from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState
rclpy.init()
n = Node('late_joiner')
for t, c in (('falcon/measured_cp', PoseStamped), ('falcon/servo_cf', WrenchStamped),
             ('contact', JointState), ('falcon/servo_cf_local', JointState)):
    n.create_subscription(c, t, lambda m: None, 10)
end = time.monotonic() + 30
while rclpy.ok() and time.monotonic() < end:
    rclpy.spin_once(n, timeout_sec=0.1)
"""


def one_start(config: str, duration: float, domain: int, work: Path) -> dict:
    """One launch start; its --json figures (latency_max_ms, rejected_stale, error)."""
    env = {k: v for k, v in os.environ.items() if k != 'HAPTIC_ANFIS_DDS_SHM'}
    if config.startswith('shm'):
        env['HAPTIC_ANFIS_DDS_SHM'] = '1'
    bag = work / f'bag_{time.monotonic_ns()}'
    p = subprocess.Popen([HAPTIC, 'launch', '--duration', str(duration), '--localhost',
                          '--domain-id', str(domain), '--log-dir', str(work / 'logs'),
                          '--record', str(bag), '--json'], cwd=ROOT, env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    joiner = None
    result = {}
    try:
        for line in p.stdout:
            if line.startswith('ready after') and config.endswith('+join'):
                time.sleep(1.0)  # a user's `ros2 topic echo` once the session runs
                jenv = dict(env)  # a plain rclpy process: rmw's own localhost setup
                jenv.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
                joiner = subprocess.Popen([sys.executable, '-c', JOINER], env=jenv,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            if line.startswith('{'):
                result = json.loads(line)
        p.wait(120)
    finally:
        if joiner is not None:
            joiner.terminate()
            joiner.wait(30)
    if not result:
        raise RuntimeError(f'{config}: launch gave no --json figures (exit {p.returncode})')
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--starts', type=int, default=20)
    ap.add_argument('--duration', type=float, default=5.0)
    ap.add_argument('--configs', default='udp,shm,udp+join,shm+join')
    ap.add_argument('--domain-id', type=int, default=79)
    args = ap.parse_args()
    print(f'{args.starts} `launch --localhost --record` starts per row, {args.duration:g} s each '
          'once ready; figures from `launch --json`.\n')
    print('| transport | late joiner | starts | starts with a latency > 100 ms | latency max: '
          'p50 / max [ms] | local models refused as stale | applied-force error RMS: p50 / '
          'max [%] |')
    print('|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory(prefix='bench-dds-') as tmp:
        for config in args.configs.split(','):
            lat, stale, err = [], 0, []
            for _ in range(args.starts):
                r = one_start(config, args.duration, args.domain_id, Path(tmp))
                lat.append(r['latency_max_ms'])
                stale += r['rejected_stale']
                err.append(r['force_error_rms_pct'])
            lat_s, err_s = sorted(lat), sorted(err)
            name = ('UDP only (default)' if config.startswith('udp')
                    else 'shared memory + UDP (HAPTIC_ANFIS_DDS_SHM=1)')
            print(f'| {name} | {"yes" if config.endswith("+join") else "no"} | {len(lat)} | '
                  f'{sum(x > 100 for x in lat)} | {lat_s[len(lat_s) // 2]:.1f} / {lat_s[-1]:.1f} | '
                  f'{stale} | {err_s[len(err_s) // 2]:.2f} / {err_s[-1]:.2f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

"""Start time of every node, cold (empty numba cache) and warm (cache filled by the cold start).

Each node is started alone as its own process (as ``haptic-anfis launch`` does) with
``NUMBA_CACHE_DIR`` pointing at a fresh directory, until it logs ``started after N s`` (its
process age once constructed: imports, kernels compiled or loaded from the cache, mesh / model
loaded); then again with the same, now filled, directory. ``haptic-anfis warmup`` (run by
``make venv``) fills the real cache, so a fresh install starts warm. Usage:
``python bench/bench_start.py [--nodes force_server,contact_detector,...] [--repeats 1]``.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

NODES = ('force_server', 'contact_detector', 'falcon_driver', 'visualizer', 'recorder', 'trainer')


def start_time(node: str, cache: Path, work: Path, domain: int, timeout: float = 600.0) -> float:
    """Seconds from process start to the node's 'started' log line."""
    from haptic_anfis.realtime.processes import node_env, start_node, stop_node
    env = node_env(domain, localhost=True)
    env.update(NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    args = {'falcon_driver': ['-p', 'hold_until_force:=false'],
            'recorder': ['-p', f'output:={work / f"bag_{time.monotonic_ns()}"}'],
            'trainer': ['-p', f'model_path:={work / "model.json"}']}.get(node, [])
    log = work / f'{node}.log'
    p = start_node(node, args, env=env, log=log.open('w'))
    try:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            m = re.search(r'started after ([0-9.]+) s', log.read_text())
            if m:
                return float(m.group(1))
            if p.poll() is not None:
                raise RuntimeError(f'{node} exited {p.returncode}:\n{log.read_text()[-1500:]}')
            time.sleep(0.1)
        raise RuntimeError(f'{node}: not started within {timeout} s')
    finally:
        p.send_signal(signal.SIGINT)
        stop_node(p)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--nodes', default=','.join(NODES))
    ap.add_argument('--repeats', type=int, default=1, help='warm starts per node (default 1)')
    a = ap.parse_args()
    print(f'node start time: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}')
    print(f'{"node":<18} {"cold s":>7} {"warm s":>7}')
    work = Path(tempfile.mkdtemp(prefix='bench_start_'))
    domain = 200 + os.getpid() % 30
    try:
        for node in a.nodes.split(','):
            cache = work / f'numba_{node}'
            cache.mkdir()
            try:
                cold = start_time(node, cache, work, domain)
                warm = min(start_time(node, cache, work, domain) for _ in range(a.repeats))
                print(f'{node:<18} {cold:7.1f} {warm:7.1f}', flush=True)
            except RuntimeError as exc:
                print(f'{node:<18} failed: {exc}', flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f'load average at the end {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

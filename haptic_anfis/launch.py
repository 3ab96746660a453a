"""Start the package's nodes as separate processes (what ``ros2 launch`` would do; not available
here). Pure process management, no ROS imports: used by ``haptic-anfis launch``, the multi-process
loop benchmark and the cross-process tests.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import IO, Mapping, Sequence

#: The nodes' console scripts sit next to the interpreter (a virtualenv's bin/).
BIN = Path(sys.executable).parent


def node_env(domain_id: int | None = None, localhost: bool = True,
             base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a node process: this interpreter's prefix as the ament prefix (so the
    package's share/ files are found), unbuffered output, and optionally a ROS domain id and
    localhost-only discovery. The ROS wheels' bootstrap marker is dropped so that each child
    bootstraps its own environment."""
    env = {k: v for k, v in (os.environ if base is None else base).items()
           if k != '_ROS_WHEELS_BOOTSTRAP_COMPLETE'}
    env.update(AMENT_PREFIX_PATH=str(Path(sys.executable).parents[1]), PYTHONUNBUFFERED='1')
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(int(domain_id))
    if localhost:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def start_node(name: str, ros_args: Sequence[str] = (), env: Mapping[str, str] | None = None,
               log: IO | int | None = None, cwd: str | os.PathLike | None = None
               ) -> subprocess.Popen:
    """Start node ``name`` (a console script of this package) with ``--ros-args ros_args``;
    its stdout and stderr go to ``log`` (a file object, ``subprocess.DEVNULL``, or inherited)."""
    exe = BIN / name
    if not exe.exists():
        raise FileNotFoundError(f'node {name!r}: no executable {exe} (install the package: '
                                f'make venv)')
    cmd = [str(exe), *(['--ros-args', *ros_args] if ros_args else [])]
    return subprocess.Popen(cmd, env=dict(env) if env is not None else node_env(), cwd=cwd,
                            stdout=log, stderr=subprocess.STDOUT if log is not None else None)


def stop_node(p: subprocess.Popen, timeout: float = 10.0) -> int:
    """Ask a node to stop as Ctrl-C would (SIGINT: nodes zero the force and close their bags),
    kill it if it has not exited after ``timeout`` seconds; returns its exit code."""
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5.0)
    return p.returncode

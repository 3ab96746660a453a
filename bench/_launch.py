"""What the benchmarks that watch a ``haptic-anfis launch`` from a probe node of their own share."""
from __future__ import annotations

import signal
import subprocess

__all__ = ['stop_launch']


def stop_launch(launch: subprocess.Popen, executor, node, context) -> None:
    """Stop the launch as Ctrl-C does (its nodes stop in order; killed after 120 s), then the
    probe node, its executor and its rclpy context."""
    import rclpy
    launch.send_signal(signal.SIGINT)
    try:
        launch.wait(120)
    except subprocess.TimeoutExpired:
        launch.kill()
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown(context=context)

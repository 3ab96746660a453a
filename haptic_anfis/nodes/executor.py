"""The one executor factory of the package, and the garbage-collector settling every spinning
process does once its nodes are built."""
from __future__ import annotations

__all__ = ['make_executor', 'settle_gc']


def make_executor(context=None):
    """The executor measured fastest here: rclpy's EventsExecutor (drive it with
    ``spin_once(timeout_sec=...)``: its ``spin()`` runs no callbacks with the rclpy wheels here).
    ``context``: the rclpy context (None = the default one)."""
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def settle_gc() -> None:
    """Collect once, then move every object alive now (modules, compiled kernels, the mesh, the
    model) into the permanent generation: later collections walk only what the running loop
    allocates (measured: longest gen-0 pause 0.26 ms frozen, 0.87 ms not; bench_soak.py)."""
    import gc
    gc.collect()
    gc.freeze()

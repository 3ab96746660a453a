"""Ctrl-C (SIGINT) for a spin loop: it ends the loop between callbacks, never inside one.

Python raises KeyboardInterrupt at the next bytecode of the main thread, which in a spinning
graph is usually inside a callback: in the middle of a force-model evaluation (numba then turns
it into ``SystemError: ... returned a result with an exception set``, and the session ended in a
traceback instead of its clean stop — measured, ``sim`` stopped with Ctrl-C in CI), or inside
rclpy, where it was logged FATAL. While ``spinning``, the handler only records the request and
the loop checks it between callbacks.
"""
from __future__ import annotations

import signal
import threading

__all__ = ['SigintStop']


class SigintStop:
    """A SIGINT handler for a spin loop (main thread only; elsewhere it does nothing): raises
    KeyboardInterrupt at once unless ``spinning``; while spinning it only sets ``requested``.
    ``restore()`` (or leaving the ``with`` block) puts the previous handler back."""

    def __init__(self, spinning: bool = False):
        self.spinning = spinning
        self.requested = False
        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)

    def _on_sigint(self, signum, frame) -> None:
        if not self.spinning:
            raise KeyboardInterrupt
        self.requested = True

    def restore(self) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def __enter__(self) -> SigintStop:
        return self

    def __exit__(self, *exc) -> None:
        self.restore()

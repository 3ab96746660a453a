"""Hold a palpation script at its start until the session is ready (no ROS).

A simulated hand that starts moving while the contact detector is still compiling presses into the
tissue with no force to feel (a cold start once took 23 s). :class:`HeldScript` wraps a
:class:`~haptic_anfis.device.PalpationScript`: until :meth:`HeldScript.release` it answers with the
script's first point (the hand waits above the skin, not pressing); the script's own time starts at
the first query after the release. Thread-safe enough for one writer (the executor thread calls
``release``) and one reader (the servo thread): the state is two attributes set once.
"""
from __future__ import annotations


class HeldScript:
    """``script`` (anything with ``target(t)``, ``is_pressing(t)``, ``duration``) held at t = 0
    until :meth:`release`; ``held=False`` makes it transparent (the script runs from t = 0)."""

    def __init__(self, script, held: bool = True):
        self.script = script
        self._released = not held
        self._offset: float | None = None if held else 0.0

    @property
    def duration(self) -> float:
        return self.script.duration

    @property
    def held(self) -> bool:
        """Still held: not released yet (the compiled servo loop plays the script's arrays and
        never queries this object, so release, not the next query, ends the hold)."""
        return not self._released

    def release(self) -> None:
        """Start the script at the next query (idempotent)."""
        self._released = True

    def _local(self, t: float) -> float:
        """Script time for the device's time ``t`` [s] since it opened."""
        if self._offset is None:
            if not self._released:
                return 0.0
            self._offset = t
        return max(t - self._offset, 0.0)

    def target(self, t: float):
        return self.script.target(self._local(t))

    def is_pressing(self, t: float) -> bool:
        return self.script.is_pressing(self._local(t))

    def buttons(self, t: float) -> tuple[int, int]:
        """The script's grip buttons (0/1, 0/1) at its own time (both up while held)."""
        if self.held and not self._released:
            return 0, 0
        f = getattr(self.script, 'buttons', None)
        return f(self._local(t)) if f is not None else (0, 0)

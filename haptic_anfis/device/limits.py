"""The bounds the device sets on the driver's safety parameters, which no parameter file, ``-p``
override or session option can lift (ROS-free; the checks return one message or None).

- ``max_force`` [N]: at most the backend's rated force (:data:`RATED_FORCE_BY_BACKEND`). The
  simulated backend models a Falcon, so it has the Falcon's rating: a session on the simulator
  then renders what the trainee would feel on the device.
- ``watchdog_timeout`` [s]: within :data:`WATCHDOG_RANGE`, 1-50 ms. Below one period of the
  fastest servo loop (1 ms at 1 kHz) no command could ever be on time; above 50 ms the last force
  stays on the hand while a palpating hand moves several millimetres (0.1 m/s for 50 ms: 5 mm,
  the local model's validity radius), and 50 ms is also the real Falcon's own stall guard
  (``stall_timeout``, measured above the USB thread's worst gap, docs/falcon.md).
- ``rate`` [Hz]: within :data:`RATE_RANGE`, 100-1000 Hz. The Falcon answers each command packet
  with one reply, and with the FTDI latency timer at its 1 ms minimum (the servo mode, as
  libnifalcon sets it) a round trip takes at least 1 ms: 1 kHz is the most it runs (and what
  its servo loop is measured at). Below 100 Hz a tick is longer than a fifth of the longest
  watchdog and the passivity bound (K <= 2 b / T) leaves less than a tenth of the Falcon's
  stiffness; the simulator models the Falcon, so it takes the same range.
"""
from __future__ import annotations

import math

from .falcon import RATED_FORCE

__all__ = ['RATED_FORCE_BY_BACKEND', 'WATCHDOG_RANGE', 'RATE_RANGE', 'rated_force',
           'check_max_force', 'check_watchdog', 'check_rate']

#: Rated force [N] of each driver backend ('sim' models a Falcon).
RATED_FORCE_BY_BACKEND = {'sim': RATED_FORCE, 'falcon': RATED_FORCE}
#: Watchdog timeouts [s] that still protect (see the module's docstring).
WATCHDOG_RANGE = (0.001, 0.050)
#: Servo loop rates [Hz] the Falcon runs (see the module's docstring).
RATE_RANGE = (100.0, 1000.0)


def rated_force(backend: str | None = None) -> float:
    """The rated force [N] of ``backend`` (None: the largest of any backend)."""
    if backend is None or backend not in RATED_FORCE_BY_BACKEND:
        return max(RATED_FORCE_BY_BACKEND.values())
    return RATED_FORCE_BY_BACKEND[backend]


def _within(v: float, lo: float, hi: float, unit: str, why: str, lo_open: bool = False) -> str | None:
    ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi
    if ok:
        return None
    lower = f'> {lo:g}' if lo_open else f'>= {lo:g}'
    return f'expected a finite value {lower} and <= {hi:g} {unit} ({why})'


def check_max_force(v: float, backend: str | None = None) -> str | None:
    """``max_force`` [N]: > 0 and at most the rated force of ``backend`` (None: any backend)."""
    return _within(v, 0.0, rated_force(backend), 'N',
                   "the Falcon's rated force; the sim backend models a Falcon", lo_open=True)


def check_watchdog(v: float) -> str | None:
    """``watchdog_timeout`` [s] within :data:`WATCHDOG_RANGE`."""
    return _within(v, *WATCHDOG_RANGE, 's', 'longer leaves the last force on a moving hand, '
                   'shorter is less than a servo period')


def check_rate(v: float) -> str | None:
    """``rate`` [Hz] within :data:`RATE_RANGE`."""
    return _within(v, *RATE_RANGE, 'Hz', "what the Falcon's USB servo loop runs")


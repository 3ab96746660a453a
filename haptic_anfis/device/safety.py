"""The force safety layer between whatever commands a force and the device's motors (no ROS).

Every force that reaches a device goes through :meth:`SafetyLayer.output`, called once per servo
tick. Rules, in order:

1. Disabled (before :meth:`start`, after :meth:`stop`): output exactly zero, commands ignored.
2. A command holding NaN/Inf, or stamped in a frame other than ``frame_id``, is rejected: the
   target becomes zero and the output drops to zero at once (zero is the safe state; no ramp), and
   stays there until the next valid command.
3. Watchdog: when the newest valid command is older than ``watchdog_timeout`` seconds, the target
   becomes zero and the output ramps down to it at the rate limit (``max_force / max_force_rate``
   seconds from full force: 10 ms with the defaults); if the caller itself was stalled longer than
   the timeout since the previous output (a paused process), the output is zero at once: the
   ramp's time has passed already. The next valid command re-arms it. A
   command's time is the time the caller gives :meth:`SafetyLayer.command`: the driver gives the
   time of its own pose the command answers (its stamp's age), not its arrival; a
   command older than the current one is ignored (out of order).
4. Rate limit: the output vector moves towards the target by at most ``max_force_rate * dt``
   (``dt`` = time since the last output, capped at ``max_dt``).
5. Clamp: the output's magnitude is at most ``max_force`` (direction kept).

Forces are (3,) newtons; time is seconds on any monotonic clock the caller chooses.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from .falcon import RATED_FORCE

OK, REJECTED_NONFINITE, REJECTED_FRAME, IGNORED_DISABLED, IGNORED_OLDER = (
    'ok', 'rejected: non-finite force', 'rejected: wrong frame', 'ignored: disabled',
    'ignored: older than the current command')


@dataclass
class SafetyStats:
    """Counters since construction."""
    commands: int = 0
    rejected_nonfinite: int = 0
    rejected_frame: int = 0
    watchdog_trips: int = 0
    watchdog_trips_in_contact: int = 0  # trips while a non-zero force was commanded
    clamped: int = 0  # outputs whose target exceeded max_force
    max_output: float = 0.0  # largest output magnitude [N]
    last_reject: str = field(default='')


class SafetyLayer:
    """Clamp, rate limit, watchdog and command validation (see the module docstring).

    Args:
        max_force: device force limit [N], > 0 (the falcon driver passes its ``max_force``, default
            8.9 N, the Falcon's rated force).
        max_force_rate: largest change of the output per second [N/s], > 0.
        watchdog_timeout: command age [s] after which the force ramps to zero, > 0.
        frame_id: the frame commands must be expressed in ('' accepts any frame).
        max_dt: cap on the time step used by the rate limit [s] (a stalled caller must not earn
            a large jump).
    """

    def __init__(self, max_force: float = RATED_FORCE, max_force_rate: float = 1000.0,
                 watchdog_timeout: float = 0.010, frame_id: str = 'tissue',
                 max_dt: float = 0.005) -> None:
        for name, v in (('max_force', max_force), ('max_force_rate', max_force_rate),
                        ('watchdog_timeout', watchdog_timeout), ('max_dt', max_dt)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')
        self.max_force = float(max_force)
        self.max_force_rate = float(max_force_rate)
        self.watchdog_timeout = float(watchdog_timeout)
        self.frame_id = frame_id
        self.max_dt = float(max_dt)
        self.stats = SafetyStats()
        self._lock = threading.Lock()
        self._enabled = False
        self._target = (0.0, 0.0, 0.0)
        self._out = (0.0, 0.0, 0.0)
        self._last_cmd: float | None = None
        self._last_out: float | None = None
        self._tripped = False

    # -- state ----------------------------------------------------------------------------------
    @property
    def enabled(self) -> bool:
        return self._enabled

    @property
    def watchdog_tripped(self) -> bool:
        return self._tripped

    def start(self, now: float) -> None:
        """Enable; the output starts at zero and the watchdog counts from ``now``."""
        with self._lock:
            self._enabled = True
            self._target = self._out = (0.0, 0.0, 0.0)
            self._last_cmd = None
            self._last_out = now
            self._tripped = False

    def stop(self) -> None:
        """Disable: the output is zero from now on (until :meth:`start`)."""
        with self._lock:
            self._enabled = False
            self._target = self._out = (0.0, 0.0, 0.0)

    # -- input ----------------------------------------------------------------------------------
    def command(self, force, now: float, frame_id: str | None = None, count: bool = True) -> str:
        """Offer a force command (3,) [N] whose time is ``now`` (the time of the pose it answers,
        or its arrival); returns OK or why it was refused. ``count=False``: not counted in
        ``stats.commands`` (the local model feeds its force every servo tick)."""
        try:
            fx, fy, fz = (float(v) for v in force)
        except (TypeError, ValueError):
            fx = fy = fz = math.nan
        with self._lock:
            if not self._enabled:
                return IGNORED_DISABLED
            if count:
                self.stats.commands += 1
            if not math.isfinite(fx + fy + fz) or not all(map(math.isfinite, (fx, fy, fz))):
                self.stats.rejected_nonfinite += 1
                self._fault(REJECTED_NONFINITE)
                return REJECTED_NONFINITE
            if self.frame_id and frame_id is not None and frame_id != self.frame_id:
                self.stats.rejected_frame += 1
                self._fault(f'{REJECTED_FRAME} {frame_id!r} (expected {self.frame_id!r})')
                return REJECTED_FRAME
            if self._last_cmd is not None and now < self._last_cmd:
                return IGNORED_OLDER
            self._target = (fx, fy, fz)
            self._last_cmd = now
            self._tripped = False
            return OK

    def reject(self, why: str) -> None:
        """A non-finite input from elsewhere (e.g. a local force model): counted as a non-finite
        command, and the output drops to zero at once as for one."""
        with self._lock:
            if not self._enabled:
                return
            self.stats.rejected_nonfinite += 1
            self._fault(why)

    def _fault(self, why: str) -> None:
        self._target = self._out = (0.0, 0.0, 0.0)
        self._last_cmd = None  # no valid command: the watchdog stays tripped until one comes
        self.stats.last_reject = why

    # -- output ---------------------------------------------------------------------------------
    def output(self, now: float) -> tuple[float, float, float]:
        """The force to apply now [N]: finite, magnitude <= max_force, rate-limited."""
        with self._lock:
            if not self._enabled:
                return (0.0, 0.0, 0.0)
            last = self._last_out if self._last_out is not None else now
            gap = now - last
            dt = min(max(gap, 0.0), self.max_dt)
            self._last_out = now
            age = math.inf if self._last_cmd is None else now - self._last_cmd
            if age > self.watchdog_timeout:
                if not self._tripped and self._last_cmd is not None:
                    self.stats.watchdog_trips += 1
                    if self._target != (0.0, 0.0, 0.0):
                        self.stats.watchdog_trips_in_contact += 1
                self._tripped = True
                self._target = (0.0, 0.0, 0.0)
                if gap > self.watchdog_timeout:
                    # The caller itself stalled longer than the watchdog (a paused process): the
                    # ramp's time has passed already; zero now, not a ramp from a stale force.
                    self._out = (0.0, 0.0, 0.0)
            tx, ty, tz = self._target
            tn = math.sqrt(tx * tx + ty * ty + tz * tz)
            if tn > self.max_force:
                self.stats.clamped += 1
                s = self.max_force / tn
                tx, ty, tz = tx * s, ty * s, tz * s
            ox, oy, oz = self._out
            dx, dy, dz = tx - ox, ty - oy, tz - oz
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            step = self.max_force_rate * dt
            if dn > step:
                s = step / dn
                dx, dy, dz = dx * s, dy * s, dz * s
            ox, oy, oz = ox + dx, oy + dy, oz + dz
            on = math.sqrt(ox * ox + oy * oy + oz * oz)
            if on > self.max_force:  # rounding guard: never above the limit
                s = self.max_force / on
                ox, oy, oz = ox * s, oy * s, oz * s
                on = self.max_force
            self._out = (ox, oy, oz)
            if on > self.stats.max_output:
                self.stats.max_output = on
            return self._out


def clamp_norm(f: np.ndarray, limit: float) -> np.ndarray:
    """``f`` (3,) scaled down to magnitude ``limit`` if longer (direction kept)."""
    n = float(np.linalg.norm(f))
    return f * (limit / n) if n > limit else f

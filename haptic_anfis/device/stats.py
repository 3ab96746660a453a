"""Servo-loop timing statistics (no ROS): tick rate, deadline misses, latency percentiles."""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np


@dataclass
class LoopStats:
    """Counters one servo loop fills in; read with :meth:`summary`.

    A *deadline miss* is a tick that started more than one period late (at least one tick was
    skipped); the loop then re-synchronises instead of bursting to catch up. Latencies are pose
    stamp -> force command received [s], recorded by whoever receives the commands.
    """
    period: float = 0.001
    ticks: int = 0
    deadline_misses: int = 0
    t_first: float | None = None
    t_last: float | None = None
    max_force: float = 0.0

    def __post_init__(self):
        self._lat: list[float] = []
        self._lock = threading.Lock()

    def reset(self) -> None:
        """Start a new measurement window (counters and latencies cleared)."""
        self.ticks = self.deadline_misses = 0
        self.t_first = self.t_last = None
        self.max_force = 0.0
        self._lat = []

    def tick(self, now: float) -> None:
        if self.t_first is None:
            self.t_first = now
        self.t_last = now
        self.ticks += 1

    def latency(self, seconds: float) -> None:
        self._lat.append(seconds)  # list.append is atomic under the GIL

    @property
    def latencies(self) -> np.ndarray:
        return np.asarray(self._lat, dtype=np.float64)

    def summary(self) -> dict:
        span = (self.t_last - self.t_first) if self.ticks > 1 else 0.0
        lat = self.latencies
        pct = (np.percentile(lat, [50, 99]) if len(lat) else [float('nan')] * 2)
        return {
            'ticks': self.ticks, 'seconds': span,
            'rate_hz': (self.ticks - 1) / span if span > 0 else 0.0,
            'deadline_misses': self.deadline_misses,
            'latency_n': int(len(lat)),
            'latency_p50_ms': float(pct[0]) * 1e3, 'latency_p99_ms': float(pct[1]) * 1e3,
            'latency_max_ms': float(lat.max()) * 1e3 if len(lat) else float('nan'),
            'max_force_N': self.max_force,
        }

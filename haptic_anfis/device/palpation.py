"""Scripted palpation: where the simulated trainee's hand pulls the device handle (no ROS).

A script (YAML, see ``config/palpation.yaml``) is a list of moves in the tissue frame (metres,
seconds; chest wall x = 0, +x out of the body). Positions on the chest are (y, z); "vertical" strips
run along z at a fixed y. The hand target of a move into the tissue is ``depth`` below the
undeformed surface along -x (the surface height comes from the analytic dome ``surface.radii``).
The handle follows the target through a spring and damper (:mod:`.falcon`), so the tissue force
pushes it back and it ends up less deep than the target.

Moves:

``press``: ``{points: [[y, z], ...], depth, hold}`` — above each point, straight in to ``depth``,
    hold ``hold`` s, back out.
``strip``: ``{y: [y0, y1, ...], z: [z_start, z_end], depth}`` — for each y, in at z_start, slide to
    z_end at ``depth``, out.
``circle``: ``{center: [y, z], radius, depth, turns, period}`` — in at the circle's start, go
    round ``turns`` times at ``period`` s per turn, out.
``pause``: ``{duration}`` — stay where the last move ended (above the surface).
``mark``: ``{points: [[y, z], ...], depth, hold}`` — like ``press``, and half-way through the hold
    the hand presses button 1 ("I feel a lump here") for ``click`` s (default 0.1).
``clutch``: ``{shift: [dx, dy, dz]}`` — above the surface, hold button 0 (clutch) and move the hand
    by ``shift`` [m, tissue-frame units of the mapped device position], then release: the probe
    stays put while the device re-centres. Later moves are emitted shifted by the sum of the
    shifts, so the probe still follows the script's tissue coordinates.

``strip`` also takes ``depths: [d1, d2, ...]`` (instead of ``depth``): one pass per depth, going
back and forth along the strip without leaving the tissue (the MammaCare light / medium / deep
passes), and ``clip_radius`` [m]: each strip's z range is cut to the disc of that radius (so strips
follow a round breast). Segment buttons: :meth:`PalpationScript.buttons` (button 0 clutch,
button 1 mark); the simulated Falcon reports them.

Top-level keys: ``approach_height`` (clearance above the surface between moves, m),
``travel_speed`` (m/s in free space), ``press_speed`` (m/s into, out of and along the tissue),
``start_delay`` (s at the first point before anything moves), ``start`` ([y, z]: begin above this
point rather than the first move's), ``loop`` (repeat for ever), ``surface``
(``{radii: [rx, ry, rz]}``), ``pattern`` (the list of moves).
"""
from __future__ import annotations

import bisect
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

DEFAULT_RADII = (0.045, 0.070, 0.070)


def dome_height(y: float, z: float, radii=DEFAULT_RADII) -> float:
    """x of the semi-ellipsoid surface above (y, z), 0 outside its footprint [m]."""
    rx, ry, rz = radii
    s = 1.0 - (y / ry) ** 2 - (z / rz) ** 2
    return rx * math.sqrt(s) if s > 0 else 0.0


@dataclass
class PalpationScript:
    """A piecewise-linear hand trajectory: ``times`` (n,) [s], ``points`` (n, 3) [m], ``pressing``
    (n - 1,) bool per segment (the hand is pushing into the tissue), ``button_states`` (n - 1, 2)
    0/1 per segment (button 0 clutch, button 1 mark; None = never pressed)."""
    times: np.ndarray
    points: np.ndarray
    pressing: np.ndarray
    loop: bool = True
    button_states: np.ndarray | None = None

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def _local(self, t: float) -> float:
        if self.loop and self.duration > 0:
            return t % self.duration
        return min(max(t, 0.0), self.duration)

    def target(self, t: float) -> tuple[float, float, float]:
        """Hand target at time ``t`` [s] since the script started (tissue frame, m)."""
        t = self._local(t)
        i = bisect.bisect_right(self._tl, t) - 1
        if i >= len(self._tl) - 1:
            return tuple(self._pl[-1])
        t0, t1 = self._tl[i], self._tl[i + 1]
        a = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        p0, p1 = self._pl[i], self._pl[i + 1]
        return (p0[0] + a * (p1[0] - p0[0]), p0[1] + a * (p1[1] - p0[1]),
                p0[2] + a * (p1[2] - p0[2]))

    def is_pressing(self, t: float) -> bool:
        t = self._local(t)
        i = min(max(bisect.bisect_right(self._tl, t) - 1, 0), len(self.pressing) - 1)
        return bool(self.pressing[i])

    def buttons(self, t: float) -> tuple[int, int]:
        """(clutch, mark) buttons the hand holds at time ``t`` [s]."""
        if self._bl is None:
            return (0, 0)
        t = self._local(t)
        i = min(max(bisect.bisect_right(self._tl, t) - 1, 0), len(self._bl) - 1)
        return self._bl[i]

    def __post_init__(self) -> None:
        self._tl = [float(v) for v in self.times]
        self._pl = [tuple(float(c) for c in p) for p in self.points]
        bs = self.button_states
        self._bl = None if bs is None or not np.any(bs) else [
            (int(a), int(b)) for a, b in np.asarray(bs, dtype=int)]

    # -- building -------------------------------------------------------------------------------
    @classmethod
    def from_yaml(cls, path: str | os.PathLike) -> 'PalpationScript':
        path = Path(path)
        try:
            doc = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ValueError(f'palpation script {str(path)!r}: {exc}') from exc
        try:
            return cls.from_dict(doc)
        except (ValueError, TypeError, KeyError) as exc:
            raise ValueError(f'palpation script {str(path)!r}: {exc}') from exc

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> 'PalpationScript':
        if not isinstance(doc, dict) or not isinstance(doc.get('pattern'), list) \
                or not doc['pattern']:
            raise ValueError('expected a mapping with a non-empty "pattern" list')
        radii = tuple(float(r) for r in doc.get('surface', {}).get('radii', DEFAULT_RADII))
        b = _Builder(radii, _pos(doc, 'approach_height', 0.010, zero_ok=True),
                     _pos(doc, 'travel_speed', 0.10), _pos(doc, 'press_speed', 0.02))
        moves = doc['pattern']
        try:
            first = _first_point(moves)
            if len(first) != 2:
                raise ValueError
        except (TypeError, ValueError, IndexError):
            first = (0.0, 0.0)  # malformed: the move itself reports the precise error below
        home = first
        if 'start' in doc:  # begin above this (y, z) instead of the first move's point
            st = doc['start']
            if not isinstance(st, (list, tuple)) or len(st) != 2 or not all(
                    isinstance(v, (int, float)) and math.isfinite(v) for v in st):
                raise ValueError(f'start: expected [y, z] in metres, got {st!r}')
            home = (float(st[0]), float(st[1]))
        b.start(home, _pos(doc, 'start_delay', 0.5, zero_ok=True))
        for k, move in enumerate(moves):
            if not isinstance(move, dict) or len(move) != 1:
                raise ValueError(f'pattern[{k}]: expected one of press/strip/circle/pause/'
                                 f'mark/clutch, '
                                 f'got {move!r}')
            (kind, spec), = move.items()
            spec = spec or {}
            if kind == 'press':
                for y, z in _pairs(spec, 'points', k):
                    b.press(y, z, _pos(spec, 'depth', 0.010), _pos(spec, 'hold', 0.5, zero_ok=True))
            elif kind == 'strip':
                z0, z1 = (float(v) for v in spec['z'])
                depths = [float(d) for d in spec['depths']] if 'depths' in spec \
                    else [_pos(spec, 'depth', 0.006)]
                if not depths or any(not (math.isfinite(d) and d > 0) for d in depths):
                    raise ValueError(f'pattern[{k}].depths: expected depths > 0 m, got {depths!r}')
                clip = _pos(spec, 'clip_radius', 0.0, zero_ok=True)
                for y in spec['y']:
                    y = float(y)
                    za, zb = z0, z1
                    if clip > 0:
                        if abs(y) >= clip:
                            continue
                        h = math.sqrt(clip * clip - y * y)
                        za, zb = max(min(z0, z1), -h), min(max(z0, z1), h)
                        if z1 < z0:
                            za, zb = zb, za
                    b.strip(y, za, zb, depths)
            elif kind == 'mark':
                for y, z in _pairs(spec, 'points', k):
                    b.press(y, z, _pos(spec, 'depth', 0.010), _pos(spec, 'hold', 0.6),
                            click=_pos(spec, 'click', 0.1))
            elif kind == 'clutch':
                shift = spec.get('shift')
                if not isinstance(shift, list) or len(shift) != 3 \
                        or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in shift):
                    raise ValueError(f'pattern[{k}].shift: expected [dx, dy, dz] in metres, '
                                     f'got {shift!r}')
                b.clutch(tuple(float(v) for v in shift))
            elif kind == 'circle':
                yc, zc = (float(v) for v in spec['center'])
                b.circle(yc, zc, _pos(spec, 'radius', 0.02), _pos(spec, 'depth', 0.006),
                         _pos(spec, 'turns', 1.0), _pos(spec, 'period', 2.0))
            elif kind == 'pause':
                b.hold(_pos(spec, 'duration', 0.5, zero_ok=True), False)
            else:
                raise ValueError(f'pattern[{k}]: unknown move {kind!r} '
                                 '(expected press, strip, circle, pause, mark or clutch)')
        b.travel_to(first)  # a looping script returns to its start
        pts = np.array(b.p) + np.array(b.shifts)
        return cls(np.array(b.t), pts, np.array(b.pressing), bool(doc.get('loop', True)),
                   np.array(b.buttons, dtype=int).reshape(-1, 2))


def _pos(d: dict, key: str, default: float, zero_ok: bool = False) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or v < 0 or (v == 0 and not zero_ok):
        raise ValueError(f'{key}: expected a number {">= 0" if zero_ok else "> 0"}, got {v!r}')
    return float(v)


def _pairs(spec: dict, key: str, k: int) -> list[tuple[float, float]]:
    pts = spec.get(key)
    if not pts or any(len(p) != 2 for p in pts):
        raise ValueError(f'pattern[{k}].{key}: expected a list of [y, z] pairs, got {pts!r}')
    return [(float(a), float(c)) for a, c in pts]


def _first_point(moves: list) -> tuple[float, float]:
    for m in moves:
        if isinstance(m, dict) and len(m) == 1:
            (kind, s), = m.items()
            s = s or {}
            if kind == 'press' and s.get('points'):
                return tuple(float(v) for v in s['points'][0])
            if kind == 'strip' and s.get('y') and s.get('z'):
                return float(s['y'][0]), float(s['z'][0])
            if kind == 'circle' and s.get('center'):
                return float(s['center'][0]) + float(s.get('radius', 0.02)), float(s['center'][1])
    return 0.0, 0.0


class _Builder:
    def __init__(self, radii, clearance, travel, press):
        self.radii, self.clearance, self.travel, self.press_v = radii, clearance, travel, press
        self.t: list[float] = []
        self.p: list[tuple[float, float, float]] = []   # probe targets, script coordinates
        self.shifts: list[tuple[float, float, float]] = []  # + clutch shift = hand target
        self.shift = (0.0, 0.0, 0.0)
        self.pressing: list[bool] = []
        self.buttons: list[tuple[int, int]] = []

    def h(self, y, z):
        return dome_height(y, z, self.radii)

    def start(self, yz, delay):
        y, z = yz
        self.t.append(0.0)
        self.p.append((self.h(y, z) + self.clearance, y, z))
        self.shifts.append(self.shift)
        self.hold(delay, False)

    def go(self, p, speed, pressing, buttons=(0, 0)):
        d = math.dist(p, self.p[-1])
        self.t.append(self.t[-1] + max(d / speed, 1e-3))
        self.p.append(tuple(p))
        self.shifts.append(self.shift)
        self.pressing.append(pressing)
        self.buttons.append(buttons)

    def hold(self, dt, pressing, buttons=(0, 0)):
        if dt > 0:
            self.t.append(self.t[-1] + dt)
            self.p.append(self.p[-1])
            self.shifts.append(self.shift)
            self.pressing.append(pressing)
            self.buttons.append(buttons)

    def clutch(self, d):
        # Button 0 down for 0.05 s, the hand moves by d (the probe stays), button 0 up.
        self.hold(0.05, False, (1, 0))
        s = self.shift
        self.shift = (s[0] + d[0], s[1] + d[1], s[2] + d[2])
        self.t.append(self.t[-1] + max(math.sqrt(sum(v * v for v in d)) / self.travel, 1e-3))
        self.p.append(self.p[-1])
        self.shifts.append(self.shift)
        self.pressing.append(False)
        self.buttons.append((1, 0))
        self.hold(0.05, False, (1, 0))
        self.hold(0.05, False)

    def travel_to(self, yz):
        y, z = yz
        above = self.h(y, z) + self.clearance
        cur = self.p[-1]
        top = max(cur[0], above)
        if cur[0] < top:
            self.go((top, cur[1], cur[2]), self.travel, False)
        self.go((top, y, z), self.travel, False)
        if top > above:
            self.go((above, y, z), self.travel, False)

    def press(self, y, z, depth, hold, click=0.0):
        self.travel_to((y, z))
        self.go((self.h(y, z) - depth, y, z), self.press_v, True)
        if click > 0:  # button 1 half-way through the hold
            self.hold(hold / 2, True)
            self.hold(click, True, (0, 1))
            self.hold(hold / 2, True)
        else:
            self.hold(hold, True)
        self.go((self.h(y, z) + self.clearance, y, z), self.press_v, False)

    def strip(self, y, z0, z1, depths):
        self.travel_to((y, z0))
        self.go((self.h(y, z0) - depths[0], y, z0), self.press_v, True)
        n = max(int(abs(z1 - z0) / 0.002), 1)
        ends = (z0, z1)
        for k, depth in enumerate(depths):
            za, zb = ends[k % 2], ends[(k + 1) % 2]
            self.go((self.h(y, za) - depth, y, za), self.press_v, True)  # to this pass's depth
            for z in np.linspace(za, zb, n + 1)[1:]:
                self.go((self.h(y, z) - depth, y, float(z)), self.press_v, True)
        zl = self.p[-1][2]
        self.go((self.h(y, zl) + self.clearance, y, zl), self.press_v, False)

    def circle(self, yc, zc, r, depth, turns, period):
        y0, z0 = yc + r, zc
        self.travel_to((y0, z0))
        self.go((self.h(y0, z0) - depth, y0, z0), self.press_v, True)
        n = max(int(72 * turns), 4)
        speed = 2 * math.pi * r / period
        for a in np.linspace(0.0, 2 * math.pi * turns, n + 1)[1:]:
            y, z = yc + r * math.cos(a), zc + r * math.sin(a)
            self.go((self.h(y, z) - depth, y, z), speed, True)
        y, z = self.p[-1][1], self.p[-1][2]
        self.go((self.h(y, z) + self.clearance, y, z), self.press_v, False)

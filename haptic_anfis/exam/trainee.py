"""Simulated trainees (no ROS): a scripted search, then marks where the felt forces say a lump is.

:class:`TraineeController` is the simulated Falcon's hand script (it has the
:class:`~haptic_anfis.device.PalpationScript` interface: ``target``, ``is_pressing``, ``buttons``,
``duration``). It plays the search script (``config/trainees/<name>.yaml``); meanwhile the caller
feeds it what the trainee feels (:meth:`feel`: contact point, depth, force magnitude from the
wrench topic). When the search is over, :meth:`decide` (called off the servo thread) runs
:func:`~haptic_anfis.exam.detector.detect_lumps` on those samples and appends a ``mark`` move at
each suspected lump (press there, button 1). Marks therefore come from the forces alone.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import yaml

from ..device.palpation import PalpationScript
from ..resources import config_dir, config_file
from ..rows import RowLog
from .detector import Detection, detect_lumps

TRAINEE_DIR = config_dir('trainees')
TRAINEES = ('systematic', 'careless')


def trainee_path(name: str) -> Path:
    """A shipped trainee name (systematic, careless) or a script path -> the YAML path."""
    if name in TRAINEES:
        return config_file(f'trainees/{name}.yaml')
    p = Path(name)
    if not p.is_file():
        raise ValueError(f'--trainee {name!r}: expected systematic, careless or a palpation '
                         'script file (YAML)')
    return p


def fit_to_breast(doc: dict, region_radius: float, radii, palpable_radius: float) -> dict:
    """The palpation script ``doc``, laid out for a palpable region of ``region_radius`` [m], moved
    onto a breast of ``radii`` (rx, ry, rz) [m] whose palpable region has ``palpable_radius`` [m].

    A trainee sees the breast it examines (never its lesions): the hand aims from the new surface
    (``surface.radii``) and every ``strip`` move's lanes, z ends and ``clip_radius`` scale by
    ``palpable_radius / region_radius`` (so the shipped systematic trainee's 8 mm lanes over the
    default 42 mm region become 7.2 mm over a 38 mm one and 9.1 mm over a 48 mm one: still
    overlapping the 16 mm probe). Depths, speeds and other moves are kept. Returns a new dict.
    """
    if not (region_radius > 0 and palpable_radius > 0):
        raise ValueError(f'region_radius {region_radius!r} / palpable radius {palpable_radius!r}: '
                         'expected > 0 m')
    k = palpable_radius / region_radius
    out = dict(doc)
    out['surface'] = {**(doc.get('surface') or {}), 'radii': [float(r) for r in radii]}
    pattern = []
    for move in doc.get('pattern') or []:
        if isinstance(move, dict) and set(move) == {'strip'} and isinstance(move['strip'], dict):
            st = dict(move['strip'])
            st['y'] = [round(float(v) * k, 6) for v in st.get('y', [])]
            st['z'] = [round(float(v) * k, 6) for v in st.get('z', [])]
            if 'clip_radius' in st:
                st['clip_radius'] = round(float(st['clip_radius']) * k, 6)
            move = {'strip': st}
        pattern.append(move)
    out['pattern'] = pattern
    return out


class TraineeController:
    """The hand script of a simulated trainee (thread-safe between the servo thread, which calls
    ``target``/``buttons``, and the executor thread, which calls ``feel``/``decide``).

    Args:
        doc: the trainee YAML as a dict: a palpation script (``loop`` forced off) plus optional
            ``mark: {depth, hold}`` (how to press a mark; no ``mark`` key = never marks) and
            ``region_radius`` [m] (the palpable radius the script's strips were laid out for).
        speed: overrides the script's ``press_speed`` [m/s] (None = keep).
        breast: ``(radii (3,) [m], palpable_radius [m])`` of the case's breast: a script with
            ``region_radius`` is fitted to it (:func:`fit_to_breast`); None = as written.
    """

    def __init__(self, doc: dict, speed: float | None = None, detector_kw: dict | None = None,
                 breast: tuple | None = None):
        doc = dict(doc)
        region = doc.pop('region_radius', None)
        if breast is not None and region is not None:
            doc = fit_to_breast(doc, float(region), *breast)
        doc['loop'] = False
        if speed is not None:
            doc['press_speed'] = float(speed)
        self.mark_spec = doc.pop('mark', None)
        self.doc = doc
        self.search = PalpationScript.from_dict(doc)
        self.detector_kw = detector_kw or {}
        self._after: tuple[float, PalpationScript] | None = None
        self._lock = threading.Lock()
        self._samples = RowLog(5)   # felt at up to 1 kHz for the whole search
        self.t_now = 0.0
        self.detections: list[Detection] | None = None
        self.done_at: float | None = None

    @classmethod
    def from_yaml(cls, path: str | os.PathLike, speed: float | None = None,
                  breast: tuple | None = None) -> 'TraineeController':
        path = Path(path)
        try:
            doc = yaml.safe_load(path.read_text())
            if not isinstance(doc, dict):
                raise ValueError('expected a mapping (a palpation script)')
            return cls(doc, speed, breast=breast)
        except (OSError, yaml.YAMLError, ValueError, TypeError, KeyError) as exc:
            raise ValueError(f'trainee script {str(path)!r}: {exc}') from None

    # -- the script interface (servo thread) ----------------------------------------------------
    @property
    def duration(self) -> float:
        a = self._after
        return self.search.duration if a is None else a[0] + a[1].duration

    @property
    def loop(self) -> bool:
        return False

    def _which(self, t: float):
        a = self._after
        if a is not None and t >= a[0]:
            return a[1], t - a[0]
        return self.search, t

    def target(self, t: float):
        self.t_now = t
        s, u = self._which(t)
        return s.target(u)

    def is_pressing(self, t: float) -> bool:
        s, u = self._which(t)
        return s.is_pressing(u)

    def buttons(self, t: float):
        s, u = self._which(t)
        return s.buttons(u)

    # -- what the trainee feels and decides (executor thread) -----------------------------------
    def feel(self, point, depth: float, force: float) -> None:
        """One felt sample: contact point (3,) [m], depth [m], force magnitude [N]."""
        self._samples.append((point[0], point[1], point[2], depth, force))

    @property
    def felt(self) -> int:
        """Samples felt so far."""
        return len(self._samples)

    def felt_array(self) -> np.ndarray:
        """(n, 5): every felt sample's contact point x, y, z [m], depth [m], |F| [N]."""
        return self._samples.array()

    @property
    def search_over(self) -> bool:
        return self.t_now >= self.search.duration

    def decide(self) -> list[Detection]:
        """After the search: find lumps in the felt forces and queue a mark at each (once)."""
        if self.detections is not None:
            return self.detections
        s = self._samples.array()
        self.detections = detect_lumps(s[:, :3], s[:, 3], s[:, 4], **self.detector_kw) \
            if self.mark_spec is not None and len(s) else []
        t0 = self.t_now + 0.05
        if self.detections:
            last = self.search.points[-1]
            spec = self.mark_spec or {}
            doc = {k: v for k, v in self.doc.items() if k != 'pattern'}
            doc.update(start=[float(last[1]), float(last[2])], start_delay=0.0, loop=False,
                       pattern=[{'mark': {'points': [[d.y, d.z] for d in self.detections],
                                          'depth': float(spec.get('depth', 0.02)),
                                          'hold': float(spec.get('hold', 0.6))}}])
            self._after = (t0, PalpationScript.from_dict(doc))
        self.done_at = self.duration if self.detections else t0
        return self.detections

    @property
    def finished(self) -> bool:
        """The search, the decision and every mark are done."""
        return self.done_at is not None and self.t_now >= self.done_at + 0.3

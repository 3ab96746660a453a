"""Exam scoring settings (``config/exam.yaml``): pressure levels, footprint, margins, score weights.

Every key is documented, with its source, in the YAML file. SI units (metres).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import yaml

from ..resources import config_file

LEVELS = ('light', 'medium', 'deep')
#: the keys that are lengths [m], and the most any may be: the Falcon's workspace is a 10 cm cube,
#: so a larger value is a length in millimetres written where metres are expected
LENGTHS = ('light', 'medium', 'deep', 'footprint_radius', 'region_radius', 'hit_margin',
           'mark_tolerance')
MAX_LENGTH = 0.1
DEFAULT_CONFIG = config_file('exam.yaml')  # source tree or installed share dir (resources)


@dataclass(frozen=True)
class ExamConfig:
    """Depth thresholds per pressure level [m] (cumulative), probe footprint radius [m], region
    radius [m] (0 = the scene's palpable radius), hit margin [m], mark tolerance [m], score
    weights, the palpability threshold [%] the library is graded at."""
    light: float = 0.002
    medium: float = 0.005
    deep: float = 0.008
    footprint_radius: float = 0.008
    region_radius: float = 0.0
    hit_margin: float = 0.008
    mark_tolerance: float = 0.005
    w_coverage: float = 0.5
    w_findings: float = 0.4
    w_pattern: float = 0.1
    false_mark_penalty: float = 10.0
    pass_deep_coverage: float = 0.9
    palpable_pct: float = 22.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f'exam config {f.name}: expected a finite number >= 0, got {v!r}')
        for name in LENGTHS:
            v = getattr(self, name)
            if v > MAX_LENGTH:
                raise ValueError(f'exam config {name}: {v!r} m is larger than the device\'s '
                                 f'workspace (expected metres <= {MAX_LENGTH:g}; '
                                 f'{v:g} mm is {v / 1000:g})')
        if self.pass_deep_coverage > 1:
            raise ValueError(f'exam config pass_deep_coverage: expected a fraction 0-1 (0.9 = '
                             f'90 %), got {self.pass_deep_coverage!r}')
        if not 0 < self.light <= self.medium <= self.deep:
            raise ValueError('exam config levels: expected 0 < light <= medium <= deep, got '
                             f'{self.light}, {self.medium}, {self.deep} m')
        if self.footprint_radius <= 0:
            raise ValueError('exam config footprint_radius: expected > 0 m')
        if self.palpable_pct <= 0:
            raise ValueError(f'exam config palpable_pct: expected a percentage > 0 (22 = 22 %), '
                             f'got {self.palpable_pct!r}')

    @property
    def thresholds(self) -> tuple[float, float, float]:
        """Depth thresholds (light, medium, deep) [m]."""
        return (self.light, self.medium, self.deep)


def load_exam_config(path: str | os.PathLike | None = None) -> ExamConfig:
    """Read ``path`` (default ``config/exam.yaml``); ValueError naming the file on a bad one."""
    path = Path(path) if path else DEFAULT_CONFIG
    if not path.is_file():
        if path == DEFAULT_CONFIG:
            return ExamConfig()  # an install without the source tree's config: the same defaults
        raise ValueError(f'exam config {str(path)!r}: no such file')
    try:
        doc = yaml.safe_load(path.read_text()) or {}
        if not isinstance(doc, dict):
            raise ValueError('expected a mapping')
        kw = dict(doc)
        kw.pop('mastery', None)   # the trainee record's (haptic_anfis.record.mastery)
        levels = kw.pop('levels', {}) or {}
        unknown = set(levels) - set(LEVELS)
        if unknown:
            raise ValueError(f'levels: unknown {sorted(unknown)} (expected {", ".join(LEVELS)})')
        kw.update(levels)
        known = {f.name for f in fields(ExamConfig)}
        bad = set(kw) - known
        if bad:
            raise ValueError(f'unknown key(s) {sorted(bad)}')
        return ExamConfig(**kw)
    except (OSError, yaml.YAMLError, ValueError, TypeError) as exc:
        # the checks of ExamConfig name themselves 'exam config': say it once, with the file
        raise ValueError(f'exam config {str(path)!r}: '
                         f'{str(exc).removeprefix("exam config ")}') from None

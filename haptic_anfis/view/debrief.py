"""The debrief model: a scored session (:class:`~haptic_anfis.exam.session.ExamSession` and its report)
as what the page shows at any time of a replay (no ROS, no viser).

Times on the scrubber are seconds from the session's first sample. Coverage at a time is exact to
one of ``bins`` steps: the contact samples are folded into a coverage grid in that many time
steps once, keeping the first time each face reached each level.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..cases.grading import DEEP_DEPTH
from ..exam.config import LEVELS
from ..exam.coverage import CoverageGrid
from .feel_again import feel_commands

__all__ = ['Debrief', 'LesionMarker', 'NormalMarker', 'lesion_status', 'lesion_why',
           'normal_markers', 'panel_numbers']


@dataclass(frozen=True)
class LesionMarker:
    """A lesion revealed: ``name``, ``centre`` (3,) [m], ``radius`` [m], ``surface`` (3,) [m]
    (its projection on the skin), ``status``: 'hit', 'missed' or 'below device', ``why``."""
    name: str
    centre: tuple
    radius: float
    surface: tuple
    status: str
    why: str


@dataclass(frozen=True)
class NormalMarker:
    """A normal structure revealed beside the lesions: ``name``, ``what`` ('a normal glandular
    lobule', 'a fat lobule', 'a rib'), ``kind`` ('nodule' / 'rib'), ``surface`` (3,) [m] (the
    skin over it), ``radius`` [m], ``line`` (k, 3) [m] (a rib's line on the skin; empty for a
    nodule), ``bump_pct`` (how much it stood out at deep pressure [%], None ungraded),
    ``status``: 'confounder' (it stands out as much as a lesion would) or 'normal', ``marked``
    (a false mark fell on it), ``label`` (what the page writes beside it; '' for an unmarked
    lobule that does not stand out: thirty labels would hide the breast)."""
    name: str
    what: str
    kind: str
    surface: tuple
    radius: float
    line: np.ndarray
    bump_pct: float | None
    status: str
    marked: bool
    label: str


def normal_markers(report: dict) -> list[NormalMarker]:
    """The report's normal background (``report['normal']``, :mod:`haptic_anfis.exam.normal`)
    as markers; [] for a smooth case or a report made before it; a region without a skin point,
    and a rib that does not cross the region to examine, are left out."""
    out = []
    for e in report.get('normal') or []:
        if e.get('surface_mm') is None or e['kind'] == 'rib' and len(e.get('line_mm') or ()) < 2:
            continue
        status = 'confounder' if e.get('confounder') else 'normal'
        bump = e.get('bump_pct')
        words = [e['what'].removeprefix('a ')]
        if bump is not None:
            words.append(f'{bump:+.0f} %')
        if e.get('marks'):
            words.append('false mark')
        show = status == 'confounder' or bool(e.get('marks')) or e['kind'] == 'rib'
        out.append(NormalMarker(
            e['name'], e['what'], e['kind'], tuple(np.array(e['surface_mm'], float) * 1e-3),
            e['radius_mm'] * 1e-3, np.array(e.get('line_mm') or [], float).reshape(-1, 3) * 1e-3,
            bump, status, bool(e.get('marks')),
            f"{e['name']}: {', '.join(words)}" if show else ''))
    return out


def lesion_status(entry: dict) -> str:
    """'hit', 'below device' (the case's grading says this device does not render it to a
    stylus: a report entry with ``palpable`` false) or 'missed'."""
    if entry.get('found'):
        return 'hit'
    if entry.get('palpable') is False:
        return 'below device'
    return 'missed'


def lesion_why(entry: dict) -> str:
    """What the debrief says of a lesion: why it was missed (or why it is not scored), the
    pressure level from which it can be felt, how much it stood out and its difficulty (from
    the case's FE grading, when graded), e.g. 'never palpated deep; palpable from medium
    pressure (5 mm); stood out 23 % at deep pressure; difficulty 3 of 5'."""
    if entry.get('palpable') is False:
        return '; '.join(v for v in (entry.get('missed'), entry.get('reason')) if v)
    parts = [entry.get('missed') or ('found' if entry.get('found') else '')]
    if entry.get('level'):
        parts.append(f"palpable from {entry['level']} pressure ({entry['level_depth_mm']:g} mm)")
    if entry.get('contrast_pct') is not None:   # how much there was to feel, in the FE
        at = entry.get('contrast_depth_mm')
        where = ('at deep pressure' if at is not None and abs(at - DEEP_DEPTH * 1e3) < 1e-3
                 else f'at {at:g} mm' if at is not None else '')
        parts.append(f"stood out {entry['contrast_pct']:.0f} % {where}".rstrip())
    if entry.get('difficulty') is not None:
        parts.append(f"difficulty {entry['difficulty']} of 5")
    return '; '.join(p for p in parts if p)


def panel_numbers(report: dict) -> dict:
    """The headline numbers the debrief panel shows, as the report has them (``exam report
    --json``): coverage per level [%], hits, misses, false marks, score, verdict, pattern,
    duration [s], time per pressure level and per area [s], force palpating / searching [N]."""
    return {'coverage_light_pct': report['coverage_pct']['light'],
            'coverage_medium_pct': report['coverage_pct']['medium'],
            'coverage_deep_pct': report['coverage_pct']['deep'],
            'hits': report['hits'], 'misses': report['misses'],
            'false_marks': report['false_marks'],
            # of them on a normal lobule or rib (None in a report made before the split)
            'false_marks_normal': report.get('false_marks_normal'),
            'score': report['score'],
            'verdict': report['verdict'], 'pattern': report['pattern'],
            'duration_s': report['duration_s'],
            # what predicts finding lumps (haptic_anfis.exam.effort; None in an older report)
            'time_at_level_s': report.get('time_at_level_s'),
            'area_time_s': report.get('area_time_s'),
            'force_palpating_n': report.get('force_palpating_n'),
            'force_searching_n': report.get('force_searching_n'),
            'palpating_vs_searching_pct': report.get('palpating_vs_searching_pct')}


class Debrief:
    """What the debrief shows of ``session`` with its ``report`` (``ExamSession.report()``).

    Args:
        bins: time steps of the replay's coverage (the scrubber's resolution for the heat map).
    """

    def __init__(self, report: dict, session, bins: int = 200) -> None:
        self.report, self.session = report, session
        c = np.array(session.contacts, float).reshape(-1, 6)
        c = c[np.argsort(c[:, 0], kind='stable')]
        times = [c[:, 0]] + [np.array(x, float).reshape(-1, 4)[:, 0]
                             for x in (session.poses, session.forces, session.marks)]
        allt = np.concatenate(times)
        self.t0 = float(allt.min()) if len(allt) else 0.0
        self.duration = float(allt.max() - self.t0) if len(allt) else 0.0
        self.contacts = c
        g = session.grid
        self._first = np.full((len(g.centroids), len(LEVELS)), np.inf)
        grid = CoverageGrid(g.vertices, g.faces, session.region_radius, g.footprint_radius,
                            g.thresholds)
        edges = np.linspace(self.t0, self.t0 + self.duration, max(int(bins), 1) + 1)
        # the samples are in time order: each bin is a slice [a, b), the last one closed
        cut = np.searchsorted(c[:, 0], edges, side='left')
        cut[-1] = len(c)
        for lo, hi, b in zip(cut[:-1], cut[1:], edges[1:]):
            part = c[lo:hi]
            part = part[part[:, 5] > 0.5]
            if len(part):
                before = grid.covered.copy()
                grid.add(part[:, 1:4], part[:, 4])
                new = grid.covered & ~before
                self._first[new] = b - self.t0
        self.lesions = [LesionMarker(e['name'], tuple(np.array(e['centre_mm']) * 1e-3),
                                     e['radius_mm'] * 1e-3, tuple(np.array(e['surface_mm']) * 1e-3),
                                     lesion_status(e), lesion_why(e))
                        for e in report['lesions']]
        self.normal = normal_markers(report)

    def face_levels(self, t: float | None = None) -> np.ndarray:
        """(m,) int 0..3: highest level per coverage face reached by ``t`` [s] (None = the end)."""
        t = self.duration if t is None else t
        return (self._first <= t + 1e-9).sum(axis=1)

    def path(self, t: float | None = None, step: float = 1e-3) -> np.ndarray:
        """(n, 3) [m]: the probe's contact points in contact up to ``t`` [s], thinned to points
        at least ``step`` [m] apart (NaN rows split the path where it left the skin)."""
        t = self.duration if t is None else t
        c = self.contacts
        c = c[c[:, 0] - self.t0 <= t + 1e-9]
        out, last, was_in = [], None, False
        for row in c:
            if row[5] <= 0.5 or not np.isfinite(row[1:4]).all():
                if was_in:
                    out.append((np.nan, np.nan, np.nan))
                was_in, last = False, None
                continue
            p = row[1:4]
            if last is None or np.linalg.norm(p - last) >= step:
                out.append(tuple(p))
                last = p
            was_in = True
        return np.array(out, float).reshape(-1, 3)

    def marks(self, t: float | None = None) -> list[tuple[np.ndarray, str]]:
        """Marks placed by ``t`` [s]: (surface point [m] (3,), result 'hit' / 'repeat' /
        'false'); marks without a surface point are left out."""
        t = self.duration if t is None else t
        out = []
        for (tm, *_), e in zip(self.session.marks, self.report['marks']):
            if tm - self.t0 <= t + 1e-9 and e.get('surface_mm') is not None:
                out.append((np.array(e['surface_mm'], float) * 1e-3, e['result']))
        return out

    def numbers(self) -> dict:
        return panel_numbers(self.report)

    def feel_again(self, directory: str | os.PathLike | None = None) -> dict[str, str]:
        """{lesion name: the command that presses it again with the simulated Falcon}
        (:mod:`.feel_again`) for each palpable lesion of a library case, its files written
        into ``directory`` (None: a folder of the temporary directory); none for a blind case
        (its name stays with the instructor) or a case not in the library."""
        case = self.report.get('case')
        if not case or case == 'blind case' or self.report.get('blind'):
            return {}
        return feel_commands(case, self.report['lesions'], self.session.config.thresholds,
                             directory)

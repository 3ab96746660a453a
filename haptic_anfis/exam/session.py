"""An examination session: samples in, report out (no ROS).

:class:`ExamSession` collects the streams the examiner node (or a bag) provides — contact samples,
force commands, probe poses, marks — and :meth:`ExamSession.report` turns them into the report
dict (coverage per level, pattern, timing, findings, score, verdict). Times in seconds, lengths in
metres inside; the report gives millimetres / percent at the edge, with the unit in each key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..contact import ContactDetector
from ..interfaces import I_DEPTH, I_IN_CONTACT, ContactLayouts
from ..rows import RowLog
from .config import LEVELS, ExamConfig
from .coverage import CoverageGrid
from .effort import effort
from .files import write_atomic
from .findings import match, project_marks
from .lesions import ExamSubject, lesion_surface_points
from .normal import normal_regions, specificity
from .pattern import classify


@dataclass
class Surface:
    """The skin: mesh vertices (v, 3) [m], faces (f, 3) and a contact detector on it (for
    projecting marks and lesions)."""
    vertices: np.ndarray
    faces: np.ndarray
    detector: object

    @classmethod
    def from_mesh(cls, mesh) -> 'Surface':
        return cls(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64),
                   ContactDetector(mesh, direction=(-1.0, 0.0, 0.0)))


class ExamSession:
    """Accumulates one session. ``add_*`` may be called from a ROS callback (one thread);
    :meth:`update_coverage` folds the new contact samples into the coverage grid (call it at a
    few Hz, it is vectorised). The samples are kept as float64 rows (:class:`~haptic_anfis.rows.
    RowLog`: ~170 MB for an hour of 1 kHz contact samples, where tuples took ~0.9 GB)."""

    def __init__(self, surface: Surface, subject: ExamSubject, config: ExamConfig):
        self.surface, self.subject, self.config = surface, subject, config
        region = config.region_radius or subject.palpable_radius
        self.region_radius = region
        self.grid = CoverageGrid(surface.vertices, surface.faces, region,
                                 config.footprint_radius, config.thresholds)
        self.contacts = RowLog(6)   # (t, x, y, z, depth, in_contact)
        self.forces = RowLog(4)     # (t, fx, fy, fz)
        self.poses = RowLog(4)      # (t, x, y, z)
        self.marks = RowLog(4, chunk=64)   # (t, x, y, z)
        self.contact_layouts = ContactLayouts()   # contact messages read / not read, by layout
        self.clutch_presses = 0
        self._buttons_prev: list[int] = []
        self._folded = 0

    def add_contact(self, t: float, point, depth: float, in_contact: bool) -> None:
        self.contacts.append((t, point[0], point[1], point[2], depth, 1.0 if in_contact else 0.0))

    def add_contact_values(self, t: float, v) -> bool:
        """A contact message's ``position`` values (current or older 9-value layout,
        :class:`~haptic_anfis.interfaces.ContactLayouts`); a message of any other length is
        counted (the report's ``contact_messages`` and a note) and not read. True when read."""
        if not self.contact_layouts.accept(v):
            return False
        self.add_contact(t, v[0:3], v[I_DEPTH], v[I_IN_CONTACT] > 0.5)
        return True

    def add_force(self, t: float, f) -> None:
        self.forces.append((t, f[0], f[1], f[2]))

    def add_pose(self, t: float, p) -> None:
        self.poses.append((t, p[0], p[1], p[2]))

    def add_mark(self, t: float, p) -> None:
        self.marks.append((t, p[0], p[1], p[2]))

    def add_buttons(self, t: float, buttons) -> None:
        """Device buttons (0/1 each); counts clutch (button 0) presses."""
        b = list(buttons)
        if b[:1] == [1] and self._buttons_prev[:1] != [1]:
            self.clutch_presses += 1
        self._buttons_prev = b

    #: the raw samples :meth:`save_samples` writes (name: columns)
    SAMPLES = {'contacts': 6, 'forces': 4, 'poses': 4, 'marks': 4}

    def save_samples(self, path) -> None:
        """The raw samples (contacts, forces, poses, marks; times in s, SI) to ``path``
        (``.npz``), for :meth:`load_samples` in another process (``exam run``'s examiner runs in
        one of its own; the debrief replays its samples)."""
        arrays = {k: np.array(getattr(self, k), float).reshape(-1, n)
                  for k, n in self.SAMPLES.items()}
        # whole or absent: the other process reads it as soon as the name exists
        write_atomic(path, lambda f: np.savez(f, **arrays))

    def load_samples(self, path) -> None:
        """Append the samples :meth:`save_samples` wrote and fold them into the coverage.

        Raises:
            ValueError: ``path`` is not such a file (the message names it).
        """
        try:
            with np.load(path) as z:
                arrays = {k: np.asarray(z[k], float).reshape(-1, n)
                          for k, n in self.SAMPLES.items()}
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f'{path}: not a samples file of an exam session ({exc})') from None
        for k, a in arrays.items():
            getattr(self, k).extend(a)
        self.update_coverage()

    def update_coverage(self) -> None:
        n = len(self.contacts)
        if n > self._folded:
            c = self.contacts.array(self._folded, n)
            self._folded = n
            inside = c[:, 5] > 0.5
            self.grid.add(c[inside, 1:4], c[inside, 4])

    # -- the report -------------------------------------------------------------------------------
    def report(self) -> dict:
        """The report dict (JSON-able). Valid for any input, including no samples at all."""
        self.update_coverage()
        cfg = self.config
        c = np.array(self.contacts, float).reshape(-1, 6)
        c = c[np.argsort(c[:, 0], kind='stable')]   # callbacks / bag order: by stamp
        p = np.array(self.poses, float).reshape(-1, 4)
        f = np.array(self.forces, float).reshape(-1, 4)
        times = np.concatenate([c[:, 0], p[:, 0], f[:, 0], [m[0] for m in self.marks]])
        duration = float(times.max() - times.min()) if len(times) else 0.0
        notes = []
        inside = c[:, 5] > 0.5 if len(c) else np.zeros(0, bool)
        layout_note = self.contact_layouts.note()
        if layout_note:
            notes.append(layout_note)
        if len(c) == 0:
            notes.append('no contact samples: nothing was palpated')
        elif not inside.any():
            notes.append('the probe never touched the tissue: zero coverage')
        dt = np.clip(np.diff(c[:, 0]), 0.0, 0.05) if len(c) > 1 else np.zeros(0)
        contact_s = float(dt[inside[:-1]].sum()) if len(dt) else 0.0
        path = p[:, 1:4] if len(p) else c[:, 1:4]
        path_len = _path_length(path)
        seg = np.cumsum(np.r_[0, np.diff(inside.astype(int)) != 0]) if len(c) else np.zeros(0)
        pat = classify(c[inside, 2:4], seg[inside], cfg.footprint_radius, t=c[inside, 0])
        cov = self.grid.fraction()
        # depth and force per level (force samples matched to contact samples by time)
        depth_max = float(c[inside, 4].max()) if inside.any() else 0.0
        fn = np.linalg.norm(f[:, 1:4], axis=1) if len(f) else np.zeros(0)
        lesions = self.subject.lesions
        lpts = lesion_surface_points(self.surface.detector, lesions)
        deep = [self.grid.pressed_near(lp, les.radius, LEVELS.index('deep'))
                for les, lp in zip(lesions, lpts)]
        mk = np.array([m[1:] for m in self.marks], float).reshape(-1, 3)
        mpts, invalid = project_marks(self.surface.detector, mk, cfg.mark_tolerance)
        fin = match(lesions, lpts, mpts, invalid, cfg.hit_margin, deep,
                    getattr(self.subject, 'background', None))
        bg_grading = getattr(self.subject, 'background_grading', None)
        normal = normal_regions(self.surface.detector, getattr(self.subject, 'background', None),
                                bg_grading, fin['marks'], self.region_radius)
        if not lesions:
            notes.append('the case has no lesion: every mark is a false mark')
        for m in fin['marks']:
            if m.get('reason') and 'outside the surface' in m['reason']:
                notes.append(f"mark {m['index']}: {m['reason']}")
        if any(not les.palpable for les in lesions):
            notes.append('below what this device renders (the FE contrast is under the '
                         'stiffness a stylus can tell apart; not scored): '
                         + ', '.join(les.name for les in lesions if not les.palpable))
        score, parts = score_of(cov, fin, pat['pattern'], fin['palpable_lesions'], cfg)
        verdict, reasons = verdict_of(cov, fin, cfg)
        eff = effort(c, f[np.argsort(f[:, 0], kind='stable')], cfg.thresholds,
                     cfg.footprint_radius)
        return {
            **eff,
            'coverage_pct': {k: round(100 * v, 2) for k, v in cov.items()},
            'duration_s': round(duration, 3), 'contact_s': round(contact_s, 3),
            'path_length_m': round(path_len, 4),
            'max_depth_mm': round(depth_max * 1e3, 2),
            'max_force_n': round(float(fn.max()), 3) if len(fn) else 0.0,
            'hits': fin['hits'], 'misses': fin['misses'], 'false_marks': fin['false_marks'],
            'false_marks_normal': fin['false_marks_normal'],
            'false_marks_elsewhere': fin['false_marks'] - fin['false_marks_normal'],
            'specificity': specificity(fin, normal, bg_grading),
            'normal': normal,
            'score': round(score, 2), 'score_parts': parts, 'verdict': verdict,
            'feedback': reasons, 'pattern': pat['pattern'], 'pattern_detail': pat,
            'marks': fin['marks'], 'lesions': fin['lesions'],
            'levels_mm': {k: v * 1e3 for k, v in zip(LEVELS, cfg.thresholds)},
            'region_radius_mm': round(self.region_radius * 1e3, 2),
            'region_faces': int(len(self.grid.centroids)),
            'clutch_presses': self.clutch_presses,
            'samples': {'contact': len(c), 'force': len(f), 'pose': len(p),
                        'marks': len(self.marks)},
            'contact_messages': self.contact_layouts.as_dict(),
            'case_source': self.subject.source, 'notes': notes,
        }


def _path_length(xyz: np.ndarray, min_step: float = 5e-4) -> float:
    """Length [m] of the path through points at least ``min_step`` apart (so sensor jitter does
    not add length)."""
    xyz = xyz[np.isfinite(xyz).all(axis=1)] if len(xyz) else xyz
    if len(xyz) < 2:
        return 0.0
    total, last = 0.0, xyz[0]
    for q in xyz[1:]:
        d = math.dist(q, last)
        if d >= min_step:
            total += d
            last = q
    return total


PATTERN_CREDIT = {'vertical_strip': 1.0, 'spiral_circular': 0.5, 'radial': 0.5}


def score_of(cov: dict, fin: dict, pattern: str, n_lesions: int, cfg: ExamConfig):
    """Score in [0, 100] (formula in config/exam.yaml and the README) and its parts."""
    c = 0.5 * cov['deep'] + 0.25 * cov['medium'] + 0.25 * cov['light']
    find = fin['hits'] / n_lesions if n_lesions else 1.0
    pc = PATTERN_CREDIT.get(pattern, 0.0)
    parts = {'coverage': round(100 * cfg.w_coverage * c, 2),
             'findings': round(100 * cfg.w_findings * find, 2),
             'pattern': round(100 * cfg.w_pattern * pc, 2),
             'false_marks': -round(cfg.false_mark_penalty * fin['false_marks'], 2)}
    return min(max(sum(parts.values()), 0.0), 100.0), parts


def false_marks_text(fin: dict) -> str:
    """'3 false mark(s): 2 on normal tissue, not a lesion: a rib (rib2), a normal glandular
    lobule (nodule4); 1 elsewhere' (split only when a mark fell on a normal structure)."""
    n, marks = fin['false_marks'], fin['marks']
    on = [m for m in marks if m.get('normal')]
    if not on:
        return f'{n} false mark(s)'
    what = ', '.join(m['reason'].removeprefix('no lesion here: ') for m in on)
    return (f'{n} false mark(s): {len(on)} on normal tissue, not a lesion: {what}'
            + (f'; {n - len(on)} elsewhere' if n > len(on) else ''))


def verdict_of(cov: dict, fin: dict, cfg: ExamConfig) -> tuple[str, list[str]]:
    """'pass' or 'retry', and the feedback lines that explain it."""
    why = []
    if cov['deep'] < cfg.pass_deep_coverage:
        why.append(f"deep coverage {100 * cov['deep']:.0f} % < {100 * cfg.pass_deep_coverage:.0f} %:"
                   ' press to the chest wall over the whole breast')
    for les in fin['lesions']:
        if not les['found'] and les.get('palpable', True):
            if les['palpated_deep']:
                why.append(f"lesion {les['name']} missed although palpated deep: you pressed over "
                           'it; compare each spot with its neighbours')
            else:
                why.append(f"lesion {les['name']} missed, never palpated deep there: cover that "
                           'area at deep pressure')
    if fin['false_marks']:
        why.append(false_marks_text(fin))
    return ('retry' if why else 'pass'), why

"""Tissue force -> device force for a case: one linear scale that keeps every force ratio and
never reaches the device's clamp within the FE's trained range.

The Falcon renders at most ``max_force`` (8.9 N, :data:`~haptic_anfis.device.falcon.RATED_FORCE`);
a dense breast pushes back with 15-26 N at the FE's deepest depth (16 mm). Rendered one to one, a
deep press there is a flat 8.9 N over the lesion and beside it: the contrast that finds a deep
lump is cut off at the pressure that finds it. A linear scale ``F_device = s * F_tissue`` keeps
every ratio, so a relative (Weber) contrast survives it; a clamp does not.

**One scale per case, not one for the library.** The scale is chosen so that the case's largest
FE force over its palpable disc at its deepest trained depth lands at ``HEADROOM`` of the clamp.
One library-wide scale would be set by the stiffest case (lib_m_dense_idc25_d15: 25.9 N at 16 mm,
s = 0.29) and would render the breasts' deep level (8 mm) at 1.1-2.0 N, and a fatty breast's
light level at 0.3 N: below the 2.5-10 N over which force discrimination keeps its ~7 % Weber
fraction (Pang, Tan & Durlach 1991), where the JND grows. Per case the deep level lands at
1.7-3.3 N and every case's deepest trained press at ``HEADROOM`` of the clamp
(docs/measurements/force_mapping.md, bench/bench_force_mapping.py). What is lost is
the absolute stiffness between cases (a fatty breast does not feel softer than a dense one);
the lesson is the lump against its own breast, which a per-case scale keeps whole. The exam's
levels stay in tissue depth and the gauge shows the tissue force (the driver divides by the
scale), so nothing the trainee is scored on changes with it.

Pure Python, no ROS.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..device.falcon import RATED_FORCE
from ..tissue.dataset import load_dataset
from .library import DEFAULT_CASE, Case, CaseError, library

__all__ = ['HEADROOM', 'ForceMapping', 'fe_peak_force', 'mapping_for', 'case_force_mapping',
           'tissue_clamp']

#: the fraction of the clamp the case's largest trained FE force is mapped to: the rest is room
#: for the force model's error, the local model's linear step between two updates and the hand's
#: overshoot, so that no tick within the trained depth reaches the clamp
HEADROOM = 0.85


@dataclass(frozen=True)
class ForceMapping:
    """How a case's tissue forces reach the device: ``F_device = force_scale * F_tissue``.

    Attributes:
        case: the case's name.
        force_scale: the scale (dimensionless, > 0).
        fe_peak_n: the largest FE |F| [N] over the palpable disc at ``depth_m``.
        depth_m: the FE's deepest trained depth [m].
        max_force_n: the device's clamp [N] the scale was chosen against.
        headroom: the fraction of the clamp ``fe_peak_n`` is mapped to.
    """

    case: str
    force_scale: float
    fe_peak_n: float
    depth_m: float
    max_force_n: float
    headroom: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def text(self) -> str:
        """'x0.43 (17.6 N at 16 mm -> 7.6 N of 8.9 N)'."""
        return (f'x{self.force_scale:.3f} ({self.fe_peak_n:.1f} N at {self.depth_m * 1e3:g} mm '
                f'-> {self.force_scale * self.fe_peak_n:.1f} N of {self.max_force_n:g} N)')


def fe_peak_force(X: np.ndarray, Y: np.ndarray, palpable_radius: float) -> tuple[float, float]:
    """(largest |F| [N], depth [m]) of a force dataset over the palpable disc at its deepest
    depth. ``X`` (n, 4): x, y, z [m], depth [m]; ``Y`` (n, 3) [N]; ``palpable_radius`` [m] from
    the nipple axis (y, z).

    Raises:
        ValueError: no sample lies within the palpable radius at that depth.
    """
    X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
    deepest = float(X[:, 3].max())
    sel = (np.abs(X[:, 3] - deepest) < 1e-9) & (np.hypot(X[:, 1], X[:, 2])
                                                <= palpable_radius + 1e-9)
    if not sel.any():
        raise ValueError(f'no FE sample within the palpable radius {palpable_radius * 1e3:g} mm '
                         f'at the deepest depth {deepest * 1e3:g} mm')
    return float(np.linalg.norm(Y[sel], axis=1).max()), deepest


def mapping_for(name: str, fe_peak_n: float, depth_m: float, max_force: float = RATED_FORCE,
                headroom: float = HEADROOM) -> ForceMapping:
    """The mapping that puts ``fe_peak_n`` [N] at ``headroom`` of ``max_force`` [N]; never above
    1 (a case that fits the device as it is is rendered one to one)."""
    if not (np.isfinite(fe_peak_n) and fe_peak_n > 0):
        raise ValueError(f'case {name!r}: FE peak force: expected a finite number > 0 N, got '
                         f'{fe_peak_n!r}')
    if not (np.isfinite(max_force) and max_force > 0):
        raise ValueError(f'max_force: expected a finite number > 0 N, got {max_force!r}')
    if not 0 < headroom <= 1:
        raise ValueError(f'headroom: expected a fraction in (0, 1], got {headroom!r}')
    s = min(1.0, headroom * max_force / fe_peak_n)
    return ForceMapping(name, float(s), float(fe_peak_n), float(depth_m), float(max_force),
                        float(headroom))


@lru_cache(maxsize=64)
def _peak(dataset_path: str, mtime_ns: int, palpable_radius: float) -> tuple[float, float]:
    """:func:`fe_peak_force` of a dataset file (cached by path and modification time)."""
    ds = load_dataset(dataset_path)
    return fe_peak_force(ds.X, ds.Y, palpable_radius)


def case_force_mapping(case: Case, max_force: float = RATED_FORCE,
                       headroom: float = HEADROOM) -> ForceMapping:
    """The :class:`ForceMapping` of a :class:`~haptic_anfis.cases.library.Case` from its shipped
    FE dataset (the default case: the package's default dataset).

    Raises:
        CaseError: the case has no dataset yet.
    """
    path = Path(case.dataset_path)
    if not path.is_file():
        raise CaseError(f'case {case.name!r}: no FE dataset {str(path)!r} to choose its force '
                        f'scale from; make it with `haptic-anfis cases generate {case.name}`')
    peak, depth = _peak(str(path), path.stat().st_mtime_ns, float(case.scene.palpable_radius))
    return mapping_for(case.name, peak, depth, max_force, headroom)


def tissue_clamp(case: Case | None, max_force: float = RATED_FORCE) -> float:
    """The tissue force [N] at which the device clamps in a session of ``case`` (None: the
    default case): ``max_force`` over the case's force scale (what sessions give the driver).
    A gauge that shows tissue force says "beyond the device's force" there; ``max_force`` itself
    where the case has no dataset to scale from."""
    try:
        c = case if case is not None else library().get(DEFAULT_CASE)
        return max_force / case_force_mapping(c, max_force).force_scale
    except (CaseError, ValueError, OSError):
        return max_force

"""Force models assembled by hand from triangular Sugeno parameters (tests only)."""
from __future__ import annotations

import numpy as np

from haptic_anfis.anfis import ANFIS, ForceModel, SugenoModel


def estimator_of(m: SugenoModel) -> ANFIS:
    """The triangular ANFIS with exactly ``m``'s MFs, consequents, range and extrapolation."""
    return ANFIS.from_params(mf='triangular', mf_params=m.mfs, consequents=m.coef,
                             input_min=m.lo, input_max=m.hi, extrapolation=m.extrapolation)


def assemble(models: list[SugenoModel], cols: tuple[int, ...] = (0, 1, 2, 3),
             scale_col: int = -1) -> ForceModel:
    """A compiled ForceModel whose three outputs are ``models`` over query columns ``cols``."""
    fm = ForceModel()
    fm.estimators_ = [estimator_of(m) for m in models]
    fm._input_cols, fm._scale_col = tuple(cols), scale_col
    lo, hi = np.full(4, np.inf), np.full(4, -np.inf)
    for c, a, b in zip(cols, models[0].lo, models[0].hi):
        lo[c], hi[c] = a, b
    if scale_col >= 0 and not np.isfinite(lo[scale_col]):
        lo[scale_col], hi[scale_col] = 0.0, 1.0
    lo[~np.isfinite(lo)], hi[~np.isfinite(hi)] = 0.0, 1.0
    fm._range = (lo, hi)
    fm._compile()
    return fm

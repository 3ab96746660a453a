"""Force datasets: samples of (contact point x, y, z; penetration depth) -> (Fx, Fy, Fz).

A dataset is a CSV file with a header naming each column and its unit::

    point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N

``point`` identifies the surface point a sample was indented at (every depth of one point shares it),
so a train/test split can hold out whole surface points. A JSON sidecar ``<name>.json`` next to the
CSV records provenance (how the data was made). SI units throughout.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from ..errors import HapticAnfisError

INPUT_COLUMNS = ('x_m', 'y_m', 'z_m', 'depth_m')
OUTPUT_COLUMNS = ('fx_N', 'fy_N', 'fz_N')
COLUMNS = ('point', *INPUT_COLUMNS, *OUTPUT_COLUMNS)
INPUT_NAMES = ('x', 'y', 'z', 'depth')
OUTPUT_NAMES = ('Fx', 'Fy', 'Fz')

from ..resources import DATA_DIR  # noqa: E402  (haptic_anfis/data, package data)
DEFAULT_DATASET = DATA_DIR / 'default_forces.csv'


class DatasetError(HapticAnfisError, ValueError):
    """A dataset file is missing, malformed or holds non-finite numbers."""


@dataclass
class ForceDataset:
    """Force samples in SI units.

    Attributes:
        X: (n, 4) inputs: contact point x, y, z on the undeformed surface [m], depth [m].
        Y: (n, 3) reaction force on the probe Fx, Fy, Fz [N].
        point: (n,) integer id of the surface point each sample belongs to.
        provenance: free-form metadata (from the JSON sidecar, if any).
    """

    X: np.ndarray
    Y: np.ndarray
    point: np.ndarray
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.X = np.ascontiguousarray(self.X, dtype=np.float64)
        self.Y = np.ascontiguousarray(self.Y, dtype=np.float64)
        self.point = np.asarray(self.point, dtype=np.int64)
        n = len(self.X)
        if self.X.shape != (n, 4) or self.Y.shape != (n, 3) or self.point.shape != (n,):
            raise DatasetError(
                f'dataset arrays have shapes X{self.X.shape}, Y{self.Y.shape}, point{self.point.shape}; '
                'expected (n, 4), (n, 3), (n,)')
        if n == 0:
            raise DatasetError('dataset has no samples')
        for name, arr, cols in (('input', self.X, INPUT_COLUMNS), ('output', self.Y, OUTPUT_COLUMNS)):
            bad = ~np.isfinite(arr)
            if bad.any():
                row, col = np.argwhere(bad)[0]
                raise DatasetError(f'non-finite {name} value {float(arr[row, col])} in column '
                                   f'{cols[col]!r}, sample {row} (0-based)')

    def __len__(self) -> int:
        return len(self.X)

    def sha256(self) -> str:
        """Hash of the numbers (not the file formatting), to tie a model to its data."""
        h = hashlib.sha256()
        for arr in (self.point, self.X, self.Y):
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()

    def subset(self, index: np.ndarray) -> 'ForceDataset':
        return ForceDataset(self.X[index], self.Y[index], self.point[index], dict(self.provenance))


def sidecar_path(csv_path: str | os.PathLike) -> Path:
    return Path(csv_path).with_suffix('.json')


def load_dataset(path: str | os.PathLike = DEFAULT_DATASET) -> ForceDataset:
    """Read a force dataset CSV (and its JSON sidecar, if present).

    Raises:
        DatasetError: missing file, missing columns, unparsable or non-finite numbers.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f'dataset file {str(path)!r} does not exist')
    with path.open(newline='') as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise DatasetError(f'dataset file {str(path)!r} is empty; expected a header '
                               f'{",".join(COLUMNS)}') from None
        missing = [c for c in COLUMNS if c not in header]
        if missing:
            raise DatasetError(f'dataset file {str(path)!r} lacks column(s) {missing}; '
                               f'expected a header with {",".join(COLUMNS)}')
        idx = [header.index(c) for c in COLUMNS]
        rows = []
        for lineno, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            try:
                values = [float(row[i]) for i in idx]
            except (ValueError, IndexError):
                raise DatasetError(f'{path}:{lineno}: cannot read row {row!r} as numbers') from None
            bad = [c for c, v in zip(COLUMNS, values) if not math.isfinite(v)]
            if bad:
                raise DatasetError(f'{path}:{lineno}: non-finite value in column(s) {bad} '
                                   f'(row {row!r}); every number must be finite')
            rows.append(values)
    if not rows:
        raise DatasetError(f'dataset file {str(path)!r} has a header but no samples')
    data = np.array(rows, dtype=np.float64)
    provenance: dict[str, Any] = {}
    side = sidecar_path(path)
    if side.is_file():
        try:
            provenance = json.loads(side.read_text())
        except json.JSONDecodeError as exc:
            raise DatasetError(f'provenance sidecar {str(side)!r} is not valid JSON: {exc}') from None
    point = data[:, 0]
    if np.any(point != np.round(point)):
        raise DatasetError(f'dataset file {str(path)!r}: column "point" must hold integers')
    return ForceDataset(X=data[:, 1:5], Y=data[:, 5:8], point=point.astype(np.int64),
                        provenance=provenance)


def save_dataset(ds: ForceDataset, path: str | os.PathLike) -> Path:
    """Write ``ds`` as CSV (full float precision) plus its JSON sidecar, each atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + '.tmp')
    with tmp.open('w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for p, x, y in zip(ds.point, ds.X, ds.Y):
            w.writerow([int(p), *(repr(float(v)) for v in x), *(repr(float(v)) for v in y)])
    os.replace(tmp, path)
    side = sidecar_path(path)
    tmp = side.with_name(side.name + '.tmp')
    tmp.write_text(json.dumps({**ds.provenance, 'sha256': ds.sha256()}, indent=2) + '\n')
    os.replace(tmp, side)
    return path


def fold_indices(ds: ForceDataset, k: int, seed: int, by: str = 'point'
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``k`` random (keep, held_out) index pairs whose held-out parts partition the data; whole
    surface points stay together with ``by='point'`` (as in :func:`split_indices`)."""
    if by not in ('point', 'sample'):
        raise ValueError(f"split 'by' must be 'point' or 'sample', got {by!r}")
    groups = ds.point if by == 'point' else np.arange(len(ds))
    units = np.unique(groups)
    if not 2 <= k <= len(units):
        raise ValueError(f'need 2 <= folds <= {len(units)} ({"points" if by == "point" else "samples"}'
                         f'), got {k!r}')
    order = np.random.default_rng(seed).permutation(units)
    out = []
    for part in np.array_split(order, k):
        held = np.isin(groups, part)
        out.append((np.flatnonzero(~held), np.flatnonzero(held)))
    return out


def split_indices(ds: ForceDataset, fraction: float, seed: int, by: str = 'point'
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Random split into (keep, held_out) index arrays, ``fraction`` of the data held out.

    ``by='point'`` holds out whole surface points (all their depths): the held-out error then
    measures what the haptic loop needs, forces at places the model never saw. ``by='sample'``
    splits samples independently, as a plain random 80/20 split would.
    """
    if not 0.0 < fraction < 1.0:
        raise ValueError(f'split fraction must be in (0, 1), got {fraction!r}')
    rng = np.random.default_rng(seed)
    if by == 'sample':
        order = rng.permutation(len(ds))
        n_out = max(1, int(round(fraction * len(ds))))
        return np.sort(order[n_out:]), np.sort(order[:n_out])
    if by != 'point':
        raise ValueError(f"split 'by' must be 'point' or 'sample', got {by!r}")
    points = np.unique(ds.point)
    if len(points) < 2:
        raise ValueError('cannot split by point: the dataset has fewer than two surface points')
    order = rng.permutation(points)
    n_out = min(len(points) - 1, max(1, int(round(fraction * len(points)))))
    held = np.isin(ds.point, order[:n_out])
    return np.flatnonzero(~held), np.flatnonzero(held)

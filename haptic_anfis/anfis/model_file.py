"""The versioned force-model file (JSON): read, validate, write atomically.

JSON keeps the file readable and diffable, and Python's float repr round-trips every float64 bit
for bit, so save -> load is exact. Layout (``format_version`` 3)::

    {"format": "haptic_anfis.force_model", "format_version": 3,
     "form": {"name": "depth_scaled", "inputs": ["y", "z", "depth"], "scale": "depth"},
     "software_version": "...", "created_utc": "...",
     "inputs":  [{"name": "x", "unit": "m", "min": .., "max": ..}, ...],
     "outputs": [{"name": "Fx", "unit": "N", "mf": "triangular",
                  "structure": [5, 5, 3],                             # per ANFIS input
                  "membership": [[[a, b, c], ...] per ANFIS input],   # metres
                  "consequents": [[p_y, p_z, p_depth, q] per rule],  # N/m² and N/m if scaled
                  "extrapolation": [0, 0.15, 0.15], "best_epoch": .., "rmse": {..}}, ...],
     "dataset": {"sha256": "...", "path": "...", "n_samples": ..},
     "training": {...}}

Each output is an :class:`~.estimator.ANFIS`: "mf" names its MF family (:mod:`.families`' rows,
in input units), whose MFs are free within their ordering constraint. The "form" says which of
(x, y, z, depth) the estimators read and whether the output is multiplied by the depth
(F = depth · g(inputs): zero force at contact).

Older versions still load, migrated exactly: version 2 (the same layout without "mf": triangular
MFs on the pinned partition, every outer peak on its domain edge and every foot on a neighbouring
peak, checked as such) is a triangular estimator with those MFs; version 1 (no "form":
F = ANFIS(x, y, z, depth)) is that plain form. A newer or unknown version fails with one line
naming the file.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .estimator import ANFIS, ANFISInputError
from .families import FAMILIES
from .sugeno import SugenoModel
from ..errors import HapticAnfisError

FORMAT = 'haptic_anfis.force_model'
FORMAT_VERSION = 3
#: Versions this software reads (1: the plain four-input form, before "form" existed; 2: the
#: triangular pinned partition, before "mf" existed).
READABLE_VERSIONS = (1, 2, 3)
#: Largest |min|, |max| of an input [m] a model file may declare: a tissue model spans centimetres,
#: so anything past this is a unit mistake (millimetres written as metres) or garbage.
MAX_ABS_INPUT_M = 1.0


class ModelFileError(HapticAnfisError, ValueError):
    """A model file is missing, of another format or version, malformed, or non-finite."""


def _no_constants(name: str) -> float:
    raise ValueError(f'non-finite number {name!r}')


def estimator_to_dict(est: ANFIS) -> dict[str, Any]:
    """One output's entry (format version 3) from a fitted estimator, in input units."""
    d = est.n_features_in_
    return {
        'mf': est.mf,
        'structure': [len(P) for P in est.mf_params_],
        'membership': [P.tolist() for P in est.mf_params_],
        'consequents': est.consequents_.tolist(),
        'extrapolation': [float(v) for v in np.broadcast_to(
            np.asarray(est.extrapolation, dtype=np.float64), (d,))],
    }


def _entry_arrays(entry: dict[str, Any], n_inputs: int, name: str
                  ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """(MF rows per input, consequents, extrapolation) of an output entry, shapes checked."""
    try:
        mfs = [np.array(P, dtype=np.float64) for P in entry['membership']]
        coef = np.array(entry['consequents'], dtype=np.float64)
        extrapolation = np.array(entry['extrapolation'], dtype=np.float64)
        structure = tuple(int(m) for m in entry['structure'])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(f'output {name}: malformed entry ({exc!r})') from None
    if extrapolation.shape != (n_inputs,) or not np.all(np.isfinite(extrapolation)) \
            or not np.all(extrapolation >= 0):
        raise ModelFileError(f'output {name}: "extrapolation" needs {n_inputs} numbers '
                             '(finite, >= 0)')
    if len(mfs) != n_inputs:
        raise ModelFileError(f'output {name}: {len(mfs)} membership lists for {n_inputs} inputs')
    if structure != tuple(len(P) for P in mfs):
        raise ModelFileError(f'output {name}: structure {structure} does not match its membership '
                             f'functions {tuple(len(P) for P in mfs)}')
    return mfs, coef, extrapolation


def estimator_from_dict(entry: dict[str, Any], lo: np.ndarray, hi: np.ndarray, name: str,
                        version: int) -> ANFIS:
    """One output's estimator from its entry; ``lo``/``hi``: its inputs' range. Versions 1 and 2
    (triangular, pinned partition) are checked against their own constraints, then migrated."""
    family = 'triangular' if version < 3 else entry.get('mf')
    if family not in FAMILIES:
        raise ModelFileError(f'output {name}: "mf" is {family!r}; expected one of '
                             f'{sorted(FAMILIES)}')
    mfs, coef, extrapolation = _entry_arrays(entry, len(lo), name)
    if version < 3:
        m = SugenoModel(mfs=mfs, coef=coef, lo=lo, hi=hi, extrapolation=extrapolation)
        try:
            m.validate(name=f'output {name}')
        except ValueError as exc:
            raise ModelFileError(str(exc)) from None
    try:
        return ANFIS.from_params(mf=family, mf_params=mfs, consequents=coef, input_min=lo,
                                 input_max=hi, extrapolation=extrapolation)
    except ANFISInputError as exc:
        raise ModelFileError(f'output {name}: {exc}') from None


def write_json_atomic(path: str | os.PathLike, doc: dict[str, Any]) -> Path:
    """Write ``doc`` to ``path`` via a temporary file and rename: readers never see half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    text = json.dumps(doc, indent=1, allow_nan=False)
    with tmp.open('w') as fh:
        fh.write(text + '\n')
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


def read_model_doc(path: str | os.PathLike) -> dict[str, Any]:
    """Read and check the envelope of a model file (format, version, inputs, outputs)."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f'model file {str(path)!r} does not exist')
    try:
        doc = json.loads(path.read_text(), parse_constant=_no_constants)
    except (json.JSONDecodeError, UnicodeDecodeError, ValueError) as exc:
        raise ModelFileError(f'model file {str(path)!r} is not a valid model file: {exc}') from None
    if not isinstance(doc, dict) or doc.get('format') != FORMAT:
        raise ModelFileError(f'{str(path)!r} is not a haptic_anfis force-model file '
                             f'(expected "format": "{FORMAT}")')
    version = doc.get('format_version')
    if isinstance(version, int) and not isinstance(version, bool) and version > FORMAT_VERSION:
        raise ModelFileError(f'model file {str(path)!r} has format_version {version}, newer than '
                             f'this software reads (up to {FORMAT_VERSION}): update haptic_anfis '
                             'or retrain with "haptic-anfis train"')
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise ModelFileError(f'model file {str(path)!r} has format_version {version!r}; this '
                             f'software reads versions {list(READABLE_VERSIONS)} (retrain with '
                             '"haptic-anfis train")')
    for key in ('inputs', 'outputs'):
        if not isinstance(doc.get(key), list) or not doc[key]:
            raise ModelFileError(f'model file {str(path)!r}: "{key}" must be a non-empty list')
    for inp in doc['inputs']:
        try:
            lo, hi = float(inp['min']), float(inp['max'])
        except (KeyError, TypeError, ValueError):
            raise ModelFileError(f'model file {str(path)!r}: every input needs numeric '
                                 '"min" and "max"') from None
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ModelFileError(f'model file {str(path)!r}: input {inp.get("name")!r} has '
                                 f'range [{lo}, {hi}]; expected finite min < max')
        if max(abs(lo), abs(hi)) > MAX_ABS_INPUT_M:
            raise ModelFileError(f'model file {str(path)!r}: input {inp.get("name")!r} has range '
                                 f'[{lo}, {hi}] m; expected metres within ±{MAX_ABS_INPUT_M} m '
                                 '(a file in millimetres?)')
    return doc

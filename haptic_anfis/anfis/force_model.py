"""``ForceModel``: three triangular :class:`~.estimator.ANFIS` estimators (Fx, Fy, Fz) over
(x, y, z, depth).

Scikit-learn conventions without the dependency: keyword-only hyper-parameters in ``__init__``,
``fit`` returns ``self``, learned attributes end in ``_`` (``estimators_``: the three ANFIS).
Inputs in metres, forces in newtons. Three ways to evaluate, all compiled (numba):

    model = ForceModel().fit(X, Y, groups=point_ids)  # the shipped configuration (defaults.SHIPPED)
    F = model.predict(X)                              # (n, 3) batch; jacobian=True adds (n, 3, 4)
    fx, fy, fz = model.predict_one(x, y, z, depth)    # real-time single query (~1 µs)
    F, J = model.jacobian_one(x, y, z, depth)         # real-time forces and Jacobian
    model.save('model.json'); model = ForceModel.load('model.json')

Each estimator's MFs are free to widen and move within their ordering constraint
(:mod:`.families`), and learning is its guarded hybrid rule (:mod:`.hybrid`): a step that raises
the training error is refused.
"""
from __future__ import annotations

import datetime as _dt
import os
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._version import __version__
from ..tissue.dataset import (INPUT_NAMES, OUTPUT_NAMES, DatasetError, ForceDataset, fold_indices,
                       split_indices)
from . import compiled
from .defaults import (AUTO, LEGACY_RIDGE, SHIPPED, SHIPPED_INPUTS, SHIPPED_STRUCTURE, X_MFS,
                       x_explained_by_yz)
from .estimator import ANFIS
from .model_file import (FORMAT, FORMAT_VERSION, MAX_ABS_INPUT_M, ModelFileError,
                         estimator_from_dict, estimator_to_dict, read_model_doc,
                         write_json_atomic)
from .structure import Candidate, SearchResult, search_structure
from .sugeno import DEFAULT_EXTRAPOLATION, DEFAULT_EXTRAPOLATION_SCALED, check_finite_inputs
from .training import TrainResult

INPUT_UNITS = ('m', 'm', 'm', 'm')
OUTPUT_UNITS = ('N', 'N', 'N')

Structure = tuple[int, ...]

#: Model forms: the paper's F = ANFIS(inputs), and F = depth · ANFIS(inputs) (zero at contact).
FORMS = ('plain', 'depth_scaled')


class ForceModel:
    """Soft-tissue force model: (x, y, z, depth) [m] -> (Fx, Fy, Fz) [N].

    The defaults are the shipped configuration (:data:`~.defaults.SHIPPED`, the same values as
    config/force_model.yaml): ``ForceModel().fit`` trains the model the force server ships.

    Args:
        structure: ``'auto'`` (default): the shipped per-output structures 6-6-2 / 6-6-2 / 5-5-2
            when the ANFIS inputs are (y, z, depth) and no ``candidates`` are given, else the
            structure search; ``None`` to choose MF counts per output by validation (see
            :func:`~.structure.search_structure`); one tuple (e.g. ``(3, 3, 3, 2)``) for all three
            outputs; or a sequence of three tuples, one per output.
        epochs: hybrid-learning epochs of the final models: one count for all outputs, or three
            (one per output: Fz, with its stronger shrinkage, keeps improving longer).
        search_epochs: maximum epochs per candidate during the structure search.
        search_start, max_mfs, candidates, tol: structure search settings.
        ridge: relative ridge weight of the consequent least squares, which shrinks every rule
            toward one global linear fit (the estimators' ``ridge_target='linear'``): one for
            all outputs, or three (one per output, e.g. a trained model's ``ridges_``).
        ridge_candidates: ridge weights the structure search scores every structure with
            (chosen per output with the structure, :func:`~.structure.search_structure`); None:
            ``ridge`` only. The chosen ones are ``ridges_``.
        step: initial gradient step (fraction of an input's range).
        val_fraction: part of the training data held out to choose the epoch count (and the
            structure when ``search_folds`` is 1); 0 = no hold-out: train ``epochs`` epochs on
            all the data and keep the lowest-training-error one.
        search_folds: k > 1 scores each structure candidate by k-fold validation over the
            training data (whole surface points per fold with ``split='point'``; k is capped at
            the number of points); 1 uses the single ``val_fraction`` hold-out. On the FE data
            (~24 validation points) one hold-out chose worse Fx structures than 3 or 5 folds, and
            their test RMSE varied more over seeds (docs/model.md).
        split: ``'point'`` (hold out whole surface points, when ``groups`` are given) or ``'sample'``.
        extrapolation: out-of-range band per input (x, y, z, depth), fraction of its range (see
            :mod:`.sugeno`): by default positions saturate and depth extrapolates by 25 %.
        seed: seeds the validation split.
        form: ``'plain'``: F = ANFIS(inputs) (the paper's form); ``'depth_scaled'``: F = depth ·
            g(inputs) with g an :class:`~.estimator.ANFIS` per output trained by the same hybrid
            rule on the error of F (g fitted to F / depth with sample weights depth²): exactly 0 N
            at zero depth and continuous from contact (|F| ≤ c·depth).
        inputs: names of the ANFIS inputs among (x, y, z, depth), used exactly as given; or
            ``'auto'`` (default): all four for ``'plain'``; for ``'depth_scaled'`` (y, z, depth)
            when the data show x is a function of (y, z) (on one skin surface it is:
            :func:`~.defaults.x_explained_by_yz`), else all four. The decision and its figure
            are recorded in ``metadata_['training']['input_check']``.
            ``structure``, ``search_start``, ``max_mfs`` have one entry per ANFIS input;
            ``extrapolation`` one per column of (x, y, z, depth).
    """

    def __init__(self, *,
                 structure: Structure | Sequence[Structure] | str | None = SHIPPED['structure'],
                 epochs: int | Sequence[int] = SHIPPED['epochs'],
                 search_epochs: int = SHIPPED['search_epochs'],
                 search_start: Structure | None = None, max_mfs: Structure | None = SHIPPED['max_mfs'],
                 candidates: list[Structure] | None = None, tol: float = SHIPPED['tol'],
                 ridge: float | Sequence[float] = SHIPPED['ridge'], step: float = 0.01,
                 val_fraction: float = SHIPPED['val_fraction'], split: str = SHIPPED['split'],
                 search_folds: int = SHIPPED['search_folds'],
                 extrapolation: Sequence[float] | None = None, seed: int = SHIPPED['seed'],
                 form: str = SHIPPED['form'], inputs: Sequence[str] | str = SHIPPED['inputs'],
                 ridge_candidates: Sequence[float] | None = None) -> None:
        self.form = form
        self.inputs = inputs
        self.structure = structure
        self.epochs = epochs
        self.search_epochs = search_epochs
        self.search_start = search_start
        self.max_mfs = max_mfs
        self.candidates = candidates
        self.tol = tol
        self.ridge = ridge
        self.ridge_candidates = ridge_candidates
        self.step = step
        self.val_fraction = val_fraction
        self.split = split
        self.search_folds = search_folds
        self.extrapolation = extrapolation
        self.seed = seed
        self.metadata_: dict[str, Any] = {}

    # ---- training ---------------------------------------------------------------------------
    def _ridges(self) -> list[float]:
        """Per-output ridge weight (checked)."""
        r = self.ridge
        vals = [r] * 3 if np.ndim(r) == 0 else list(r)
        if len(vals) != 3 or not all(isinstance(v, (int, float, np.floating, np.integer))
                                     and np.isfinite(v) and v >= 0 for v in vals):
            raise ValueError(f'ridge: expected a weight >= 0 or one per output (3), got {r!r}')
        return [float(v) for v in vals]

    def _structures(self, names: Sequence[str] | None = None) -> list[Structure | None]:
        """Per-output structure (None = search); ``names``: the resolved ANFIS inputs (for
        ``structure='auto'``)."""
        s = self.structure
        if isinstance(s, str):
            if s != AUTO:
                raise ValueError(f"structure: expected None, 'auto' or MF counts, got {s!r}")
            if names is not None and tuple(names) == SHIPPED_INPUTS and self.candidates is None:
                return [tuple(st) for st in SHIPPED_STRUCTURE]
            return [None, None, None]
        if s is None:
            return [None, None, None]
        if len(s) and all(isinstance(v, (int, np.integer)) for v in s):
            return [tuple(int(v) for v in s)] * 3
        if len(s) != 3:
            raise ValueError(f'structure must be None, one tuple, or three tuples; got {s!r}')
        return [tuple(int(v) for v in st) for st in s]

    def _form(self, X4: np.ndarray | None = None
              ) -> tuple[tuple[int, ...], int, np.ndarray, Structure, Structure]:
        """(input columns, scale column, extrapolation (4,), search start, max MFs), checked;
        ``X4`` (n, 4): the training inputs ``inputs='auto'`` is decided on (sets
        ``input_check_``)."""
        if self.form not in FORMS:
            raise ValueError(f'form: expected one of {FORMS}, got {self.form!r}')
        scaled = self.form == 'depth_scaled'
        names = self.inputs
        self.input_check_ = {'inputs': 'given'}
        if names is None or (isinstance(names, str) and names == AUTO):
            if not scaled:
                names, self.input_check_ = INPUT_NAMES, {'inputs': 'auto (plain form: all four)'}
            elif X4 is None:
                names = SHIPPED_INPUTS
            else:
                chk = x_explained_by_yz(X4)
                names = SHIPPED_INPUTS if chk['drop_x'] else INPUT_NAMES
                self.input_check_ = {'inputs': 'auto', **chk}
        elif isinstance(names, str):
            raise ValueError(f"inputs: expected 'auto' or names among {INPUT_NAMES}, got {names!r}")
        unknown = [n for n in names if n not in INPUT_NAMES]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(f'inputs: expected distinct names among {INPUT_NAMES}, got {names!r}')
        cols = tuple(sorted(INPUT_NAMES.index(n) for n in names))
        d = len(cols)
        ext = self.extrapolation if self.extrapolation is not None else (
            DEFAULT_EXTRAPOLATION_SCALED if scaled else DEFAULT_EXTRAPOLATION)
        ext = np.broadcast_to(np.asarray(ext, dtype=np.float64), (4,)).copy()
        start = tuple(self.search_start) if self.search_start is not None else (2,) * d
        max_mfs = tuple(self.max_mfs) if self.max_mfs is not None else tuple(
            (X_MFS, 5, 5, 3)[c] for c in cols)
        if len(start) != d or len(max_mfs) != d:
            raise ValueError(f'search_start {start} and max_mfs {max_mfs} need one entry per ANFIS '
                             f'input {tuple(INPUT_NAMES[c] for c in cols)}')
        return cols, (3 if scaled else -1), ext, start, max_mfs

    def fit(self, X: np.ndarray, Y: np.ndarray, groups: np.ndarray | None = None,
            verbose: bool = False) -> 'ForceModel':
        """Train the three models on (X (n, 4) [m], Y (n, 3) [N]).

        ``val_fraction`` of the data (whole surface points if ``groups`` is given and
        ``split='point'``) is held out to choose each output's structure and epoch count; the chosen
        structure is then retrained on all of ``X`` for that many epochs.
        """
        def count(v: Any) -> bool:
            return not isinstance(v, bool) and isinstance(v, (int, np.integer)) and v >= 1
        if not count(self.search_epochs):
            raise ValueError(f'search_epochs: expected an integer >= 1, got {self.search_epochs!r}')
        epochs = [self.epochs] * 3 if np.ndim(self.epochs) == 0 else list(self.epochs)
        if len(epochs) != 3 or not all(count(e) for e in epochs):
            raise ValueError(f'epochs: expected an integer >= 1, got {self.epochs!r} (or three, '
                             'one per output)')
        X = check_finite_inputs(X, INPUT_NAMES)
        Y = np.asarray(Y, dtype=np.float64)
        if X.shape[1] != 4 or Y.shape != (len(X), 3):
            raise ValueError(f'fit needs X (n, 4) and Y (n, 3); got {X.shape} and {Y.shape}')
        if not np.all(np.isfinite(Y)):
            raise ValueError('fit: Y holds non-finite forces')
        cols, scol, ext, search_start, max_mfs = self._form(X)
        names = tuple(INPUT_NAMES[c] for c in cols)
        structures = self._structures(names)
        if scol >= 0 and not np.all(X[:, scol] > 0):
            k = int(np.argmin(X[:, scol]))
            raise ValueError(f'fit: the depth-scaled form needs depths > 0; sample {k} has depth '
                             f'{float(X[k, scol])} m')
        X4, X = X, X[:, list(cols)]
        S = X4[:, scol] if scol >= 0 else None
        sub = (lambda idx: None) if S is None else (lambda idx: S[idx])  # noqa: E731
        for o, st in enumerate(structures):
            if st is not None and len(st) != len(cols):
                raise ValueError(f'structure {st} of output {OUTPUT_NAMES[o]} needs one MF count '
                                 f'per ANFIS input {tuple(INPUT_NAMES[c] for c in cols)}')
        by = self.split if groups is not None else 'sample'
        groups = np.arange(len(X)) if groups is None else np.asarray(groups)
        ds = ForceDataset(X4, Y, groups)
        if self.val_fraction == 0:
            # No hold-out: every output trains exactly ``epochs`` epochs on all the data and keeps
            # its lowest-training-error epoch (a fixed epoch count, itself chosen by grouped CV).
            if any(s is None for s in structures) and int(self.search_folds) < 2:
                raise ValueError('val_fraction 0 (no hold-out) needs a fixed structure or '
                                 'search_folds >= 2 to score the structure search')
            fit_idx, val_idx = np.arange(len(X)), np.arange(0)
        else:
            fit_idx, val_idx = split_indices(ds, self.val_fraction, self.seed, by=by)
        if isinstance(self.search_folds, bool) or not isinstance(self.search_folds, (int, np.integer)) \
                or self.search_folds < 1:
            raise ValueError(f'search_folds: expected an integer >= 1, got {self.search_folds!r}')
        k = min(int(self.search_folds), len(np.unique(ds.point)) if by == 'point' else len(ds))
        folds = (fold_indices(ds, k, self.seed, by=by)
                 if k > 1 and any(s is None for s in structures) else None)
        lo, hi = X.min(axis=0), X.max(axis=0)  # of the ANFIS inputs
        ridges = self._ridges()
        if self.ridge_candidates is not None and all(s is not None for s in structures):
            raise ValueError('ridge_candidates: the ridge is chosen with the structure search; '
                             'with fixed structures give ridge (one, or one per output)')
        t_start = time.perf_counter()
        self.estimators_: list[ANFIS] = []
        self.search_: list[SearchResult | None] = []
        self.best_epoch_: list[int] = []
        self.val_rmse_: list[float] = []
        self.train_rmse_: list[float] = []
        self.train_curves_: list[dict[str, list[float]]] = []
        self.ridges_: list[float] = []
        for o, fixed in enumerate(structures):
            t0 = time.perf_counter()
            kw = dict(ridge=ridges[o], step=self.step, extrapolation=ext[list(cols)])
            Xf, tf, Xv, tv = X[fit_idx], Y[fit_idx, o], X[val_idx], Y[val_idx, o]
            if fixed is None:
                held = (dict(folds=folds, scale=S) if folds else
                        dict(X_val=Xv, t_val=tv, scale=sub(fit_idx), scale_val=sub(val_idx)))
                sr = search_structure(X if folds else Xf, Y[:, o] if folds else tf,
                                      start=search_start, max_mfs=max_mfs,
                                      candidates=self.candidates, tol=self.tol,
                                      epochs=self.search_epochs, lo=lo, hi=hi,
                                      ridges=self.ridge_candidates, trainer=_fit_anfis,
                                      **held, **kw)
                structure = sr.chosen.structure
                if sr.chosen.ridge is not None:
                    kw['ridge'] = sr.chosen.ridge
            else:
                sr = None
                structure = fixed
            self.ridges_.append(float(kw['ridge']))
            if len(val_idx):
                # Choose the epoch with the full epoch budget on the held-out part ...
                chk = _fit_anfis(Xf, tf, structure, epochs[o], X_check=Xv, t_check=tv,
                                 scale=sub(fit_idx), scale_check=sub(val_idx), **kw)
                # ... then retrain on all the training data for exactly that many epochs.
                final = _fit_anfis(X, Y[:, o], structure, chk.best_epoch, scale=S, **kw)
            else:
                final = chk = _fit_anfis(X, Y[:, o], structure, epochs[o], scale=S, **kw)
            self.estimators_.append(final.model)
            self.search_.append(sr)
            self.best_epoch_.append(chk.best_epoch)
            self.val_rmse_.append(chk.check_rmse[chk.best_epoch - 1] if chk.check_rmse
                                  else None)  # no hold-out (val_fraction 0)
            pred = final.model.predict(X) * (1.0 if S is None else S)  # numpy path
            self.train_rmse_.append(float(np.sqrt(np.mean((pred - Y[:, o]) ** 2))))
            self.train_curves_.append({'train': chk.train_rmse, 'check': chk.check_rmse})
            if verbose:
                _print_output_summary(OUTPUT_NAMES[o], sr, structure, chk.best_epoch,
                                      self.train_rmse_[-1], self.val_rmse_[-1], time.perf_counter() - t0)
        self.fit_seconds_ = time.perf_counter() - t_start
        self._input_cols, self._scale_col = cols, scol
        self._range = (X4.min(axis=0), X4.max(axis=0))
        self.metadata_ = {'training': {
            'form': self.form, 'inputs': [INPUT_NAMES[c] for c in cols], 'max_mfs': list(max_mfs),
            'epochs': self.epochs if np.ndim(self.epochs) == 0 else [int(e) for e in epochs],
            'search_epochs': self.search_epochs, 'tol': self.tol,
            'ridge': self.ridges_[0] if len(set(self.ridges_)) == 1 else list(self.ridges_),
            **({'ridge_candidates': [float(r) for r in self.ridge_candidates]}
               if self.ridge_candidates is not None else {}),
            'val_fraction': self.val_fraction, 'split': by,
            'search_folds': self.search_folds, 'input_check': self.input_check_,
            'structure': 'given' if not isinstance(self.structure, str) and self.structure is not None
            else ('search' if all(s is None for s in structures) else 'shipped'),
            'seed': self.seed, 'mf': 'triangular',
            'seconds': round(self.fit_seconds_, 3),
            'n_samples': int(len(X)),
            'candidates': [[_candidate_dict(c) for c in sr.candidates] if sr else []
                           for sr in self.search_],
        }}
        self._compile()
        return self

    # ---- prediction -------------------------------------------------------------------------
    def _check_fitted(self) -> None:
        if not getattr(self, 'estimators_', None):
            raise RuntimeError('ForceModel is not trained: call fit() or ForceModel.load()')

    @property
    def input_cols_(self) -> tuple[int, ...]:
        """Columns of (x, y, z, depth) the single-output models read."""
        return getattr(self, '_input_cols', (0, 1, 2, 3))

    @property
    def scale_col_(self) -> int:
        """Column of (x, y, z, depth) that multiplies the outputs (3: F = depth · g), or -1."""
        return getattr(self, '_scale_col', -1)

    def _compile(self) -> None:
        self._fp, self._ip = compiled.pack(self.estimators_, self.input_cols_, self.scale_col_, 4)
        compiled.warm_up(self._fp, self._ip)
        self._eval_one, self._jac_one = compiled.entry_points(self._fp, self._ip)

    def __getstate__(self) -> dict[str, Any]:
        # The compiled entry points are not picklable; they are rebuilt from the packed arrays.
        return {k: v for k, v in self.__dict__.items() if k not in ('_eval_one', '_jac_one')}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if '_fp' in state:
            compiled.warm_up(self._fp, self._ip)
            self._eval_one, self._jac_one = compiled.entry_points(self._fp, self._ip)

    def predict(self, X: np.ndarray, *, jacobian: bool = False
                ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Batch forces (compiled): X (n, 4) [m] (any float dtype) -> F (n, 3) [N].

        With ``jacobian``: (F, J (n, 3, 4) [N/m]) with ``J[i, a, b] = dF_a / dX_b`` at ``X[i]``,
        the exact derivatives of the model. Where an input is clamped by the out-of-range policy
        its column is 0; at an MF kink the derivative is one-sided. The same numbers as the
        estimators' numpy path (``estimators_[o].predict`` on the input columns, times the depth
        in the depth-scaled form) to rounding.

        Raises:
            ValueError: on NaN/Inf input or a shape other than (n, 4).
        """
        self._check_fitted()
        X = np.ascontiguousarray(check_finite_inputs(X, INPUT_NAMES))
        if X.shape[1] != 4:
            raise ValueError(f'predict needs X of shape (n, 4); got {X.shape}')
        if jacobian:
            return compiled.eval_jac_batch(X, self._fp, self._ip)
        return compiled.eval_batch(X, self._fp, self._ip)

    def jacobian_one(self, x: float, y: float, z: float, depth: float
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Compiled real-time forces and Jacobian for one contact: metres in.

        Returns:
            (F (3,) [N], J (3, 4) [N/m]), ``J[a, b] = dF_a / d(x, y, z, depth)_b``. From njit code
            call :func:`.compiled.jac_xyzd` with :attr:`kernel_params` instead.
        Raises:
            ValueError: if any input is NaN or Inf.
        """
        F, J, ok = self._jac_one(x, y, z, depth, self._fp, self._ip)
        if not ok:
            raise ValueError(f'non-finite input to jacobian_one: x={x!r}, y={y!r}, z={z!r}, '
                             f'depth={depth!r}')
        return F, J

    def predict_one(self, x: float, y: float, z: float, depth: float) -> tuple[float, float, float]:
        """Compiled real-time path for one contact: metres in, (Fx, Fy, Fz) newtons out.

        Raises:
            ValueError: if any input is NaN or Inf (the caller decides the safe output, e.g. 0 N).
        """
        try:
            return self._eval_one(x, y, z, depth, self._fp, self._ip)
        except ValueError:
            raise ValueError(f'non-finite input to predict_one: x={x!r}, y={y!r}, z={z!r}, '
                             f'depth={depth!r}') from None

    @property
    def kernel_params(self) -> tuple[np.ndarray, np.ndarray]:
        """(fp, ip) packed parameters for calling :mod:`.compiled` kernels from other njit code."""
        self._check_fitted()
        return self._fp, self._ip

    @property
    def input_range_(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) (4,) arrays of the trained input domain [m]."""
        self._check_fitted()
        return self._range[0].copy(), self._range[1].copy()

    @property
    def structures_(self) -> list[Structure]:
        """MF counts per ANFIS input, one tuple per output."""
        self._check_fitted()
        return [tuple(len(P) for P in e.mf_params_) for e in self.estimators_]

    # ---- persistence ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The model file's document (:mod:`.model_file`, the current format version)."""
        self._check_fitted()
        lo, hi = self.input_range_
        outputs = []
        rmse = self.metadata_.get('rmse', {})
        for o, e in enumerate(self.estimators_):
            entry = {'name': OUTPUT_NAMES[o], 'unit': OUTPUT_UNITS[o], **estimator_to_dict(e)}
            entry['best_epoch'] = self.best_epoch_[o] if hasattr(self, 'best_epoch_') else None
            entry['rmse'] = {k: v[o] for k, v in rmse.items()}
            outputs.append(entry)
        scol = self.scale_col_
        form = {'name': 'depth_scaled' if scol >= 0 else 'plain',
                'inputs': [INPUT_NAMES[c] for c in self.input_cols_],
                'scale': INPUT_NAMES[scol] if scol >= 0 else None}
        return {
            'format': FORMAT, 'format_version': FORMAT_VERSION, 'software_version': __version__,
            'form': form,
            'created_utc': _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds'),
            'inputs': [{'name': n, 'unit': u, 'min': float(a), 'max': float(b)}
                       for n, u, a, b in zip(INPUT_NAMES, INPUT_UNITS, lo, hi)],
            'outputs': outputs,
            **{k: v for k, v in self.metadata_.items() if k != 'rmse'},
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the versioned model file atomically (see :mod:`.model_file`)."""
        return write_json_atomic(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike) -> 'ForceModel':
        """Read a model file; any format, version, shape or finiteness problem -> ModelFileError.
        Files of format versions 1 and 2 (triangular MFs on the pinned partition) are migrated
        to the estimators exactly (:func:`.model_file.estimator_from_dict`)."""
        doc = read_model_doc(path)
        try:
            return cls._from_doc(doc, path)
        except ModelFileError:
            raise
        except (AttributeError, TypeError, KeyError, IndexError, ValueError) as exc:
            # a field of the wrong type (a hand-edited file): one line, not a traceback
            raise ModelFileError(f'model file {str(path)!r}: malformed ({type(exc).__name__}: '
                                 f'{exc}); expected the layout `haptic-anfis train` writes'
                                 ) from None

    @classmethod
    def _from_doc(cls, doc: dict, path: str | os.PathLike) -> 'ForceModel':
        for key in ('training', 'dataset', 'case', 'grouped_cv'):   # read by callers as mappings
            if key in doc and not isinstance(doc[key], dict):
                raise ModelFileError(f'model file {str(path)!r}: "{key}" is '
                                     f'{type(doc[key]).__name__}; expected a mapping')
        names = [i.get('name') for i in doc['inputs']]
        if names != list(INPUT_NAMES):
            raise ModelFileError(f'model file {str(path)!r} has inputs {names}; expected '
                                 f'{list(INPUT_NAMES)}')
        outs = [o.get('name') for o in doc['outputs']]
        if outs != list(OUTPUT_NAMES):
            raise ModelFileError(f'model file {str(path)!r} has outputs {outs}; expected '
                                 f'{list(OUTPUT_NAMES)}')
        lo = np.array([i['min'] for i in doc['inputs']], dtype=np.float64)
        hi = np.array([i['max'] for i in doc['inputs']], dtype=np.float64)
        cols, scol = _read_form(doc, path)
        self = cls()
        try:
            self.estimators_ = [estimator_from_dict(o, lo[list(cols)], hi[list(cols)], o['name'],
                                                    doc['format_version'])
                                for o in doc['outputs']]
        except ModelFileError as exc:
            raise ModelFileError(f'model file {str(path)!r}: {exc}') from None
        self._input_cols, self._scale_col = cols, scol
        self._range = (lo, hi)
        self.best_epoch_ = [o.get('best_epoch') for o in doc['outputs']]
        rmse_keys = set().union(*(o.get('rmse', {}).keys() for o in doc['outputs']))
        self.metadata_ = {k: v for k, v in doc.items()
                          if k not in ('format', 'format_version', 'inputs', 'outputs', 'form',
                                       'software_version', 'created_utc')}
        self.metadata_['rmse'] = {k: [o.get('rmse', {}).get(k) for o in doc['outputs']]
                                  for k in sorted(rmse_keys)}
        self.source_ = {'path': str(path), 'software_version': doc.get('software_version'),
                        'created_utc': doc.get('created_utc'),
                        'format_version': doc['format_version']}
        self.ridges_ = _trained_ridges(self.metadata_)
        self._compile()
        return self


def _fit_anfis(X: np.ndarray, t: np.ndarray, structure: Structure, epochs: int,
               X_check: np.ndarray | None = None, t_check: np.ndarray | None = None,
               lo: np.ndarray | None = None, hi: np.ndarray | None = None,
               scale: np.ndarray | None = None, scale_check: np.ndarray | None = None, *,
               ridge: float, step: float, extrapolation: np.ndarray) -> TrainResult:
    """One output's triangular :class:`~.estimator.ANFIS` on (X, t), with
    :func:`~.training.train`'s signature for :func:`~.structure.search_structure`.

    The scaled form F = s · g (``scale`` s > 0 per sample) is fitted as g on t / s with sample
    weights s²: the same squared error of F. ``lo``/``hi`` are not used: an estimator's domain
    is its training data's range. RMSEs in the result are of F.
    """
    est = ANFIS(n_mfs=tuple(int(m) for m in structure), mf='triangular', epochs=int(epochs),
                step=step, ridge=ridge, ridge_target='linear',
                extrapolation=tuple(extrapolation))
    val = None
    if X_check is not None and t_check is not None and len(X_check):
        val = ((X_check, t_check, None) if scale_check is None
               else (X_check, t_check / scale_check, scale_check ** 2))
    est.fit(X, t if scale is None else t / scale,
            sample_weight=None if scale is None else scale ** 2, validation_data=val)
    return TrainResult(model=est, best_epoch=est.best_epoch_, train_rmse=est.train_rmse_,
                       check_rmse=est.validation_rmse_, n_params=est.n_params_)


def numpy_forces(model: ForceModel, X: np.ndarray) -> np.ndarray:
    """The estimators' numpy path: X (n, 4) [m] -> (n, 3) [N], each output's
    :meth:`ANFIS.predict <.estimator.ANFIS.predict>` on its input columns (times the depth in the
    depth-scaled form). The oracle the compiled kernels are tested against, and the numpy
    timings' path; the force model's own :meth:`ForceModel.predict` is compiled."""
    model._check_fitted()
    X = check_finite_inputs(X, INPUT_NAMES)
    U = X[:, list(model.input_cols_)]
    F = np.column_stack([e.predict(U) for e in model.estimators_])
    if model.scale_col_ >= 0:
        F *= np.maximum(X[:, model.scale_col_], 0.0)[:, None]
    return F


def _trained_ridges(metadata: dict[str, Any]) -> list[float]:
    """Per-output ridge a model file was trained with (its training metadata: one weight or one
    per output); :data:`~.defaults.LEGACY_RIDGE` when the file does not say (older files)."""
    r = metadata.get('training', {}).get('ridge', LEGACY_RIDGE)
    vals = list(r) if np.ndim(r) else [r] * 3
    try:
        return [float(v) for v in vals] if len(vals) == 3 else [LEGACY_RIDGE] * 3
    except (TypeError, ValueError):
        return [LEGACY_RIDGE] * 3


def _read_form(doc: dict[str, Any], path: str | os.PathLike) -> tuple[tuple[int, ...], int]:
    """(ANFIS input columns, scale column or -1) from a model file's "form" (version 1: plain)."""
    if doc['format_version'] == 1:
        return (0, 1, 2, 3), -1
    form = doc.get('form')
    try:
        names = list(form['inputs'])
        cols = tuple(INPUT_NAMES.index(n) for n in names)
        scale = form.get('scale')
        scol = {None: -1, 'depth': 3}[scale]
        ok = form.get('name') == ('plain' if scol < 0 else 'depth_scaled')
    except (TypeError, KeyError, ValueError, AttributeError):
        ok = False
    if not ok or not cols or list(cols) != sorted(set(cols)):
        raise ModelFileError(f'model file {str(path)!r} (format_version {doc["format_version"]}): '
                             '"form" must be '
                             '{"name": "plain" | "depth_scaled", "inputs": [names among '
                             f'{list(INPUT_NAMES)} in order], "scale": null | "depth"}}; got {form!r}')
    return cols, scol


def _candidate_dict(c: Candidate) -> dict[str, Any]:
    return {'structure': list(c.structure), 'rules': c.n_rules, 'params': c.n_params,
            'train_rmse': c.train_rmse, 'val_rmse': c.val_rmse, 'best_epoch': c.best_epoch,
            'seconds': round(c.seconds, 3), **({'ridge': c.ridge} if c.ridge is not None else {})}


def _print_output_summary(name: str, sr: SearchResult | None, structure: Structure, epoch: int,
                          train_rmse: float, val_rmse: float | None, seconds: float) -> None:
    if sr is not None:
        print(f'{name}: structure search ({len(sr.candidates)} candidates)')
        print(f'  {"structure":<12} {"rules":>5} {"params":>6} {"train N":>9} {"val N":>9} '
              f'{"epoch":>5} {"s":>6}')
        for c in sr.candidates:
            mark = ' <- chosen' if c.structure == structure else ''
            print(f'  {"-".join(map(str, c.structure)):<12} {c.n_rules:>5} {c.n_params:>6} '
                  f'{c.train_rmse:>9.5f} {c.val_rmse:>9.5f} {c.best_epoch:>5} {c.seconds:>6.2f}{mark}')
    val = 'n/a (no hold-out)' if val_rmse is None else f'{val_rmse:.5f} N'
    print(f'{name}: structure {"-".join(map(str, structure))}, best epoch {epoch}, '
          f'train RMSE {train_rmse:.5f} N, validation RMSE {val} ({seconds:.1f} s)')


def rmse(pred: np.ndarray, Y: np.ndarray) -> list[float]:
    """Per-output root-mean-square error [N] of (n, 3) predictions."""
    return [float(v) for v in np.sqrt(np.mean((pred - Y) ** 2, axis=0))]


def _check_training_inputs(ds: ForceDataset, dataset_path: str | None) -> None:
    """DatasetError naming the dataset, the row and the column for inputs no model file may
    hold: lengths beyond the model file's ±1 m (a dataset in millimetres: the model would be
    written, then refused when loaded) and depths <= 0 (the depth-scaled form divides by them).
    Rows count from 1 after the header (a CSV's line is one more)."""
    where = f'dataset {dataset_path!r}' if dataset_path else 'dataset'
    X = np.asarray(ds.X, dtype=np.float64)
    for c, name in enumerate(('x_m', 'y_m', 'z_m', 'depth_m')):
        k = int(np.argmax(np.abs(X[:, c]))) if len(X) else 0
        if len(X) and abs(X[k, c]) > MAX_ABS_INPUT_M:
            raise DatasetError(f'{where}: {name} = {X[k, c]:g} at row {k + 1}; expected metres '
                               f'within ±{MAX_ABS_INPUT_M:g} m (a dataset in millimetres?)')
    if len(X) and not np.all(X[:, 3] > 0):
        k = int(np.argmin(X[:, 3]))
        raise DatasetError(f'{where}: depth_m = {X[k, 3]:g} at row {k + 1}; expected depths > 0 '
                           '(a sample with no indentation has no force to learn)')


def train_on_dataset(ds: ForceDataset, test_fraction: float = 0.2, seed: int = 0,
                     verbose: bool = False, dataset_path: str | None = None,
                     **params: Any) -> tuple[ForceModel, ForceDataset]:
    """The paper's protocol: hold out ``test_fraction`` (whole surface points) for the test, fit
    on the rest (ForceModel's defaults: the shipped configuration, :data:`.defaults.SHIPPED`;
    ``params`` override them), record RMSEs and the dataset hash in the model. Returns (model,
    test set).
    """
    _check_training_inputs(ds, dataset_path)
    by = params.get('split', 'point')
    if by == 'point' and len(np.unique(ds.point)) < 5:
        raise DatasetError(f'training needs at least 5 surface points for a split by point, the '
                           f'dataset has {len(np.unique(ds.point))} (or split by sample)')
    train_idx, test_idx = split_indices(ds, test_fraction, seed, by=by)
    tr, te = ds.subset(train_idx), ds.subset(test_idx)
    model = ForceModel(seed=seed, **params).fit(tr.X, tr.Y, groups=tr.point, verbose=verbose)
    model.metadata_['rmse'] = {
        'train': model.train_rmse_,
        'validation': model.val_rmse_,
        'test': rmse(model.predict(te.X), te.Y),
    }
    model.metadata_['dataset'] = {
        'sha256': ds.sha256(), 'path': dataset_path, 'n_samples': len(ds),
        'n_points': int(len(np.unique(ds.point))), 'test_fraction': test_fraction,
        'n_test_samples': len(te), 'kind': ds.provenance.get('kind'),
    }
    return model, te

"""The models the report compares, behind one small adapter interface.

A peer has a ``name``, a ``family`` (what kind of model it is) and

    fit(X (n, 4) [m], Y (n, 3) [N], groups=None) -> self     # groups: surface-point ids (ours use them)
    predict(X (n, 4)) -> (n, 3) [N]                          # batch path

and, with defaults here, ``time_single(Q, repeats)`` (per-call seconds of its real-time path on one
row: ours ``predict_one``, everyone else ``predict`` on a (1, 4) array), ``throughput(X)`` (batch
evaluations per second) and ``curves()`` (per-epoch errors, if it keeps them). A peer that cannot be
imported or trained raises; the report catches that and lists the peer as failed with the reason.

scikit-learn (the ``report`` extra) is optional: without it its peers raise when fitted. xanfis
runs in a process of its own (:mod:`haptic_anfis.report._xanfis_worker`). Nothing here is needed to
run the simulator.
"""
from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import RBFInterpolator

from ..anfis import ForceModel
from ..anfis.timing import throughput, time_calls
from ._xanfis_worker import _pack, _unpack
from .compiled_mlp import mlp_batch, mlp_one, pack_mlp

try:  # the scikit-learn peers: the 'report' extra
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import LinearRegression
    from sklearn.neighbors import KNeighborsRegressor
    from sklearn.neural_network import MLPRegressor
except ImportError as exc:
    _NO_SKLEARN: ImportError | None = exc
else:
    _NO_SKLEARN = None


def _need_sklearn() -> None:
    if _NO_SKLEARN is not None:
        raise ImportError(f'scikit-learn (the report extra): {_NO_SKLEARN}')


def _rows(Q: np.ndarray) -> list[tuple[np.ndarray]]:
    """Each row of Q as a (1, 4) array argument: the single-query call of a batch ``predict``."""
    return [(np.ascontiguousarray(Q[i:i + 1]),) for i in range(len(Q))]


class Peer:
    """Base adapter: subclasses set ``name``/``family`` and implement ``fit`` and ``predict``."""

    name = 'peer'
    family = ''
    realtime_path = 'predict on one row'

    def fit(self, X: np.ndarray, Y: np.ndarray, groups: np.ndarray | None = None) -> 'Peer':
        raise NotImplementedError

    def predict(self, X: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def time_single(self, Q: np.ndarray, repeats: int) -> np.ndarray:
        return time_calls(self.predict, _rows(Q), repeats)

    def throughput(self, X: np.ndarray, min_seconds: float = 0.3) -> float:
        return throughput(self.predict, X, min_seconds)

    def curves(self) -> list[dict[str, list[float]]]:
        return []

    def close(self) -> None:
        pass


class _Standardised(Peer):
    """Inputs and outputs scaled to zero mean, unit variance (positions and depth differ in spread)."""

    def _scale_fit(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.mu_, self.sd_ = X.mean(0), np.where(X.std(0) > 0, X.std(0), 1.0)
        self.ymu_, self.ysd_ = Y.mean(0), np.where(Y.std(0) > 0, Y.std(0), 1.0)
        return (X - self.mu_) / self.sd_, (Y - self.ymu_) / self.ysd_

    def predict(self, X: np.ndarray) -> np.ndarray:
        Z = (np.asarray(X, dtype=np.float64) - self.mu_) / self.sd_
        return self._predict_scaled(Z).reshape(len(Z), 3) * self.ysd_ + self.ymu_

    def _predict_scaled(self, Z: np.ndarray) -> np.ndarray:
        raise NotImplementedError


# ---- ours -----------------------------------------------------------------------------------
def structure_label(structure: Any) -> str:
    """'5-5-2' for one structure (all outputs), '7-7-2/5-5-2/5-5-2' for one per output."""
    if len(structure) and all(isinstance(v, (int, np.integer)) for v in structure):
        return '-'.join(map(str, structure))
    labels = ['-'.join(map(str, s)) for s in structure]
    return labels[0] if len(set(labels)) == 1 else '/'.join(labels)


class OursPeer(Peer):
    """Our ANFIS (:class:`haptic_anfis.anfis.ForceModel`); ``structure=None`` = the structure search."""

    family = 'ANFIS (ours)'
    realtime_path = 'predict_one (numba)'

    def __init__(self, structure: tuple[int, ...] | None, **params: Any) -> None:
        self.structure = structure
        self.params = params
        form = 'plain' if params.get('form') == 'plain' else 'depth·g'
        if params.get('inputs') is not None and tuple(params['inputs']) != ('y', 'z', 'depth'):
            form += '(' + ', '.join(params['inputs']) + ')'
        self.name = (f'ours {form}: search' if structure is None else
                     f'ours {form} {structure_label(structure)}')

    def fit(self, X, Y, groups=None):
        self.model_ = ForceModel(structure=self.structure, **self.params).fit(X, Y, groups=groups)
        return self

    def predict(self, X):
        return self.model_.predict(X)

    def time_single(self, Q, repeats):
        one = self.model_.predict_one
        return time_calls(one, [tuple(float(v) for v in q) for q in Q], repeats)

    def throughput(self, X, min_seconds=0.3):
        return throughput(self.model_.predict, X, min_seconds)

    def curves(self):
        return [dict(c) for c in self.model_.train_curves_]

    @property
    def detail(self) -> str:
        return '/'.join('-'.join(map(str, s)) for s in self.model_.structures_)


# ---- scikit-learn / scipy -------------------------------------------------------------------
class LinearPeer(Peer):
    name, family = 'linear regression', 'scikit-learn LinearRegression'

    def fit(self, X, Y, groups=None):
        _need_sklearn()
        self.model_ = LinearRegression().fit(X, Y)
        return self

    def predict(self, X):
        return self.model_.predict(X)


class KnnPeer(_Standardised):
    family = 'scikit-learn KNeighborsRegressor'

    def __init__(self, k: int = 5) -> None:
        self.k = k
        self.name = f'k-NN (k={k}, distance-weighted)'

    def fit(self, X, Y, groups=None):
        _need_sklearn()
        Z, T = self._scale_fit(X, Y)
        self.model_ = KNeighborsRegressor(n_neighbors=self.k, weights='distance').fit(Z, T)
        return self

    def _predict_scaled(self, Z):
        return self.model_.predict(Z)


class MlpPeer(_Standardised):
    family = 'scikit-learn MLPRegressor'

    def __init__(self, hidden: tuple[int, ...] = (32, 32), max_iter: int = 2000, seed: int = 0) -> None:
        self.hidden, self.max_iter, self.seed = hidden, max_iter, seed
        self.name = f'MLP {"-".join(map(str, hidden))} (tanh)'

    def fit(self, X, Y, groups=None):
        _need_sklearn()
        Z, T = self._scale_fit(X, Y)
        self.model_ = MLPRegressor(hidden_layer_sizes=self.hidden, activation='tanh', solver='lbfgs',
                                   alpha=1e-4, max_iter=self.max_iter, random_state=self.seed)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', ConvergenceWarning)
            self.model_.fit(Z, T)
        return self

    def _predict_scaled(self, Z):
        return self.model_.predict(Z)

    def curves(self):
        lc = getattr(self.model_, 'loss_curve_', None)
        return [{'train': [float(v) for v in lc]}] if lc else []


class CompiledMlpPeer(MlpPeer):
    """The MLP peer with its forward pass compiled like ours (numba, packed parameters): the fair
    speed comparison (same weights as :class:`MlpPeer`, so the same errors)."""

    family = 'scikit-learn MLPRegressor, forward pass in numba'
    realtime_path = 'mlp_one (numba)'

    def __init__(self, hidden: tuple[int, ...] = (32, 32), max_iter: int = 2000, seed: int = 0) -> None:
        super().__init__(hidden, max_iter, seed)
        self.name = f'MLP {"-".join(map(str, hidden))} (tanh, numba)'

    def fit(self, X, Y, groups=None):
        super().fit(X, Y, groups)
        self.fp_, self.ip_ = pack_mlp(self.model_.coefs_, self.model_.intercepts_, self.mu_,
                                      self.sd_, self.ymu_, self.ysd_)
        mlp_one(0.0, 0.0, 0.0, 0.0, self.fp_, self.ip_)  # compile (or load) outside the timings
        mlp_batch(np.zeros((1, 4)), self.fp_, self.ip_)
        return self

    def predict(self, X):
        return mlp_batch(np.ascontiguousarray(X, dtype=np.float64), self.fp_, self.ip_)

    def time_single(self, Q, repeats):
        fp, ip = self.fp_, self.ip_
        return time_calls(lambda x, y, z, d: mlp_one(x, y, z, d, fp, ip),
                          [tuple(float(v) for v in q) for q in Q], repeats)


class RbfPeer(_Standardised):
    family = 'scipy RBFInterpolator'

    def __init__(self, kernel: str = 'thin_plate_spline', smoothing: float = 1e-3) -> None:
        self.kernel, self.smoothing = kernel, smoothing
        self.name = f'RBF ({kernel.replace("_", " ")})'

    def fit(self, X, Y, groups=None):
        Z, T = self._scale_fit(X, Y)
        self.model_ = RBFInterpolator(Z, T, kernel=self.kernel, smoothing=self.smoothing)
        return self

    def _predict_scaled(self, Z):
        return self.model_(Z)


# ---- xanfis (its own virtualenv) ------------------------------------------------------------
XANFIS_ENV = 'HAPTIC_ANFIS_XANFIS_PYTHON'
WORKER = Path(__file__).resolve().parent / '_xanfis_worker.py'


def xanfis_python() -> Path:
    """The interpreter of the xanfis environment: $HAPTIC_ANFIS_XANFIS_PYTHON, else the virtualenv
    ``<this venv>-xanfis`` beside the running one (``make venv`` makes ``.venv-xanfis``)."""
    env = os.environ.get(XANFIS_ENV)
    if env:
        return Path(env)
    prefix = Path(sys.prefix)
    return prefix.with_name(prefix.name + '-xanfis') / 'bin' / 'python'


class XanfisPeer(Peer):
    """xanfis ``AnfisRegressor`` (PyPI ``xanfis`` 1.1.0: Gaussian MFs, a learned rule base of
    ``num_rules`` rules, least squares for the consequents + Adam for the MFs, on torch).

    xanfis pins numpy<=1.26.0, incompatible with this project's numpy 2, so it runs in its own
    virtualenv through ``_xanfis_worker.py``; fit, predict and all timings happen in that process.
    """

    family = 'xanfis AnfisRegressor (PyPI, torch)'
    realtime_path = 'predict on one row (in its own process)'

    # Settings: a few tried on the shipped data (rules 5/10/20, ridge 1e-5..1e-1, batch 64/512,
    # early stopping on/off); 10 rules, ridge 1e-2, full-batch least squares generalised best.
    def __init__(self, num_rules: int = 10, epochs: int = 300, batch_size: int = 512, lr: float = 0.01,
                 reg_lambda: float = 1e-2, seed: int = 0,
                 python: str | os.PathLike | None = None) -> None:
        self.params = dict(num_rules=num_rules, mf_class='Gaussian', reg_lambda=reg_lambda,
                           epochs=epochs, batch_size=batch_size, optim='Adam',
                           optim_params={'lr': lr}, early_stopping=False, valid_rate=0.1,
                           seed=seed, verbose=False)
        self.python = Path(python) if python else xanfis_python()
        self.name = f'xanfis ANFIS ({num_rules} rules)'
        self._proc: subprocess.Popen | None = None

    def _start(self) -> None:
        if not self.python.exists():
            raise RuntimeError(f'xanfis environment not installed ({self.python} missing; '
                               '`make venv` creates it)')
        env = {k: v for k, v in os.environ.items() if k != '_ROS_WHEELS_BOOTSTRAP_COMPLETE'}
        env.update(OMP_NUM_THREADS='1', MKL_NUM_THREADS='1', OPENBLAS_NUM_THREADS='1')
        self._proc = subprocess.Popen([str(self.python), str(WORKER)], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)

    def _call(self, *req: Any) -> Any:
        if self._proc is None:
            self._start()
        p = self._proc
        data = pickle.dumps(_pack(req), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            p.stdin.write(struct.pack('<Q', len(data)) + data)
            p.stdin.flush()
            head = p.stdout.read(8)
            if len(head) < 8:
                raise EOFError
            (n,) = struct.unpack('<Q', head)
            status, value = _unpack(pickle.loads(p.stdout.read(n)))
        except (EOFError, BrokenPipeError, OSError):
            self.close()
            err = p.stderr.read().decode(errors='replace').strip().splitlines()
            raise RuntimeError('xanfis worker died: ' + (err[-1] if err else 'no message')) from None
        if status != 'ok':
            raise RuntimeError(f'xanfis: {value}')
        return value

    def fit(self, X, Y, groups=None):
        self.fit_seconds_ = self._call('fit', np.asarray(X, np.float64), np.asarray(Y, np.float64),
                                       self.params)
        return self

    def predict(self, X):
        return np.asarray(self._call('predict', np.asarray(X, np.float64)), dtype=np.float64)

    def time_single(self, Q, repeats):
        return np.asarray(self._call('time_single', np.asarray(Q, np.float64), int(repeats)))

    def throughput(self, X, min_seconds=0.3):
        return float(self._call('throughput', np.asarray(X, np.float64), float(min_seconds)))

    def curves(self):
        c = self._call('curves')
        return [c] if c else []

    def close(self) -> None:
        p, self._proc = self._proc, None
        if p is not None and p.poll() is None:
            try:
                p.stdin.close()
                p.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                p.kill()
                p.wait()


def default_peers(quick: bool = False, seed: int = 0) -> list[Peer]:
    """The peers of a full report (or tiny ones for ``quick``)."""
    if quick:
        return [LinearPeer(), KnnPeer(5), RbfPeer(), MlpPeer((8,), max_iter=200, seed=seed),
                CompiledMlpPeer((8,), max_iter=200, seed=seed),
                XanfisPeer(num_rules=4, epochs=5, seed=seed)]
    return [LinearPeer(), KnnPeer(5), RbfPeer(), MlpPeer((32, 32), seed=seed),
            CompiledMlpPeer((32, 32), seed=seed), XanfisPeer(seed=seed)]

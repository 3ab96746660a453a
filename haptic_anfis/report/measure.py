"""Measures of one fitted model: accuracy on the held-out points, speed, and smoothness.

Pure numpy/scipy; every number comes from running the model here. Timings are wall-clock on a
shared machine: percentiles, never asserted.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.interpolate import LinearNDInterpolator

from ..tissue.dataset import ForceDataset

JUMP_STEP_M = 1e-4          # neighbouring inputs 0.1 mm apart
MONOTONE_TOL_N = 1e-5       # Fx may dip this much between 0.1 mm steps and still count as growing


@dataclass
class Probes:
    """Inputs every model is evaluated on beyond the test set (built once, shared by all models).

    lines: list of (m_i, 4) arrays, consecutive rows 0.1 mm apart (along y, z or depth).
    depth_lines: (P, D, 4): for each surface point, depth from the data's min to max in 0.1 mm steps.
    batch: (B, 4) random inputs on the surface within the data's range, for throughput.
    """
    lines: list[np.ndarray]
    depth_lines: np.ndarray
    batch: np.ndarray
    summary: dict[str, Any] = field(default_factory=dict)


def surface_points(ds: ForceDataset) -> tuple[np.ndarray, np.ndarray]:
    """(ids (P,), xyz (P, 3)) of the dataset's surface points."""
    ids, first = np.unique(ds.point, return_index=True)
    return ids, ds.X[first, :3]


def make_probes(ds: ForceDataset, n_lines: int = 8, n_depths: int = 3, batch: int = 100_000,
                seed: int = 0) -> Probes:
    """Lines through the input domain. Contact points stay on the surface: x is interpolated
    (linearly, over the (y, z) triangulation of the data's surface points) from (y, z)."""
    _, xyz = surface_points(ds)
    surf = LinearNDInterpolator(xyz[:, 1:], xyz[:, 0])
    d_lo, d_hi = ds.X[:, 3].min(), ds.X[:, 3].max()
    depths = np.linspace(d_lo, d_hi, n_depths)
    lines = []
    for axis in (1, 2):                       # along y at fixed z, along z at fixed y
        other = 3 - axis
        a_lo, a_hi = xyz[:, axis].min(), xyz[:, axis].max()
        o_lo, o_hi = xyz[:, other].min(), xyz[:, other].max()
        t = np.arange(a_lo, a_hi + 1e-12, JUMP_STEP_M)
        for o in np.linspace(o_lo, o_hi, n_lines + 2)[1:-1]:
            yz = np.empty((len(t), 2))
            yz[:, axis - 1], yz[:, other - 1] = t, o
            x = surf(yz)
            ok = np.isfinite(x)
            if ok.sum() < 2:
                continue
            # keep the longest run inside the data's footprint (one line, no gaps)
            idx = np.flatnonzero(ok)
            runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
            run = max(runs, key=len)
            for d in depths:
                L = np.column_stack([x[run], yz[run], np.full(len(run), d)])
                lines.append(L)
    steps = np.arange(d_lo, d_hi + 1e-12, JUMP_STEP_M)
    depth_lines = np.empty((len(xyz), len(steps), 4))
    depth_lines[:, :, :3] = xyz[:, None, :]
    depth_lines[:, :, 3] = steps[None, :]
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(xyz), batch)
    B = np.column_stack([xyz[pick], d_lo + (d_hi - d_lo) * rng.random(batch)])
    n_line_pts = sum(len(L) for L in lines)
    return Probes(lines, depth_lines, B, {
        'n_lines': len(lines), 'n_line_points': n_line_pts, 'depths_m': depths.tolist(),
        'n_depth_lines': len(xyz), 'depth_steps': len(steps)})


def data_jump_scale(ds: ForceDataset) -> float:
    """The data's own steepest change per 0.1 mm: max over surface points and consecutive depths of
    |ΔF| / Δdepth × 0.1 mm (the FE data's slope, for scale)."""
    best = 0.0
    for p in np.unique(ds.point):
        m = ds.point == p
        order = np.argsort(ds.X[m, 3])
        d, F = ds.X[m, 3][order], ds.Y[m][order]
        if len(d) > 1:
            dd = np.diff(d)
            ok = dd > 0
            slope = np.linalg.norm(np.diff(F, axis=0), axis=1)[ok] / dd[ok]
            if len(slope):
                best = max(best, float(slope.max() * JUMP_STEP_M))
    return best


def rmse_per_output(P: np.ndarray, Y: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((P - Y) ** 2, axis=0))


def measure(peer, train: ForceDataset, test: ForceDataset, probes: Probes, force_range: np.ndarray,
            full: ForceDataset, repeats: int, batch_seconds: float) -> dict[str, Any]:
    """Fit ``peer`` on ``train`` and measure it. Never raises: a failure becomes ``status``."""
    row: dict[str, Any] = {'name': getattr(peer, 'name', type(peer).__name__),
                           'family': getattr(peer, 'family', ''),
                           'realtime_path': getattr(peer, 'realtime_path', ''), 'status': 'ok'}
    stage = 'fit'
    try:
        t0 = time.perf_counter()
        peer.fit(train.X, train.Y, groups=train.point)
        row['fit_s'] = time.perf_counter() - t0
        stage = 'predict'
        P = np.asarray(peer.predict(test.X), dtype=np.float64)
        if P.shape != test.Y.shape:
            raise ValueError(f'predict returned shape {P.shape}, expected {test.Y.shape}')
        if not np.all(np.isfinite(P)):
            raise ValueError('predict returned non-finite forces on the test set')
        err = P - test.Y
        row['test_pred'] = P
        row['rmse'] = rmse_per_output(P, test.Y)
        row['rel_rmse'] = row['rmse'] / force_range
        row['rmse_vec'] = float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))
        row['max_err'] = np.abs(err).max(axis=0)
        row['full_pred'] = np.asarray(peer.predict(full.X), dtype=np.float64)
        stage = 'timing'
        t = np.asarray(peer.time_single(test.X, repeats))
        row['single_p50_us'] = float(np.percentile(t, 50) * 1e6)
        row['single_p99_us'] = float(np.percentile(t, 99) * 1e6)
        row['batch_per_s'] = float(peer.throughput(probes.batch, batch_seconds))
        stage = 'smoothness'
        jumps = []
        for L in probes.lines:
            F = np.asarray(peer.predict(L))
            jumps.append(np.linalg.norm(np.diff(F, axis=0), axis=1).max())
        D = probes.depth_lines
        F = np.asarray(peer.predict(D.reshape(-1, 4))).reshape(D.shape[0], D.shape[1], 3)
        jd = np.linalg.norm(np.diff(F, axis=1), axis=2).max()
        row['max_jump_N'] = float(max(max(jumps) if jumps else 0.0, jd))
        row['max_jump_surface_N'] = float(max(jumps)) if jumps else float('nan')
        row['max_jump_depth_N'] = float(jd)
        mono = np.all(np.diff(F[:, :, 0], axis=1) >= -MONOTONE_TOL_N, axis=1)
        row['fx_monotone_frac'] = float(mono.mean())
        row['curves'] = peer.curves()
        if hasattr(peer, 'detail'):
            row['detail'] = peer.detail
    except Exception as exc:  # a peer that fails is reported, not hidden
        row['status'] = f'failed at {stage}: {type(exc).__name__}: {exc}'.splitlines()[0][:300]
        row['traceback'] = traceback.format_exc()
    finally:
        try:
            peer.close()
        except Exception:  # noqa: BLE001  (closing must not hide the row)
            pass
    return row

"""The report's PNG figures (matplotlib, Agg backend; small files, readable at README width)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..tissue.dataset import OUTPUT_NAMES, ForceDataset
from .targets import HAPTIC_BUDGET_US, PAPER_EVALS_PER_S

try:  # matplotlib: an optional dependency (the 'report' and 'fe' extras); PNG files, no display
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
except ImportError:
    plt = None

DPI = 100


def _plt():
    """matplotlib.pyplot; one line naming the extra when matplotlib is not installed."""
    if plt is None:
        raise ImportError('the report figures need matplotlib (the report extra)')
    return plt


def _save(fig, path: Path) -> str:
    fig.savefig(path, dpi=DPI, bbox_inches='tight')
    _plt().close(fig)
    return path.name


def _chosen(res: dict[str, Any]) -> dict[str, Any] | None:
    ok = [r for r in res['rows'] if r['status'] == 'ok' and r.get('ours')]
    return ok[0] if ok else None


def _best_peer(res: dict[str, Any]) -> dict[str, Any] | None:
    ok = [r for r in res['rows'] if r['status'] == 'ok' and not r.get('ours')]
    return min(ok, key=lambda r: r['rmse_vec']) if ok else None


def speed_vs_error(res: dict[str, Any], path: Path) -> str:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    ok = [r for r in res['rows'] if r['status'] == 'ok']
    for r in ok:
        colour = 'tab:blue' if r.get('ours') else 'tab:orange'
        marker = 'o' if r.get('ours') else 's'
        ax.scatter(r['single_p50_us'], r['rmse_vec'], c=colour, marker=marker, s=45, zorder=3,
                   edgecolors='k' if r.get('pareto') else 'none', linewidths=1.2)
        ax.errorbar(r['single_p50_us'], r['rmse_vec'],
                    xerr=[[0], [max(r['single_p99_us'] - r['single_p50_us'], 0)]],
                    color=colour, alpha=0.35, capsize=0, zorder=2)
        ax.annotate(r['name'].replace('ours: ', '').replace('ours ', ''),
                    (r['single_p50_us'], r['rmse_vec']), textcoords='offset points', xytext=(5, 4),
                    fontsize=7.5)
    front = sorted((r for r in ok if r.get('pareto')), key=lambda r: r['single_p50_us'])
    if len(front) > 1:
        ax.step([r['single_p50_us'] for r in front], [r['rmse_vec'] for r in front], where='post',
                color='k', lw=0.8, ls='--', label='Pareto front', zorder=1)
    ax.axvline(HAPTIC_BUDGET_US, color='tab:red', lw=1, label='haptic budget: 1 ms per loop (1 kHz)')
    ax.axvline(1e6 / PAPER_EVALS_PER_S, color='tab:green', lw=1, ls=':',
               label='paper: 1e5 evaluations/s (10 µs each)')
    fe = res['fe']
    if fe['seconds_per_point'] is not None:
        ax.axvline(fe['seconds_per_point'] * 1e6, color='0.4', lw=1, ls='-.',
                   label=f'FE solve: {fe["seconds_per_point"]:.3g} s per point')
    ax.scatter([], [], c='tab:blue', marker='o', label='ours (ANFIS)')
    ax.scatter([], [], c='tab:orange', marker='s', label='peers')
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.set_xlabel('single-query latency p50 [µs] (bar to p99), log')
    ax.set_ylabel('test RMS force-vector error [N], log')
    title = 'Speed against error on held-out surface points'
    if 'SYNTHETIC' in str(res['dataset']['kind']).upper():
        title += ' (synthetic placeholder data)'
    ax.set_title(title, fontsize=10)
    ax.grid(True, which='both', alpha=0.25)
    ax.legend(fontsize=7, loc='best', framealpha=0.85)
    return _save(fig, path)


def pred_vs_fe(res: dict[str, Any], test: ForceDataset, path: Path) -> str:
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.5))
    shown = [r for r in (_chosen(res), _best_peer(res)) if r is not None]
    styles = [dict(c='tab:blue', marker='o', s=14), dict(c='tab:orange', marker='x', s=14)]
    for o, ax in enumerate(axes):
        y = test.Y[:, o]
        lo, hi = y.min(), y.max()
        pad = 0.05 * (hi - lo or 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], 'k-', lw=0.8)
        for r, st in zip(shown, styles):
            ax.scatter(y, r['test_pred'][:, o], alpha=0.7, label=f'{r["name"]} '
                       f'(RMSE {r["rmse"][o]:.3g} N)', **st)
        ax.set_title(f'{OUTPUT_NAMES[o]} [N]', fontsize=10)
        ax.set_xlabel('FE (dataset) force [N]')
        ax.legend(fontsize=6.5, loc='upper left')
        ax.grid(alpha=0.25)
    axes[0].set_ylabel('predicted force [N]')
    fig.suptitle(f'Test set: {len(test)} samples at held-out surface points', fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def error_map(res: dict[str, Any], ds: ForceDataset, test: ForceDataset, path: Path) -> str:
    plt = _plt()
    shown = [r for r in (_chosen(res), _best_peer(res)) if r is not None]
    fig, axes = plt.subplots(1, max(len(shown), 1), figsize=(5.2 * max(len(shown), 1), 4.4),
                             squeeze=False)
    ids = np.unique(ds.point)
    yz = np.array([ds.X[ds.point == p][0, 1:3] for p in ids]) * 1e3
    is_test = np.isin(ids, test.point)
    per_pt = []
    for r in shown:
        e2 = np.sum((r['full_pred'] - ds.Y) ** 2, axis=1)
        per_pt.append(np.array([np.sqrt(e2[ds.point == p].mean()) for p in ids]))
    vmax = max((v.max() for v in per_pt), default=1.0)
    tumour = res['dataset'].get('provenance', {}).get('tumour_yz_m')
    for ax, r, err in zip(axes[0], shown, per_pt):
        sc = ax.scatter(yz[~is_test, 0], yz[~is_test, 1], c=err[~is_test], cmap='viridis', vmin=0,
                        vmax=vmax, s=40, label='training point')
        ax.scatter(yz[is_test, 0], yz[is_test, 1], c=err[is_test], cmap='viridis', vmin=0, vmax=vmax,
                   s=90, edgecolors='r', linewidths=1.5, label='test point (held out)')
        if tumour:
            ax.plot(tumour[0] * 1e3, tumour[1] * 1e3, 'r+', ms=14, mew=2, label='tumour (y, z)')
        ax.set_aspect('equal')
        ax.set_xlabel('y [mm]')
        ax.set_ylabel('z [mm]')
        ax.set_title(f'{r["name"]}: RMS |F error| over depths', fontsize=9)
        ax.legend(fontsize=6.5, loc='lower left', framealpha=0.8)
        fig.colorbar(sc, ax=ax, shrink=0.85, label='N')
    fig.tight_layout()
    return _save(fig, path)


def training_curves(res: dict[str, Any], path: Path) -> str:
    plt = _plt()
    r = _chosen(res)
    curves = r['curves'] if r else []
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.3))
    for o, ax in enumerate(axes):
        if o < len(curves) and curves[o].get('train'):
            c = curves[o]
            ep = np.arange(1, len(c['train']) + 1)
            ax.plot(ep, c['train'], label='training')
            if c.get('check'):
                ax.plot(ep, c['check'], label='checking (held-out points)')
                best = int(np.argmin(c['check'])) + 1
                ax.axvline(best, color='k', ls=':', lw=0.8, label=f'kept: epoch {best}')
            ax.set_yscale('log')
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, 'no curve', ha='center', transform=ax.transAxes)
        ax.set_title(f'{OUTPUT_NAMES[o]}' + (f' ({r["detail"].split("/")[o]})' if r and r.get('detail')
                                             else ''), fontsize=10)
        ax.set_xlabel('epoch')
        ax.grid(alpha=0.25)
    axes[0].set_ylabel('RMSE [N]')
    fig.suptitle(f'Training curves: {r["name"] if r else "no model"}', fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def make_all(res: dict[str, Any], ds: ForceDataset, train: ForceDataset, test: ForceDataset,
             out: Path) -> dict[str, str]:
    """Write every figure into ``out``; returns {key: file name}."""
    return {
        'speed_vs_error': speed_vs_error(res, out / 'speed_vs_error.png'),
        'pred_vs_fe': pred_vs_fe(res, test, out / 'pred_vs_fe.png'),
        'error_map': error_map(res, ds, test, out / 'error_map.png'),
        'training_curves': training_curves(res, out / 'training_curves.png'),
    }

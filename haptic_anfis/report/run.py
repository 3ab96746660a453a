"""Build the speed-against-error report: every model on the same split, one run, one Markdown file
plus PNG figures. ``haptic-anfis report`` and ``bench/bench_report.py`` call :func:`build_report`.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._version import __version__
from ..tissue.dataset import DATA_DIR, ForceDataset, INPUT_NAMES, OUTPUT_NAMES, split_indices
from . import figures
from .contact import contact_onset
from .cv import format_cv_table, group_cv
from .measure import (JUMP_STEP_M, MONOTONE_TOL_N, data_jump_scale, make_probes, measure)
from .peers import LinearPeer, MlpPeer, OursPeer, Peer, RbfPeer, default_peers
from .targets import HAPTIC_BUDGET_US, PAPER_EVALS_PER_S, PAPER_RMSE_N  # noqa: F401 (re-exported)


#: Plain-form (the paper's F = ANFIS(x, y, z, depth)) structures the report also trains.
FULL_STRUCTURES: tuple[tuple[int, ...], ...] = ((3, 3, 3, 2), (4, 4, 4, 2))
QUICK_STRUCTURES: tuple[tuple[int, ...], ...] = ((2, 2, 2, 2),)
def shipped_params(path: str | os.PathLike | None = None) -> dict[str, Any]:
    """ForceModel keyword arguments that retrain the shipped default model (or the model file at
    ``path``): read from the hyper-parameters the file records (its form, inputs, per-output
    structures, extrapolation band, ridge, epochs, validation split), so that the report measures
    exactly what the force server loads (config/force_model.yaml made it: ``haptic-anfis train``)."""
    doc = json.loads(Path(path or DATA_DIR / 'default_model.json').read_text())
    tr = doc.get('training', {})
    form = doc.get('form') or {'name': 'plain', 'inputs': list(INPUT_NAMES)}
    cols = [INPUT_NAMES.index(n) for n in form['inputs']]
    ext = np.zeros(len(INPUT_NAMES))
    ext[cols] = doc['outputs'][0]['extrapolation']
    structures = [tuple(o['structure']) for o in doc['outputs']]
    params: dict[str, Any] = {
        'form': form['name'], 'inputs': tuple(form['inputs']),
        'structure': structures[0] if len(set(structures)) == 1 else structures,
        'extrapolation': tuple(float(v) for v in ext)}
    for key in ('ridge', 'epochs', 'val_fraction', 'split'):
        if key in tr:
            params[key] = tr[key]
    return params


def our_models(quick: bool, seed: int = 0,
               structures: Sequence[tuple[int, ...]] | None = None) -> list[OursPeer]:
    """The shipped default first (its hyper-parameters read from the model file, see
    :func:`shipped_params`), the depth-scaled structure search, then plain-form fixed structures
    (the paper's 3-3-3-2 and 4-4-4-2)."""
    if structures is None:
        structures = QUICK_STRUCTURES if quick else FULL_STRUCTURES
    kw: dict[str, Any] = {'seed': seed}
    if quick:
        kw.update(epochs=8)
        default = OursPeer((3, 3, 2), **kw)
        search = OursPeer(None, search_epochs=4, max_mfs=(3, 2, 2), **kw)
    else:
        sp = shipped_params()
        default = OursPeer(sp.pop('structure'), **sp, **kw)
        default.name += ' (shipped)'
        search = OursPeer(None, **kw)
    return [default, search, *(OursPeer(tuple(s), form='plain', **kw) for s in structures)]


def cv_models(quick: bool) -> dict[str, Any]:
    """``name -> (seed -> model)`` of the grouped-CV table: the shipped default and the paper's
    plain form, and the best plain peers (compiled MLP has the MLP's errors, so it is not
    repeated)."""
    if quick:
        return {'ours depth·g 3-3-2': lambda s: OursPeer((3, 3, 2), epochs=5, seed=s),
                'RBF (thin plate spline)': lambda s: RbfPeer(),
                'linear regression': lambda s: LinearPeer()}
    sp = shipped_params()
    st = sp.pop('structure')
    name = OursPeer(st, **sp).name + ' (shipped)'
    return {name: lambda s: OursPeer(st, seed=s, **sp),
            'ours plain 3-3-3-2 (paper)': lambda s: OursPeer((3, 3, 3, 2), form='plain', seed=s),
            'RBF (thin plate spline)': lambda s: RbfPeer(),
            'MLP 32-32 (tanh)': lambda s: MlpPeer((32, 32), seed=s),
            'linear regression': lambda s: LinearPeer()}


def fe_cost(provenance: dict[str, Any]) -> dict[str, Any]:
    """Seconds of FE computation per surface point (all depths, one load path) from the dataset's
    provenance sidecar, or why it is not available."""
    kind = str(provenance.get('kind', 'unknown'))
    wt = provenance.get('wall_time_s')
    n = provenance.get('n_points')
    if 'SYNTHETIC' in kind.upper() or 'PLACEHOLDER' in kind.upper():
        return {'seconds_per_point': None, 'why': 'n/a: the dataset is the synthetic placeholder '
                '(closed-form forces, no FE solve was timed)'}
    total = wt.get('sum_over_points') if isinstance(wt, dict) else wt
    if isinstance(total, (int, float)) and isinstance(n, int) and n > 0:
        return {'seconds_per_point': float(total) / n,
                'why': f'from the sidecar: wall_time_s.sum_over_points / n_points = {total:.0f} s / {n}'}
    return {'seconds_per_point': None, 'why': f'n/a: the sidecar (kind {kind!r}) records no FE wall time'}


def pareto_front(latency: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Boolean mask of points no other point beats on both (lower latency and lower error)."""
    n = len(latency)
    keep = np.ones(n, dtype=bool)
    for i in range(n):
        for j in range(n):
            if j != i and latency[j] <= latency[i] and error[j] <= error[i] and (
                    latency[j] < latency[i] or error[j] < error[i]):
                keep[i] = False
                break
    return keep


def build_report(ds: ForceDataset, out_dir: str | os.PathLike, quick: bool = False, seed: int = 0,
                 dataset_label: str = '', peers: Sequence[Peer] | None = None,
                 ours: Sequence[Peer] | None = None, repeats: int | None = None,
                 cv_seeds: Sequence[int] = (0, 1, 2), cv_folds: int = 5,
                 log=print) -> dict[str, Any]:
    """Train and measure every model on one split, then the grouped cross-validation of
    :func:`cv_models` (``cv_seeds`` × ``cv_folds`` folds over surface points; no seeds: skipped);
    write ``report.md``, ``results.json`` and the figures into ``out_dir``. Returns the results
    (rows, split, settings, cv)."""
    t_start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tr_idx, te_idx = split_indices(ds, 0.2, seed, by='point')   # as train_on_dataset does
    train, test = ds.subset(tr_idx), ds.subset(te_idx)
    force_range = ds.Y.max(0) - ds.Y.min(0)
    force_range = np.where(force_range > 0, force_range, 1.0)
    probes = make_probes(ds, n_lines=3 if quick else 8, n_depths=2 if quick else 3,
                         batch=5000 if quick else 100_000, seed=seed)
    repeats = repeats or (300 if quick else 20000)
    peer_repeats = max(100, repeats // 10)
    batch_seconds = 0.05 if quick else 0.3
    models = list(ours) if ours is not None else our_models(quick, seed)
    others = list(peers) if peers is not None else default_peers(quick, seed)
    rows = []
    for m in [*models, *others]:
        log(f'  {getattr(m, "name", m)} ...')
        r = measure(m, train, test, probes, force_range, ds,
                    repeats if isinstance(m, OursPeer) else peer_repeats, batch_seconds)
        r['ours'] = isinstance(m, OursPeer)
        if r['status'] == 'ok':
            try:
                r['contact'] = contact_onset(m, ds)
            except Exception as exc:  # noqa: BLE001 - e.g. a peer whose worker measure() closed
                r['contact_error'] = repr(exc)
            finally:
                m.close()
        log(f'    {r["status"]}' + (f', RMSE {np.round(r["rmse"], 4).tolist()} N, '
                                    f'fit {r["fit_s"]:.1f} s' if r['status'] == 'ok' else ''))
        rows.append(r)
    cv: dict[str, Any] = {}
    for name, make in (cv_models(quick).items() if cv_seeds else ()):
        log(f'  group CV: {name} ...')
        try:
            cv[name] = group_cv(ds, make, folds=cv_folds, seeds=cv_seeds)
        except Exception as exc:  # noqa: BLE001 - a failed peer is listed, not fatal
            log(f'    failed: {exc!r}')
    ok = [r for r in rows if r['status'] == 'ok']
    if ok:
        lat = np.array([r['single_p50_us'] for r in ok])
        err = np.array([r['rmse_vec'] for r in ok])
        for r, p in zip(ok, pareto_front(lat, err)):
            r['pareto'] = bool(p)
    res = {
        'dataset': {'label': dataset_label, 'kind': ds.provenance.get('kind', 'unknown'),
                    'sha256': ds.sha256(), 'n_samples': len(ds),
                    'n_points': int(len(np.unique(ds.point))),
                    'provenance': {k: ds.provenance.get(k) for k in ('tumour_yz_m',)
                                   if k in ds.provenance}},
        'split': {'by': 'point', 'test_fraction': 0.2, 'seed': seed,
                  'n_train': len(train), 'n_test': len(test),
                  'test_points': [int(p) for p in np.unique(test.point)]},
        'force_range_N': force_range.tolist(),
        'fe': fe_cost(ds.provenance),
        'probes': probes.summary, 'data_jump_N': data_jump_scale(ds),
        'quick': quick, 'repeats': {'ours': repeats, 'peers': peer_repeats},
        'machine': {'python': platform.python_version(), 'cpu_count': os.cpu_count(),
                    'platform': platform.platform(), 'numpy': np.__version__},
        'software_version': __version__,
        'created_utc': _dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds'),
        'rows': rows,
        'cv': cv,
    }
    res['figures'] = figures.make_all(res, ds, train, test, out)
    res['seconds'] = time.perf_counter() - t_start
    (out / 'report.md').write_text(format_markdown(res))
    (out / 'results.json').write_text(json.dumps(_jsonable(res), indent=1) + '\n')
    return res


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()
                if k not in ('test_pred', 'full_pred', 'traceback')}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


# ---- Markdown -------------------------------------------------------------------------------
def _f(v: float, digits: int = 3) -> str:
    return f'{v:.{digits}g}'


def headline_table(res: dict[str, Any]) -> str:
    """The one table: every model, same split, measured in this run."""
    head = ('| model | test RMSE Fx / Fy / Fz [N] | RMSE / force range [%] | max error Fx / Fy / Fz [N] '
            '| fit [s] | single query p50 / p99 [µs] | batch [eval/s] | max jump per 0.1 mm [N] '
            '| Fx grows with depth [% points] |')
    lines = [head, '|' + '---|' * 9]
    for r in res['rows']:
        name = f'**{r["name"]}**' if r.get('pareto') else r['name']
        if r.get('detail'):
            name += f' ({r["detail"]})'
        if r['status'] != 'ok':
            lines.append(f'| {name} | **{r["status"]}** | – | – | – | – | – | – | – |')
            continue
        rm, rel, mx = r['rmse'], 100 * np.asarray(r['rel_rmse']), r['max_err']
        lines.append(
            f'| {name} | {" / ".join(_f(v) for v in rm)} | {" / ".join(f"{v:.2f}" for v in rel)} '
            f'| {" / ".join(_f(v) for v in mx)} | {r["fit_s"]:.2f} '
            f'| {r["single_p50_us"]:.3g} / {r["single_p99_us"]:.3g} | {r["batch_per_s"]:.2g} '
            f'| {r["max_jump_N"]:.3g} | {100 * r["fx_monotone_frac"]:.0f} |')
    fe = res['fe']
    fe_cell = (f'{fe["seconds_per_point"]:.3g} s per surface point (all depths)'
               if fe['seconds_per_point'] is not None else fe['why'])
    lines.append(f'| FE model (the data itself) | 0 (reference) | 0 | 0 | – | {fe_cell} | – | – | – |')
    p = PAPER_RMSE_N
    lines.append(f'| paper (MATLAB, **its own FE data, not this data**) | {p[0]} / {p[1]} / {p[2]} '
                 f'| – | – | – | – | ~1e5 | – | – |')
    lines.append(f'| haptic budget (1 kHz loop) | – | – | – | – | {HAPTIC_BUDGET_US:.0f} per loop, '
                 'contact + force + I/O | ≥ 1e3 | – | – |')
    return '\n'.join(lines)


def cv_section(res: dict[str, Any]) -> list[str]:
    """Markdown lines of the grouped cross-validation table (empty when it was skipped)."""
    cv = res.get('cv') or {}
    if not cv:
        return []
    first = next(iter(cv.values()))
    return ['## Grouped cross-validation', '',
            f'{first["folds"]}-fold cross-validation over surface points (every depth of a point in '
            f'the same fold), seeds {first["seeds"]}: out-of-fold RMSE over the whole dataset per '
            'seed, mean ± std over the seeds (bold: best per axis). A steadier measure than the '
            'single split above, whose ~30 test points decide its ranking.', '',
            format_cv_table(cv), '']


def contact_section(res: dict[str, Any]) -> list[str]:
    """Markdown lines of the contact-onset check (see :mod:`.contact`)."""
    rows = [r for r in res['rows'] if r['status'] == 'ok' and 'contact' in r]
    if not rows:
        return []
    c0 = rows[0]['contact']
    L = ['## Contact onset', '',
         f'At the {c0["n_points"]} surface points of the data: the largest |F| at depth 0 (a force '
         f'step when contact begins), the largest |F|/ε at ε = {c0["eps_m"] * 1e3:.1f} mm, and the '
         'lowest force component along the outward surface normal for depths 0 to '
         f'{c0["depth_max_m"] * 1e3:.0f} mm (negative: the model pulls the probe into the tissue).',
         '', r'| model | max \|F(0)\| [N] | max \|F(ε)\|/ε [N/m] | min F·n [N] | points pulling in |',
         '|---|---|---|---|---|']
    for r in rows:
        c = r['contact']
        L.append(f'| {r["name"]} | {c["max_force_at_zero_N"]:.3g} | '
                 f'{c["max_slope_at_eps_N_per_m"]:.3g} | {c["min_normal_force_N"]:.3g} | '
                 f'{c["n_points_pulling"]} / {c["n_points"]} |')
    return L + ['']


def format_markdown(res: dict[str, Any]) -> str:
    d, s = res['dataset'], res['split']
    rng = res['force_range_N']
    pr = res['probes']
    failed = [r for r in res['rows'] if r['status'] != 'ok']
    ok = [r for r in res['rows'] if r['status'] == 'ok']
    L = [f'# Speed against error: the force model among the alternatives',
         '',
         f'Generated by `haptic-anfis report{" --quick" if res["quick"] else ""}` '
         f'({res["created_utc"]}, haptic_anfis {res["software_version"]}, {res["seconds"]:.0f} s). '
         'Every number below was measured in this run.',
         '',
         f'- **Data**: {d["label"] or "dataset"} — {d["n_samples"]} samples at {d["n_points"]} surface '
         f'points; kind: *{d["kind"]}*; sha256 `{d["sha256"][:16]}…`.',
         f'- **Split**: the same for every model — `split_indices(by="point", fraction=0.2, '
         f'seed={s["seed"]})` as `train_on_dataset` uses: {s["n_train"]} training samples, '
         f'{s["n_test"]} test samples at {len(s["test_points"])} surface points never seen in '
         'training. Ours choose the structure by 3-fold validation over the training points and the '
         'epoch on a 20 % hold-out of them.',
         f'- **Force range** (max − min over the data): Fx {rng[0]:.3g} N, Fy {rng[1]:.3g} N, '
         f'Fz {rng[2]:.3g} N.',
         f'- **Machine**: Python {res["machine"]["python"]}, {res["machine"]["cpu_count"]} cores '
         f'(shared; timings are wall clock, p50/p99 of {res["repeats"]["ours"]} calls for ours, '
         f'{res["repeats"]["peers"]} for peers).',
         '',
         '## Headline table',
         '',
         headline_table(res),
         '',
         *cv_section(res),
         *contact_section(res),
         'Bold: on the Pareto front of single-query p50 latency against RMS force-vector error '
         '(no other model is both faster and more accurate). *Single query* is the real-time path each '
         'model offers: ours `ForceModel.predict_one` (numba, packed parameter arrays), every peer its '
         '`predict` on one (1, 4) row; xanfis is timed inside its own process. *Batch*: ours '
         '`predict` (compiled), peers `predict`, on random surface inputs.',
         '',
         f'**Smoothness.** *Max jump*: the largest change of the force vector between neighbouring '
         f'inputs {JUMP_STEP_M * 1e3:.1f} mm apart, over {pr["n_lines"]} lines along y and z across '
         f'the surface (at depths {", ".join(f"{1e3 * v:.1f}" for v in pr["depths_m"])} mm; contact '
         f'points kept on the surface by interpolating x from the data\'s surface points) and along '
         f'depth at all {pr["n_depth_lines"]} surface points. For scale, the data\'s own steepest '
         f'slope is {res["data_jump_N"]:.3g} N per 0.1 mm. *Fx grows with depth*: the share of '
         f'surface points where predicted Fx never decreases (tolerance {MONOTONE_TOL_N:g} N) from '
         'the shallowest to the deepest sampled depth.',
         '',
         f'**FE model**: {res["fe"]["why"]}.',
         '',
         '**Paper**: Amirkhani & Nahvi report test RMSE 0.0791 / 0.0063 / 0.0181 N and >1e5 '
         'evaluations/s, on their own FE data (glandular tissue with tumour, 765 samples): shown for '
         'scale only, not comparable number for number.',
         '']
    if failed:
        L += ['## Models that failed', '']
        L += [f'- **{r["name"]}** ({r["family"]}): {r["status"]}' for r in failed]
        L += ['']
    L += ['## Figures', '']
    captions = {
        'speed_vs_error': 'Speed against error: single-query latency (p50, log) against RMS '
                          'force-vector error on the test points; Pareto front joined.',
        'pred_vs_fe': 'Predicted against FE (dataset) force for the test set, per output '
                      '(the paper\'s Figure 11).',
        'error_map': 'Error over the surface (y-z plane): RMS force-vector error over the depths '
                     'of each surface point; ringed points are held-out test points.',
        'training_curves': 'Training and checking RMSE per epoch of our searched model (the epoch '
                           'kept is marked).',
    }
    for key, fname in res['figures'].items():
        L += [f'![{key}]({fname})', '', captions.get(key, key), '']
    L += ['## Models', '']
    for r in res['rows']:
        L.append(f'- **{r["name"]}** — {r["family"]}; real-time path: {r["realtime_path"]}.')
    L += ['', 'Reproduce: `haptic-anfis report --out DIR [--dataset CSV] [--quick]` '
          '(or `make bench`, which writes `out/report/`).', '']
    if ok:
        best = min(ok, key=lambda r: r['rmse_vec'])
        fast = min(ok, key=lambda r: r['single_p50_us'])
        L += ['## In one line', '',
              f'Most accurate here: {best["name"]} (RMS vector error {best["rmse_vec"]:.3g} N); '
              f'fastest single query: {fast["name"]} ({fast["single_p50_us"]:.3g} µs p50).', '']
    return '\n'.join(L)

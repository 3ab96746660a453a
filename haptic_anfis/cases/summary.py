"""What ``haptic-anfis cases list`` shows for a case: lesions, size, data, model, errors, speed,
and each lesion's contrast (FE against model).

Lesion contrast: the normal force Fx at 8 mm depth with the probe over the lesion
centre, relative to the mirror point (-y, -z) of the symmetric dome: ``F_over / F_mirror - 1``.
The loading points include both points (:func:`haptic_anfis.tissue.geometry.loading_points`), so
the FE contrast is read from the dataset; the model's from the model at the same two inputs. The
bar: the model's contrast within 25 % (relative) of the FE's.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..anfis import ForceModel
from ..anfis.timing import percentiles_us, time_calls
from ..tissue.dataset import ForceDataset, load_dataset
from ..tissue.scene import surface_height
from .background import summary_fields
from .force_mapping import case_force_mapping
from .library import Case
from .sweeps import case_stores, store_status

CONTRAST_DEPTH = 0.008  # [m]
CONTRAST_TOLERANCE = 0.25  # relative


def lesion_rows(case: Case, threshold_pct: float | None = None) -> list[dict[str, Any]]:
    """Lesions of the case in the listing's units (mm, kPa), with the FE grading of a graded case
    at ``threshold_pct`` [%] (None: as stored): ``contrast_n``, ``contrast_pct`` (at the depth it
    is found, else its largest), ``palpable``, ``difficulty``, ``found_level``,
    ``found_depth_mm``, ``reason``; None when not graded."""
    out = []
    graded = {g['lesion']: g for g in ((case.grading(threshold_pct) or {}).get('lesions') or [])}
    for t in case.scene.tumours:

        skin = float(surface_height(np.array(t.centre[1]), np.array(t.centre[2]), case.scene.radii))
        out.append({'name': t.name, 'kind': t.kind or 'unstated',
                    'center_mm': [round(c * 1e3, 3) for c in t.centre],
                    'depth_mm': round((skin - t.centre[0]) * 1e3, 3),
                    'radius_mm': round(t.radius * 1e3, 3), 'modulus_kpa': round(t.youngs / 1e3, 3)})
        g = graded.get(t.name, {})
        out[-1].update({k: g.get(k) for k in ('contrast_n', 'contrast_pct', 'palpable',
                                              'difficulty', 'found_level', 'reason')})
        found = g.get('found_depth_m')
        out[-1]['found_depth_mm'] = None if found is None else round(found * 1e3, 3)
    return out


def _fe_force(ds: ForceDataset, yz: tuple[float, float], depth: float) -> float | None:
    sel = (np.abs(ds.X[:, 1] - yz[0]) < 1e-6) & (np.abs(ds.X[:, 2] - yz[1]) < 1e-6) \
        & (np.abs(ds.X[:, 3] - depth) < 1e-9)
    return float(ds.Y[sel, 0][0]) if sel.any() else None


def lesion_contrast(case: Case, model, ds: ForceDataset, depth: float = CONTRAST_DEPTH
                    ) -> list[dict[str, Any]]:
    """Per lesion: FE and model Fx over the centre and at the mirror point, both contrasts, and
    whether the model's is within ``CONTRAST_TOLERANCE`` of the FE's. Without a loading point
    over the centre (a scene without refinement) the nearest one with a mirror point is used
    (``over_yz_mm``)."""
    scene = case.scene
    rows = []
    yz = np.unique(np.round(ds.X[:, 1:3], 9), axis=0)
    for t in scene.tumours:
        # over the centre (a refined case has a loading point there), else over the nearest
        # loading point whose mirror point is in the data too (the default scene's grid)
        d = np.hypot(yz[:, 0] - t.centre[1], yz[:, 1] - t.centre[2])
        has_mirror = np.array([np.any(np.hypot(*(yz + q).T) < 1e-6) for q in yz])
        d[~has_mirror] = np.inf
        k = int(np.argmin(d))
        over = ((float(yz[k, 0]), float(yz[k, 1])) if np.isfinite(d[k])
                else (t.centre[1], t.centre[2]))
        mirror = (-over[0], -over[1])
        X = np.array([[float(surface_height(np.array(q[0]), np.array(q[1]), scene.radii)), *q,
                       depth] for q in (over, mirror)])
        m_over, m_mirror = model.predict(X)[:, 0]
        f_over, f_mirror = _fe_force(ds, over, depth), _fe_force(ds, mirror, depth)
        row = {'lesion': t.name, 'over_yz_mm': [round(1e3 * v, 3) for v in over],
               'model_over_n': float(m_over), 'model_mirror_n': float(m_mirror),
               'model_contrast': float(m_over / m_mirror - 1.0), 'fe_over_n': f_over,
               'fe_mirror_n': f_mirror, 'fe_contrast': None, 'contrast_error': None, 'ok': None}
        if f_over is not None and f_mirror is not None:
            fe = f_over / f_mirror - 1.0
            row['fe_contrast'] = fe
            if abs(fe) > 1e-12:
                row['contrast_error'] = row['model_contrast'] / fe - 1.0
                row['ok'] = abs(row['contrast_error']) <= CONTRAST_TOLERANCE
        rows.append(row)
    return rows


def eval_p50_us(model, ds: ForceDataset, n: int = 2000, seed: int = 0) -> float:
    """Median time [µs] of one compiled ``predict_one`` call over the dataset's input box."""
    rng = np.random.default_rng(seed)
    lo, hi = ds.X.min(0), ds.X.max(0)
    q = [tuple(float(v) for v in row) for row in lo + rng.random((200, 4)) * (hi - lo)]
    model.predict_one(*q[0])
    return percentiles_us(time_calls(model.predict_one, q, n))[0]


def case_summary(case: Case, timing: bool = True, contrast: bool = True,
                 threshold_pct: float | None = None) -> dict[str, Any]:
    """One row of ``cases list`` (also its ``--json`` object). Model fields are None while the
    case has no model; dataset fields None while it has no dataset. ``threshold_pct``: grade
    the lesions at this palpability threshold [%] (None: the stored grading)."""
    scene = case.scene
    row: dict[str, Any] = {
        'name': case.name, 'description': case.description,
        'lesions': lesion_rows(case, threshold_pct), 'threshold_pct': threshold_pct,
        'breast_radii_mm': [round(r * 1e3, 3) for r in scene.radii],
        'glandular_kpa': round(scene.material.youngs / 1e3, 3),
        'dataset_path': str(case.dataset_path), 'model_path': str(case.model_path),
        'mesh_path': str(case.mesh_path), 'mesh_unit': 'mm', 'scene_path': str(case.scene_path),
        'missing': case.missing(), 'scene_changed': case.scene_changed(), 'dataset_rows': None,
        'dataset_points': None,
        'fe_probe_cells': None, 'structures': None, 'rules': None, 'rules_per_output': None,
        'parameters': None, 'rmse_n': None, 'rmse_pct_range': None, 'eval_p50_us': None,
        'contrast': None, 'level': case.level_at(threshold_pct),
        'below_device': case.below_device_at(threshold_pct), 'cv_rmse_n': None,
        'cv_pct_range': None,
        'fe_points': _store_progress(case)}
    row.update(summary_fields(scene, None))
    ds = None
    row['force_mapping'] = None
    if case.dataset_path.is_file():
        ds = load_dataset(case.dataset_path)
        row['force_mapping'] = case_force_mapping(case).as_dict()
        row.update(summary_fields(scene, (ds.provenance.get('grading') or {}).get('background')))
        row['dataset_rows'] = len(ds)
        row['dataset_points'] = int(len(np.unique(ds.point)))
        row['fe_probe_cells'] = ds.provenance.get('mesh', {}).get('probe_cells')
        cv = ds.provenance.get('grouped_cv') or {}
        row['cv_rmse_n'], row['cv_pct_range'] = cv.get('rmse_n'), cv.get('pct_range')
    if case.model_path.is_file():
        model = ForceModel.load(case.model_path)
        row['structures'] = ['-'.join(map(str, s)) for s in model.structures_]
        row['rules_per_output'] = [e.n_rules_ for e in model.estimators_]
        row['rules'] = int(sum(row['rules_per_output']))
        row['parameters'] = int(sum(e.n_params_ for e in model.estimators_))
        test = model.metadata_.get('rmse', {}).get('test')
        if test and all(v is not None for v in test):
            row['rmse_n'] = [float(v) for v in test]
            if ds is not None:
                span = ds.Y.max(0) - ds.Y.min(0)
                row['rmse_pct_range'] = [float(100.0 * v / s) for v, s in zip(test, span)]
        if ds is not None and timing:
            row['eval_p50_us'] = eval_p50_us(model, ds)
        if ds is not None and contrast:
            row['contrast'] = lesion_contrast(case, model, ds)
    return row


def _store_progress(case: Case) -> dict[str, int] | None:
    """{'solved', 'total', 'failed'} FE points of a graded-library case in the committed store
    (None for a case whose scene is not graded, i.e. not swept per point: ``Scene.graded``)."""
    if not case.scene.graded:
        return None

    try:
        st = store_status(case_stores(case), with_partial=False)  # counts only: no file reads
    except ValueError:  # a store of another scene version: the listing still works
        return None
    return {'solved': st.solved, 'total': st.total, 'failed': len(st.failed)}


def _lesion_text(l: dict[str, Any]) -> str:
    """'m25mm@15' plus, when graded, ' +42.3%/2.45N d2@5' (the contrast where it is found, its
    difficulty, the depth [mm] it is first palpable at) or ' +12.1% bd' (below what this device
    renders: its largest contrast)."""
    text = f'{l["kind"][0]}{2 * l["radius_mm"]:g}mm@{l["depth_mm"]:.0f}'
    if l.get('contrast_pct') is not None:
        text += (f' {l["contrast_pct"]:+.1f}%/{l["contrast_n"]:.2f}N '
                 + (f'd{l["difficulty"]}@{l["found_depth_mm"]:g}' if l['palpable'] else 'bd'))
    return text


def _scale_text(m: dict[str, Any] | None) -> str:
    """'x0.43' (the force scale), '-' without a dataset."""
    return '-' if not m else f'x{m["force_scale"]:.2f}'


def format_table(rows: list[dict[str, Any]]) -> str:
    """The human-readable listing."""
    head = (f'{"case":<24} {"lvl":>3} {"lesions":<30} {"breast mm":<10} {"E kPa":>5} {"rows":>5} '
            f'{"structure Fx/Fy/Fz":<24} {"rules":>5} {"params":>6} '
            f'{"test RMSE N (% range) Fx, Fy, Fz":<42} {"CV % range":<16} {"p50 µs":>6} '
            f'{"force":>6} {"background":<28} {"ribs":>4}')
    lines = [head, '-' * len(head)]
    for r in rows:
        les = ', '.join(_lesion_text(l) for l in r['lesions']) or 'none'
        lvl = 'bd' if r.get('below_device') else '-' if r.get('level') is None else str(r['level'])
        cv = ('/'.join(f'{v:.2f}' for v in r['cv_pct_range']) if r.get('cv_pct_range') else
              (f'FE {r["fe_points"]["solved"]}/{r["fe_points"]["total"]}'
               if r.get('fe_points') and not r['structures'] else '-'))
        size = 'x'.join(f'{v:g}' for v in r['breast_radii_mm'])
        st = ('(scene changed)' if r.get('scene_changed') else
              '/'.join(r['structures']) if r['structures'] else '(no model)')
        err = (', '.join(f'{v:.3f} ({p:.1f}%)' for v, p in zip(r['rmse_n'], r['rmse_pct_range']))
               if r['rmse_n'] and r['rmse_pct_range'] else '-')
        lines.append(f'{r["name"]:<24} {lvl:>3} {les:<30} {size:<10} {r["glandular_kpa"]:>5g} '
                     f'{r["dataset_rows"] or "-":>5} {st:<24} {r["rules"] or "-":>5} '
                     f'{r["parameters"] or "-":>6} {err:<42} {cv:<16} '
                     f'{"-" if r["eval_p50_us"] is None else format(r["eval_p50_us"], ".2f"):>6} '
                     f'{_scale_text(r.get("force_mapping")):>6} '
                     f'{r.get("background", "smooth"):<28} {r.get("ribs", 0):>4}')
    lines.append('lesions: kind (m = malignant, b = benign, u = unstated), diameter @ centre depth '
                 'under the skin [mm]; graded cases add the FE contrast vs the lesion-free twin '
                 '(% / N) at the shallowest depth a stylus can feel it, the difficulty dN and '
                 'that depth @mm (bd = below what this device renders: its largest contrast); '
                 'lvl: case '
                 'level 1-5 (bd: every lesion below what this device renders: no level); CV % range: grouped-CV RMSE Fx/Fy/Fz (or FE points solved so far); '
                 '(scene changed): the scene file was edited since the case was generated '
                 '(not ready until `cases generate NAME`); force: the tissue -> device force '
                 'scale a session of the case renders (its largest FE force at the deepest '
                 'trained depth at 85 % of the clamp; --json: force_mapping); background: smooth, '
                 'or nodular with its nodule count and (once graded) their contrast range over the '
                 'smooth breast at the deep level; ribs: ribs under the breast')
    return '\n'.join(lines)


def format_markdown(rows: list[dict[str, Any]]) -> str:
    """The README's table: rules per case and each lesion's contrast, FE against model."""
    out = ['| case | lesions | breast (mm) | E (kPa) | FE points (rows) | structure Fx / Fy / Fz '
           '| rules | params | test RMSE N (% of range) | contrast at 8 mm: FE → model |',
           '|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        les = ', '.join(f'{l["kind"]} {2 * l["radius_mm"]:g} mm @ {l["depth_mm"]:.0f} mm'
                        for l in r['lesions']) or 'none'
        if not r['structures']:
            out.append(f'| {r["name"]} | {les} | {"×".join(f"{v:g}" for v in r["breast_radii_mm"])} '
                       f'| {r["glandular_kpa"]:g} | not generated | | | | | |')
            continue
        err = ', '.join(f'{v:.3f} ({p:.1f})' for v, p in zip(r['rmse_n'], r['rmse_pct_range'] or []))
        con = '; '.join(
            f'{c["lesion"]}: {100 * c["fe_contrast"]:+.1f} % → {100 * c["model_contrast"]:+.1f} % '
            f'({"ok" if c["ok"] else "FAIL"})' if c['fe_contrast'] is not None else
            f'{c["lesion"]}: model {100 * c["model_contrast"]:+.1f} % (no FE point)'
            for c in (r['contrast'] or [])) or '–'
        out.append(f'| {r["name"]} | {les} | {"×".join(f"{v:g}" for v in r["breast_radii_mm"])} '
                   f'| {r["glandular_kpa"]:g} | {r["dataset_points"]} ({r["dataset_rows"]}) '
                   f'| {" / ".join(r["structures"])} | {r["rules"]} | {r["parameters"]} | {err} '
                   f'| {con} |')
    return '\n'.join(out)

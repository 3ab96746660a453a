"""Build a graded case from its complete FE store: dataset, dent, grading, model, gates, ship.

Order (nothing is written into the package until every check passed):

1. the case's and its twin's points from the store (:func:`.sweeps.stored_records`; a missing or
   failed point refuses the case, naming it);
2. the force dataset and the skin displacement file of the same solves (the displacement file's
   ``dataset_sha256`` ties them; the model records the dataset's hash, as for every case);
3. grading (:mod:`.grading`): contrast per depth, palpable, the pressure level it is found at,
   difficulty per lesion; the case level;
4. the model, trained as every case's (``config/case_model.yaml``), then grouped cross-validation
   by loading point (5 folds x 3 seeds, the model's own structures refitted);
5. gates (:func:`gate_failures`): grouped-CV RMSE <= 1 % of the force range on every axis and
   <= 1/3 of each palpable lesion's contrast (its largest at a depth where it is palpable);
   shipped files <= 1 MB (forces as float32
   decimals, displacement harmonics in 1 µm steps, 2 or 4 µm where 1 µm would not fit, float32,
   compressed). A failed gate raises
   :class:`~.library.CaseError` naming the figure.

Pure Python, no ROS.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..anfis import ForceModel, train_on_dataset
from ..anfis.force_model import INPUT_NAMES
from ..report.cv import group_cv
from ..tissue.dataset import save_dataset, sidecar_path
from ..tissue.displacement import displacement_path, displacements_from_records, save_displacements
from ..tissue.sweep import records_to_dataset
from .background import background_gate_failures, background_grades
from .generate import _package_relative, write_case_mesh
from .grading import PALPABLE_PCT, case_level, grading_record, lesion_grades
from .library import Case, CaseError
from .reference import smooth_reference
from .sweeps import case_stores, stored_records

__all__ = ['RANGE_GATE_PCT', 'CONTRAST_GATE', 'SIZE_GATE_BYTES', 'BuildResult', 'build_case',
           'gate_failures', 'grouped_cv', 'regrade_case']

RANGE_GATE_PCT = 1.0        # grouped-CV RMSE per axis, % of that axis's force range
CONTRAST_GATE = 1.0 / 3.0   # grouped-CV RMSE (vector norm) as a fraction of a lesion's contrast
SIZE_GATE_BYTES = 1 << 20   # shipped dataset + sidecar + displacement file + model
#: [m] the steps shipped skin-displacement harmonics are rounded to: the finest that keeps the
#: case's files within :data:`SIZE_GATE_BYTES` (a denser loading grid has more profiles); all
#: are far below what the dent display resolves (a dent of millimetres on a screen)
DISPLACEMENT_QUANTA = (1e-6, 2e-6, 4e-6)
CV_FOLDS = 5
CV_SEEDS = (0, 1, 2)


@dataclass
class BuildResult:
    """What :func:`build_case` found and wrote."""

    case: str
    level: int | None = 1   # None: every lesion below what the device renders
    grades: list[dict[str, Any]] = field(default_factory=list)
    cv_rmse_n: list[float] = field(default_factory=list)
    cv_pct_range: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    written: list[str] = field(default_factory=list)
    bytes: int = 0
    train_s: float = 0.0
    cv_s: float = 0.0


def grouped_cv(ds, model, params: dict[str, Any], folds: int = CV_FOLDS,
               seeds: Sequence[int] = CV_SEEDS) -> np.ndarray:
    """(3,) mean over seeds of the out-of-fold RMSE [N] per axis, refitting ``model``'s own
    inputs and structures (no structure search, no input check) with ``params`` (:func:`haptic_anfis.report.cv.group_cv`)."""
    p = {k: v for k, v in params.items() if k not in ('test_fraction', 'seed', 'candidates',
                                                        'tol', 'structure', 'inputs',
                                                        'ridge_candidates')}
    structures = [tuple(s) for s in model.structures_]
    # the ridge the search chose with each structure (one per output)
    p['ridge'] = list(model.ridges_)
    # the model's own inputs too: 'auto' decided on a fold may keep an input it dropped
    p['inputs'] = tuple(INPUT_NAMES[c] for c in model.input_cols_)
    res = group_cv(ds, lambda seed: ForceModel(structure=structures, seed=seed, **p),
                   folds=folds, seeds=seeds)
    return np.asarray(res['mean'], dtype=float)


def gate_failures(cv_rmse: np.ndarray, span: np.ndarray, grades: Sequence[dict[str, Any]]
                  ) -> list[str]:
    """One message per missed figure (empty when the case may ship)."""
    out = []
    for a, name in enumerate(('Fx', 'Fy', 'Fz')):
        pct = 100.0 * cv_rmse[a] / span[a] if span[a] > 0 else np.inf
        if pct > RANGE_GATE_PCT:
            out.append(f'{name} grouped-CV RMSE {cv_rmse[a]:.4f} N is {pct:.2f} % of its range '
                       f'({span[a]:.2f} N), above {RANGE_GATE_PCT:g} %')
    norm = float(np.linalg.norm(cv_rmse))
    for g in grades:
        if not g['palpable']:
            continue
        # its strongest contrast where a stylus feels it (the grading's per-depth figures)
        rows = [r for r in g.get('contrasts') or ()
                if r['contrast_pct'] >= g.get('threshold_pct', 0.0)]
        c = max(r['contrast_n'] for r in rows) if rows else g['contrast_n']
        if norm > CONTRAST_GATE * c:
            out.append(f'lesion {g["lesion"]}: grouped-CV RMSE {norm:.4f} N (|Fx, Fy, Fz|) is more '
                       f'than 1/3 of its FE contrast {c:.4f} N')
    return out


def build_case(case: Case, *, store_root: str | os.PathLike | None = None, coarse: bool = False,
               train_params: dict[str, Any] | None = None, folds: int = CV_FOLDS,
               seeds: Sequence[int] = CV_SEEDS, ship: bool = True,
               verbose: bool = False) -> BuildResult:
    """Build ``case`` from its store and (if every gate passes and ``ship``) write its files.

    Raises:
        CaseError: a point is missing or failed, or a gate failed (the message names the figure;
            ``BuildResult`` figures are attached as ``exc.result``).
    """
    scene = case.scene
    stores = case_stores(case, store_root, coarse)
    recs, twins = stored_records(stores)  # CaseError naming a hole
    res = BuildResult(case.name)
    ds = records_to_dataset(scene, recs, coarse=coarse)
    # float32 forces (as stored) written as their shortest decimals: the CSV stays small
    ds.Y = np.vectorize(lambda v: float(str(np.float32(v))))(ds.Y)
    res.grades = lesion_grades(scene, recs, twins)
    res.level = case_level(res.grades)
    bg = (background_grades(scene, recs, smooth_reference(case, store_root, coarse))
          if scene.background is not None else None)
    if bg is not None:  # in a nodular breast the level is how hard a lesion is told apart
        res.level = bg['level']
    ds.provenance.update(
        case=case.name, generator='haptic_anfis.cases.build.build_case',
        store={'dir': stores.main.dir.name, 'probe_cells': stores.probe_cells,
               'twin_points': len(twins)},
        grading={**grading_record(res.grades), 'level': res.level,
                 **({'background': bg} if bg is not None else {})},
        cpu_time_s=float(sum(r.get('cpu_time_s', 0.0) for r in recs)))
    p = dict(train_params or {})
    test_fraction, seed = p.pop('test_fraction', 0.2), p.pop('seed', 0)
    t0 = time.perf_counter()
    model, _ = train_on_dataset(ds, test_fraction=test_fraction, seed=seed, verbose=verbose,
                                dataset_path=_package_relative(case.dataset_path), **p)
    res.train_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    cv = grouped_cv(ds, model, p, folds=folds, seeds=seeds)
    res.cv_s = time.perf_counter() - t0
    span = ds.Y.max(0) - ds.Y.min(0)
    res.cv_rmse_n = [float(v) for v in cv]
    res.cv_pct_range = [float(100.0 * v / s) for v, s in zip(cv, span)]
    res.failures = gate_failures(cv, span, res.grades)
    if bg is not None:
        res.failures += background_gate_failures(cv, bg)
    cv_meta = {'folds': folds, 'seeds': list(seeds), 'rmse_n': res.cv_rmse_n,
               'pct_range': res.cv_pct_range, 'gates': {'range_pct': RANGE_GATE_PCT,
                                                        'contrast_fraction': CONTRAST_GATE}}
    ds.provenance['grouped_cv'] = cv_meta
    model.metadata_['grouped_cv'] = cv_meta
    model.metadata_['case'] = {'name': case.name, 'scene_sha256': scene.sha256(),
                               'description': case.description, 'level': res.level}
    disp = displacements_from_records(recs, scene.depths, {
        'dataset_sha256': ds.sha256(), 'scene_sha256': scene.sha256(), 'scene': scene.name,
        'probe_radius_m': scene.probe_radius, 'coarse': coarse,
        'mesh': ds.provenance['mesh'], 'generator': 'haptic_anfis.cases.build'})
    # rounded steps compress: a 173-point case's file is 1.08 MB unquantised, 0.56 MB at 1 µm
    raw = disp.coeffs
    # Write into a staging directory first: the size gate needs the real files.
    stage = Path(tempfile.mkdtemp(prefix=f'.{case.name}.', dir=_stage_root(case)))
    try:
        csv = stage / case.dataset_path.name
        save_dataset(ds, csv)
        model.save(stage / case.model_path.name)
        for q in DISPLACEMENT_QUANTA:
            disp.coeffs = np.round(raw / q) * q
            disp.meta['quantum_m'] = q
            save_displacements(disp, displacement_path(csv))
            files = sorted(stage.iterdir())
            res.bytes = int(sum(f.stat().st_size for f in files))
            if res.bytes <= SIZE_GATE_BYTES:
                break
        if res.bytes > SIZE_GATE_BYTES:
            res.failures.append(f'shipped files are {res.bytes / 2**20:.2f} MB, above 1 MB')
        if res.failures:
            exc = CaseError(f'case {case.name!r} not shipped: ' + '; '.join(res.failures))
            exc.result = res
            raise exc
        if ship:
            case.dataset_path.parent.mkdir(parents=True, exist_ok=True)
            for f in files:
                dest = case.dataset_path.parent / f.name
                os.replace(f, dest)
                res.written.append(str(dest))
            if write_case_mesh(case):
                res.written.append(str(case.mesh_path))
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return res


def _stage_root(case: Case) -> Path:
    """A staging directory on the same file system as the case's files (atomic renames)."""
    d = case.dataset_path.parent.parent
    d.mkdir(parents=True, exist_ok=True)
    return d



def regrade_case(case: Case, *, store_root: str | os.PathLike | None = None,
                 threshold_pct: float | None = None) -> dict[str, Any]:
    """Grade a shipped case again from its committed store (:mod:`.grading`: every depth, the
    shallowest palpable pressure level) and write the grading into its dataset sidecar, leaving
    the dataset, the displacement file and the model as they are. Returns the new grading.

    Raises:
        CaseError: the case is not shipped, or its store lacks a point (naming it).
    """
    side = sidecar_path(case.dataset_path)
    if not side.is_file():
        raise CaseError(f'case {case.name!r}: no dataset sidecar {str(side)!r} to regrade; make '
                        f'it with `haptic-anfis cases generate {case.name}`')
    doc = json.loads(side.read_text())
    if doc.get('scene_sha256') not in (None, case.scene.sha256()):
        raise CaseError(f'case {case.name!r}: its dataset was made from another version of its '
                        f'scene file; regenerate it with `haptic-anfis cases generate '
                        f'{case.name}`')
    thr = PALPABLE_PCT if threshold_pct is None else float(threshold_pct)
    recs, twins = stored_records(case_stores(case, store_root))
    doc['grading'] = grading_record(lesion_grades(case.scene, recs, twins, thr), thr)
    if case.scene.background is not None:   # a nodular breast: told apart from its background
        bg = background_grades(case.scene, recs, smooth_reference(case, store_root),
                               threshold_pct=thr)
        doc['grading'].update(level=bg['level'], background=bg)
    tmp = side.with_name(f'.{side.name}.tmp')
    tmp.write_text(json.dumps(doc, indent=2) + '\n')
    os.replace(tmp, side)
    return doc['grading']

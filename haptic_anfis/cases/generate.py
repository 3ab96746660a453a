"""Make a case's files: FE sweep -> dataset (+ sidecar), surface mesh, trained model.

The sweep is :func:`haptic_anfis.tissue.sweep.run_sweep`: parallel, resumable (per-point results
in ``Case.work_dir``; re-running continues), with a progress line, on a process pool or any
Executor-like object (e.g. ``dask.distributed.Client(LocalCluster(...)).get_executor()``).
Pure Python, no ROS.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..anfis import train_on_dataset
from ..tissue.dataset import DATA_DIR, ForceDataset, load_dataset, save_dataset
from ..tissue.displacement import (displacement_path, displacements_from_records, record_is_current,
                                   save_displacements)
from ..tissue.geometry import loading_points, write_surface_mesh
from ..tissue.sweep import records_to_dataset, run_sweep
from .library import Case, CaseError


@dataclass
class GenerateResult:
    """What :func:`generate_case` did: seconds of FE (this run's elapsed and the summed solver
    time of every point) and of training, failed loading points, and the files written."""

    case: str
    fe_elapsed_s: float = 0.0
    fe_solver_s: float = 0.0
    train_s: float = 0.0
    samples: int = 0
    failed: list[int] = field(default_factory=list)
    written: list[str] = field(default_factory=list)


#: A loading point farther than lesion radius + this from every lesion's (y, z) takes the force of
#: the lesion-free case of the same breast (see :func:`reuse_plan`). Measured on the default
#: scene's fine FE data (r = 7.5 mm, 15 mm deep): the lesion changes the force by 1.1 % at
#: r + 14 mm, 0.4 % at r + 18 mm, 21 % over its centre. For a 25 mm lesion it is more than 1 % of
#: the local force well beyond r + 14 mm (docs/case_library.md), so the graded library
#: (:mod:`.build`) reuses nothing; this older path keeps it for the older cases only.
REUSE_MARGIN = 0.014  # [m]


def _work_dir(case: Case, coarse: bool):
    return case.work_dir.with_name(case.work_dir.name + ('-coarse' if coarse else ''))


def base_case(case: Case, cases: list[Case]) -> Case | None:
    """The lesion-free case whose FE solves ``case`` can reuse away from its lesions: same breast,
    probe, protocol, loading grid and mesh; only the (homogeneous) tissue modulus may differ."""
    s = case.scene
    if not s.tumours:
        return None
    same = ('radii', 'probe_radius', 'direction', 'spacing', 'palpable_radius', 'depths', 'mesh')
    for c in cases:
        b = c.scene
        if c.name != case.name and not b.tumours and b.material.poisson == s.material.poisson \
                and all(getattr(b, k) == getattr(s, k) for k in same):
            return c
    return None


def reuse_plan(case: Case, base: Case) -> tuple[dict[int, int], float]:
    """({case point id: base point id} for the points that reuse the base's solve, modulus ratio).

    A nearly incompressible Neo-Hookean body with prescribed (probe) displacements deforms the
    same for any shear modulus, and its forces scale with it: the base's forces times
    E_case / E_base are the lesion-free forces of the case exactly (up to the Newton tolerance).
    Near a lesion (within radius + :data:`REUSE_MARGIN`) every point is solved.
    """
    s = case.scene
    pts, bpts = loading_points(s), loading_points(base.scene)
    plan = {}
    for i, p in enumerate(pts):
        far = all(np.hypot(p[1] - t.centre[1], p[2] - t.centre[2]) > t.radius + REUSE_MARGIN
                  for t in s.tumours)
        j = np.flatnonzero(np.hypot(bpts[:, 1] - p[1], bpts[:, 2] - p[2]) < 1e-9)
        if far and len(j):
            plan[i] = int(j[0])
    return plan, s.material.youngs / base.scene.material.youngs


def _reused_records(case: Case, base: Case, plan: dict[int, int], scale: float,
                    coarse: bool) -> dict[int, dict[str, Any]]:
    """The base case's per-point records for ``plan``, forces scaled; {} if any is missing."""
    work = _work_dir(base, coarse)
    out = {}
    for i, j in plan.items():
        f = work / f'point_{j:04d}.json'
        if not f.is_file():
            return {}
        rec = json.loads(f.read_text())
        if rec.get('status') != 'ok':
            return {}
        rec.update(point=i, forces_N=(np.asarray(rec['forces_N']) * scale).tolist(),
                   reused_from={'case': base.name, 'point': j, 'force_scale': scale},
                   wall_time_s=0.0)
        out[i] = rec
    return out


def sweep_case(case: Case, *, coarse: bool = False, workers: int = 2, executor: Any = None,
               progress: bool = True, cases: list[Case] | None = None
               ) -> tuple[ForceDataset, GenerateResult]:
    """FE-solve the loading points of ``case`` and write its dataset CSV (+ JSON sidecar, +
    the skin displacement profiles).

    With ``cases`` given and a lesion-free :func:`base_case` among them already solved (its work
    directory holds every point), the points away from the lesions take the base's solves
    (:func:`reuse_plan`) and only those near a lesion are solved. The work directory is per case
    and per density (``<work_dir>`` or ``<work_dir>-coarse``), so a coarse and a full sweep never
    mix. A point whose load path failed contributes the depths it reached; ``failed`` lists it.
    """
    scene = case.scene
    work = _work_dir(case, coarse)
    n = len(loading_points(scene))
    base = base_case(case, cases or [])
    reused: dict[int, dict[str, Any]] = {}
    if base is not None:
        plan, scale = reuse_plan(case, base)
        reused = _reused_records(case, base, plan, scale, coarse)
    solve = [i for i in range(n) if i not in reused]
    res = run_sweep(scene, work, coarse=coarse, workers=workers, executor=executor,
                    progress=progress, indices=solve)
    records = sorted(res.records + list(reused.values()), key=lambda r: r['point'])
    dataset = records_to_dataset(scene, records, coarse=coarse, elapsed_s=res.elapsed_s)
    solver_s = float(dataset.provenance['wall_time_s']['sum_over_points'])
    out = GenerateResult(case.name, fe_elapsed_s=res.elapsed_s, fe_solver_s=solver_s,
                         samples=len(dataset), failed=list(res.failed))
    # A failed point keeps the depths it reached (records_to_dataset); the sidecar lists it.
    dataset.provenance['case'] = case.name
    dataset.provenance['reused'] = (
        {'base_case': base.name, 'points': sorted(reused), 'force_scale': scale,
         'margin_m': REUSE_MARGIN, 'solved_points': solve} if reused else None)
    save_dataset(dataset, case.dataset_path)
    out.written.append(str(case.dataset_path))

    if all(record_is_current(r) for r in records):  # the skin's dent of the same solves
        disp = displacements_from_records(records, scene.depths, {
            'dataset_sha256': dataset.sha256(), 'scene_sha256': scene.sha256(),
            'scene': scene.name, 'probe_radius_m': scene.probe_radius, 'coarse': coarse,
            'mesh': dataset.provenance['mesh'], 'generator': 'haptic_anfis.cases.generate'})
        out.written.append(str(save_displacements(disp, displacement_path(case.dataset_path))))
    return dataset, out


def write_case_mesh(case: Case) -> bool:
    """Write the case's surface mesh (mm) if it does not exist yet; True if written."""
    if case.mesh_path.is_file():
        return False

    write_surface_mesh(case.scene, case.mesh_path, units='mm')
    return True


def train_case(case: Case, params: dict[str, Any] | None = None, verbose: bool = False,
               ds: ForceDataset | None = None):
    """Train the case's model on its dataset (the paper's protocol, :func:`train_on_dataset`:
    structure search per output under ``params['tol']``), write ``model.json`` and return the
    model. ``params``: ForceModel arguments plus ``test_fraction`` and ``seed``."""
    if ds is None:
        if not case.dataset_path.is_file():
            raise CaseError(f'case {case.name!r}: missing dataset_path '
                            f'{str(case.dataset_path)!r}; run the FE sweep first')
        ds = load_dataset(case.dataset_path)
    p = dict(params or {})
    test_fraction = p.pop('test_fraction', 0.2)
    seed = p.pop('seed', 0)
    model, _ = train_on_dataset(ds, test_fraction=test_fraction, seed=seed, verbose=verbose,
                                dataset_path=_package_relative(case.dataset_path), **p)
    model.metadata_['case'] = {'name': case.name, 'scene_sha256': case.scene.sha256(),
                               'description': case.description}
    model.save(case.model_path)
    return model


def generate_case(case: Case, *, coarse: bool = False, workers: int = 2, executor: Any = None,
                  train: bool = True, sweep: bool = True, train_params: dict | None = None,
                  progress: bool = True, verbose: bool = False,
                  cases: list[Case] | None = None) -> GenerateResult:
    """Sweep (unless ``sweep`` is False and the dataset exists; reusing a solved lesion-free
    case among ``cases``, see :func:`sweep_case`), write the mesh, train."""
    ds = None
    if sweep or not case.dataset_path.is_file():
        ds, res = sweep_case(case, coarse=coarse, workers=workers, executor=executor,
                             progress=progress, cases=cases)
    else:
        res = GenerateResult(case.name)
    if write_case_mesh(case):
        res.written.append(str(case.mesh_path))
    if train:
        t0 = time.perf_counter()
        train_case(case, train_params, verbose=verbose, ds=ds)
        res.train_s = time.perf_counter() - t0
        res.written.append(str(case.model_path))
    return res


def _package_relative(path) -> str:
    """A path inside the package as 'haptic_anfis/...', else as given (model-file provenance
    that does not record one machine's directories)."""
    p = Path(path).resolve()
    try:
        return str(Path('haptic_anfis') / p.relative_to(DATA_DIR.parent))
    except ValueError:
        return str(p)

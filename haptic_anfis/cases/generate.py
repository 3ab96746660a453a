"""Make a case's files: FE sweep -> dataset (+ sidecar), surface mesh, trained model.

The sweep is :func:`haptic_anfis.tissue.sweep.run_sweep`: parallel, resumable (per-point results
in ``Case.work_dir``; re-running continues), with a progress line, on a process pool or any
Executor-like object (e.g. ``dask.distributed.Client(LocalCluster(...)).get_executor()``).
Pure Python, no ROS.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from ..dataset import ForceDataset, load_dataset, save_dataset
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


def sweep_case(case: Case, *, coarse: bool = False, workers: int = 2, executor: Any = None,
               progress: bool = True) -> tuple[ForceDataset, GenerateResult]:
    """FE-solve every loading point of ``case`` and write its dataset CSV (+ JSON sidecar).

    The work directory is per case and per density (``<work_dir>`` or ``<work_dir>-coarse``), so
    a coarse and a full sweep of one case never mix. Raises CaseError if any point failed (its
    finished points stay in the work directory; re-run to retry only the failed ones after
    deleting their ``point_NNNN.json``).
    """
    from ..tissue.sweep import run_sweep

    scene = case.scene
    work = case.work_dir.with_name(case.work_dir.name + ('-coarse' if coarse else ''))
    res = run_sweep(scene, work, coarse=coarse, workers=workers, executor=executor,
                    progress=progress)
    solver_s = float(res.dataset.provenance['wall_time_s']['sum_over_points'])
    out = GenerateResult(case.name, fe_elapsed_s=res.elapsed_s, fe_solver_s=solver_s,
                         samples=len(res.dataset), failed=list(res.failed))
    if res.failed:
        raise CaseError(f'case {case.name!r}: FE failed at loading points {res.failed} (see '
                        f'{str(work)!r}); the dataset was not written')
    res.dataset.provenance['case'] = case.name
    save_dataset(res.dataset, case.dataset_path)
    out.written.append(str(case.dataset_path))
    if res.displacements is not None:  # the skin's dent of the same solves (issue 16)
        from ..tissue.displacement import displacement_path, save_displacements

        out.written.append(str(save_displacements(res.displacements,
                                                  displacement_path(case.dataset_path))))
    return res.dataset, out


def write_case_mesh(case: Case) -> bool:
    """Write the case's surface mesh (mm) if it does not exist yet; True if written."""
    if case.mesh_path.is_file():
        return False
    from ..tissue.geometry import write_surface_mesh

    write_surface_mesh(case.scene, case.mesh_path, units='mm')
    return True


def train_case(case: Case, params: dict[str, Any] | None = None, verbose: bool = False,
               ds: ForceDataset | None = None):
    """Train the case's model on its dataset (the paper's protocol, :func:`train_on_dataset`:
    structure search per output under ``params['tol']``), write ``model.json`` and return the
    model. ``params``: ForceModel arguments plus ``test_fraction`` and ``seed``."""
    from ..anfis import train_on_dataset

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
                  progress: bool = True, verbose: bool = False) -> GenerateResult:
    """Sweep (unless ``sweep`` is False and the dataset exists), write the mesh, train."""
    ds = None
    if sweep or not case.dataset_path.is_file():
        ds, res = sweep_case(case, coarse=coarse, workers=workers, executor=executor,
                             progress=progress)
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
    from pathlib import Path

    from ..dataset import DATA_DIR

    p = Path(path).resolve()
    try:
        return str(Path('haptic_anfis') / p.relative_to(DATA_DIR.parent))
    except ValueError:
        return str(p)

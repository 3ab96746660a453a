"""Parallel, resumable sweep of a scene's loading points into a force dataset.

Each loading point is one task (mesh + load path to every depth). Tasks run on any
``concurrent.futures.Executor``-like object (``submit(fn, *args)`` returning futures with
``result()``): a process pool by default, or e.g. ``dask.distributed.Client.get_executor()``.
Every finished point is written at once to ``WORK_DIR/point_NNNN.json`` (write-then-rename), so an
interrupted sweep loses at most the points in flight and re-running the same command continues.
A ``manifest.json`` ties the work dir to one scene and mesh density; a mismatch is an error.
"""
from __future__ import annotations

import concurrent.futures as cf
import json
import os
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import scipy

from ..optional import optional
from .dataset import ForceDataset
from .displacement import DisplacementSet, displacements_from_records, record_is_current
from .fe import FESolveError, default_linear_solver, solve_scene_point
from .geometry import indentation_direction, loading_points
from .linsolve import backend_name
from .pointsweep import path_record
from .scene import Scene

# their versions are recorded with the data (solver_versions)
felupe = optional('felupe')  # the FE stack: the 'fe' extra
pypardiso = optional('pypardiso')  # MKL PARDISO: the 'fe-fast' extra

THREAD_VARS = ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS',
               'NUMBA_NUM_THREADS', 'VECLIB_MAXIMUM_THREADS')


def limit_threads() -> None:
    """One math thread per worker process: with 2 cores, 2 single-threaded workers doubled
    throughput, threaded BLAS/MKL inside workers only oversubscribes."""
    for var in THREAD_VARS:
        os.environ.setdefault(var, '1')


def _solve_task(scene: Scene, index: int, point: list[float], coarse: bool) -> dict[str, Any]:
    """Worker: solve one loading point; never raises for a failed solve (records the error).
    The record holds the forces and the skin's displacement profile at every depth reached."""
    limit_threads()

    t0 = time.perf_counter()
    direction = indentation_direction(scene, np.asarray(point)[None])[0]
    out: dict[str, Any] = {'point': index, 'surface_point_m': point, 'status': 'ok',
                           'direction': direction.tolist()}
    name = default_linear_solver()[0]
    try:
        out.update(path_record(solve_scene_point(scene, point, coarse=coarse), name, point,
                               direction, scene))
    except FESolveError as exc:
        part = getattr(exc, 'partial', None)
        out.update(status='failed', error=str(exc), depths_m=[], forces_N=[], linear_solver=name)
        if part is not None:
            out.update(path_record(part, name, point, direction, scene))
    out['wall_time_s'] = time.perf_counter() - t0
    return out


def _write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text(json.dumps(data, indent=1) + '\n')
    os.replace(tmp, path)


@dataclass
class SweepResult:
    """Outcome of a sweep: the dataset (all recorded samples), per-point records, and the skin
    displacement profiles (None when the task recorded none, e.g. a test's stand-in task)."""

    dataset: ForceDataset
    records: list[dict[str, Any]]
    failed: list[int]
    elapsed_s: float
    displacements: DisplacementSet | None = None


class _Progress:
    """Minimal progress line on stderr (tqdm is optional; not a dependency)."""

    def __init__(self, total: int, done: int) -> None:
        self.total, self.done, self.t0, self.start = total, done, time.time(), done

    def update(self, msg: str = '') -> None:
        self.done += 1
        rate = (self.done - self.start) / max(time.time() - self.t0, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else float('inf')
        print(f'\r[{self.done}/{self.total} points] {time.time() - self.t0:7.0f} s elapsed, '
              f'ETA {eta:6.0f} s {msg}', end='', file=sys.stderr, flush=True)

    def close(self) -> None:
        print(file=sys.stderr, flush=True)


def run_sweep(scene: Scene, work_dir: str | os.PathLike, *, coarse: bool = False,
              workers: int = 2, executor: Any | None = None, indices: Iterable[int] | None = None,
              progress: bool = True, task: Callable = _solve_task) -> SweepResult:
    """Solve every (or the given) loading point of ``scene``, persisting each as it finishes.

    Args:
        work_dir: directory for per-point results; re-running with the same one resumes.
        coarse: use the scene's coarse mesh density (CI / quick looks).
        workers: process-pool size when no ``executor`` is given (each single-threaded).
        executor: any Executor-like object; the caller owns (and shuts down) it.
        indices: subset of loading-point ids (default: all).
        task: the per-point solve (the FE solve by default). With the FE solve, a persisted
            record without the current displacement profile (from an older version) is solved
            again, so the forces and the dent always come from the same solve.
    Returns:
        SweepResult with a ForceDataset of every recorded (point, depth) sample and the
        DisplacementSet of the same solves (its ``meta['dataset_sha256']`` is the dataset's).
    """
    limit_threads()
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    n_cells = scene.mesh.coarse_probe_cells if coarse else scene.mesh.probe_cells
    manifest = {'scene_sha256': scene.sha256(), 'scene_name': scene.name, 'probe_cells': n_cells,
                'edge_refine': scene.mesh.edge_refine, 'edge_offset': scene.mesh.edge_offset,
                'coarse': coarse}
    mpath = work / 'manifest.json'
    if mpath.is_file():
        old = json.loads(mpath.read_text())
        if {k: old.get(k) for k in manifest} != manifest:
            raise ValueError(f'work dir {str(work)!r} belongs to another scene or mesh density '
                             f'({old}); use a fresh --work-dir')
    else:
        _write_json(mpath, manifest)

    pts = loading_points(scene)
    todo_ids = sorted(set(range(len(pts)) if indices is None else indices))
    if any(i < 0 or i >= len(pts) for i in todo_ids):
        raise ValueError(f'loading point ids must be in [0, {len(pts)}), got {todo_ids}')
    records: dict[int, dict[str, Any]] = {}
    for i in todo_ids:
        f = work / f'point_{i:04d}.json'
        if f.is_file():
            try:
                rec = json.loads(f.read_text())
            except json.JSONDecodeError:
                f.unlink()  # a torn write cannot happen (rename), but be forgiving
                continue
            if task is not _solve_task or record_is_current(rec):
                records[i] = rec
    todo = [i for i in todo_ids if i not in records]
    t0 = time.time()
    bar = _Progress(len(todo_ids), len(records)) if progress else None
    own = executor is None
    if own and todo:
        executor = cf.ProcessPoolExecutor(max_workers=max(1, workers))
    try:
        futures = {executor.submit(task, scene, i, pts[i].tolist(), coarse): i for i in todo} \
            if todo else {}
        native = all(isinstance(f, cf.Future) for f in futures)
        for fut in (cf.as_completed(futures) if native else list(futures)):
            rec = fut.result()
            rec['scene_sha256'] = manifest['scene_sha256']
            _write_json(work / f'point_{rec["point"]:04d}.json', rec)
            records[rec['point']] = rec
            if bar:
                bar.update('' if rec['status'] == 'ok' else f'(point {rec["point"]} failed)')
    except BaseException:
        if own and executor is not None:
            executor.shutdown(wait=False, cancel_futures=True)
            executor = None
        raise
    finally:
        if own and executor is not None:
            executor.shutdown(wait=True)
        if bar:
            bar.close()
    elapsed = time.time() - t0
    recs = [records[i] for i in todo_ids]
    dataset = records_to_dataset(scene, recs, coarse=coarse, elapsed_s=elapsed)
    disp = None
    if any(record_is_current(r) for r in recs):
        disp = displacements_from_records(recs, scene.depths, {
            'dataset_sha256': dataset.sha256(), 'scene_sha256': scene.sha256(),
            'scene': scene.name, 'probe_radius_m': scene.probe_radius, 'coarse': coarse,
            'mesh': dataset.provenance['mesh'],
            'generator': 'haptic_anfis.tissue.sweep.run_sweep'})
    return SweepResult(dataset=dataset, records=recs,
                       failed=[r['point'] for r in recs if r['status'] != 'ok'],
                       elapsed_s=elapsed, displacements=disp)


def solver_versions() -> dict[str, str]:
    """Versions of everything that shapes the numbers."""
    out = {'python': platform.python_version(), 'numpy': np.__version__, 'scipy': scipy.__version__,
           'felupe': felupe.__version__}
    if backend_name() == 'pypardiso':
        out['pypardiso'] = getattr(pypardiso, '__version__', 'installed')
    return out


def records_to_dataset(scene: Scene, records: list[dict[str, Any]], coarse: bool = False,
                       elapsed_s: float = 0.0) -> ForceDataset:
    """Assemble per-point records into a ForceDataset with a provenance dict."""
    X, Y, P = [], [], []
    for r in sorted(records, key=lambda r: r['point']):
        x, y, z = r['surface_point_m']
        for d, f in zip(r['depths_m'], r['forces_N']):
            X.append([x, y, z, d])
            Y.append(f)
            P.append(r['point'])
    if not X:
        raise ValueError('no loading point produced any force sample')
    ok = [r for r in records if r['status'] == 'ok']
    ndofs = [r['ndof'] for r in ok] or [0]
    provenance = {
        'kind': 'FE (felupe, nearly incompressible Neo-Hookean, mean-dilatation hexahedra)',
        'generator': 'haptic_anfis.tissue.sweep.run_sweep',
        'scene': scene.name,
        'scene_sha256': scene.sha256(),
        'scene_file_sha256': scene.source_sha256,
        'scene_si': scene.to_dict(),
        'coarse': coarse,
        'mesh': {'probe_cells': scene.mesh.coarse_probe_cells if coarse else scene.mesh.probe_cells,
                 'edge_refine': scene.mesh.edge_refine,
                 'edge_offset': scene.mesh.edge_offset,
                 'probe_edge_m': ok[0]['probe_edge_m'] if ok else None,
                 'ndof_min': int(min(ndofs)), 'ndof_max': int(max(ndofs)),
                 'ndof_mean': float(np.mean(ndofs))},
        'solver': {**solver_versions(), 'linear_solver': sorted({r.get('linear_solver', '?')
                                                                 for r in records})},
        'wall_time_s': {'sum_over_points': float(sum(r['wall_time_s'] for r in records)),
                        'this_run_elapsed': float(elapsed_s)},
        'n_points': len(records),
        'failed_points': [r['point'] for r in records if r['status'] == 'failed'],
        # points whose solve stopped before the deepest depths: their samples end there
        'partial_points': {str(r['point']): r.get('missing_depths_m', [])
                           for r in records if r['status'] == 'partial'},
        'n_samples': len(X),
        'units': 'x, y, z, depth in m (tissue frame: chest wall x = 0, +x out of the body); '
                 'forces in N on the probe',
        'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
    }
    return ForceDataset(X=np.array(X), Y=np.array(Y), point=np.array(P), provenance=provenance)

"""Resumable per-point FE sweeps into a :class:`~.store.PointStore` (local pool or dask cluster).

- Each loading point is one task. A task first looks for its point file and, if present, returns
  it unsolved; otherwise it solves with retries (:data:`ATTEMPTS`: the scene's load step, then
  half and a quarter of it with more cut-backs; each attempt follows the load path depth by depth
  from the previous converged depth), writes the point file atomically itself (when the store
  directory is reachable from the worker) and returns the record.
- The submitting side writes every returned record that is not on disk yet, so a worker killed
  mid-sweep loses only the point it was solving (the scheduler reruns it elsewhere) and a point
  already on disk is never solved again.
- A point whose every attempt fails past its first depths keeps the depths it reached: a point
  file with status 'partial' (what it lacks in ``missing_depths_m``), resumed like a solved one
  unless failures are retried. A point that reached no depth is recorded as
  ``<key>.failed.json``; a case with such a hole is refused by the case builder, naming the point.

Executors: ``None`` (a process pool of ``workers`` single-threaded processes), any
``concurrent.futures.Executor``, or a ``distributed.Client`` (per-point tasks, results taken as
they complete). Progress: tqdm when importable, else one status line on stderr.
"""
from __future__ import annotations

import concurrent.futures as cf
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from ..optional import optional
from .displacement import profile_record
from .fe import FESolveError, default_linear_solver, solve_scene_point
from .geometry import indentation_direction
from .linsolve import backend_name
from .scene import Scene
from .store import PointStore, point_key

try:  # one math thread per FE worker: the 'fe' extra
    from threadpoolctl import threadpool_limits
except ImportError:
    threadpool_limits = None
try:  # the sweep's progress bar (the 'fe' extra; a plain status line without it)
    from tqdm import tqdm
except ImportError:
    tqdm = None
distributed = optional('distributed')  # FE points on a dask.distributed cluster: the 'dask' extra

__all__ = ['ATTEMPTS', 'JOURNAL_ENV', 'PointSweepResult', 'path_record', 'run_point_sweep',
           'solve_point']

#: when set (in the workers' environment), every finished solve appends '<store dir> <key>' to
#: this file: a journal that shows no point was solved twice
JOURNAL_ENV = 'HAPTIC_ANFIS_FE_JOURNAL'

#: (fraction of the scene's max load step, max cut-backs) per attempt
ATTEMPTS: tuple[tuple[float, int], ...] = ((1.0, 6), (0.5, 8), (0.25, 10))


def solve_point(scene: Scene, point: Sequence[float], probe_cells: int,
                attempts: Sequence[tuple[float, int]] = ATTEMPTS) -> dict[str, Any]:
    """Solve one loading point (x, y, z) [m] with retries; the sweep record (``status`` 'ok',
    'partial' or 'failed'; the last two with ``error`` and ``attempts``). Never raises for a
    failed solve.

    When every attempt fails, the record keeps the depths the deepest attempt reached (status
    'partial', ``missing_depths_m``; 'failed' only when not even the first depth converged): each
    of those depths is a converged equilibrium at full fidelity, and a point near a limit of the
    model (tissue squeezed against a rib) loses only its deep depths. No further retry is made
    once an attempt stopped less than the previous attempt's smallest increment past where that
    one stopped: the smaller step only crept towards the same depth, so the limit is the
    model's (a collapsing cell), not the step's.
    """
    if threadpool_limits is None:
        raise ImportError('the FE sweep needs threadpoolctl (the fe extra)')
    t0, c0 = time.perf_counter(), time.process_time()
    point = [float(v) for v in point]
    direction = indentation_direction(scene, np.asarray(point)[None])[0]
    out: dict[str, Any] = {'surface_point_m': point, 'direction': direction.tolist()}
    errors: list[str] = []
    best, best_k, best_name, stops = None, 0, '', []  # the deepest partial path, its attempt
    # and solver; where each attempt stopped
    smallest = 0.0  # [m] the previous attempt's smallest increment
    res = None
    # Load the linear solver's library (MKL, when pypardiso is installed) before the limit is
    # set: threadpoolctl limits only the libraries loaded when it is entered.
    backend_name()
    with threadpool_limits(1):  # one math thread per worker process (sweep.limit_threads)
        for k, (frac, cutbacks) in enumerate(attempts, 1):
            name, solver = default_linear_solver()
            step = frac * scene.max_step
            try:
                res = solve_scene_point(scene, point, probe_cells=probe_cells, solver=solver,
                                        max_step=step, max_cutbacks=cutbacks)
            except FESolveError as exc:
                part = getattr(exc, 'partial', None)
                reached = float(part.depths[-1]) if part is not None and len(part.depths) else 0.0
                errors.append(f'attempt {k} (step {1e3 * step:g} mm): '
                              f'stopped at {1e3 * reached:g} mm: {exc}')
                if part is not None and len(part.depths) > (0 if best is None else
                                                            len(best.depths)):
                    best, best_k, best_name = part, k, name
                stops.append(getattr(exc, 'depth', None))
                if _same_limit(stops, smallest):
                    errors.append(f'no further attempt: attempts {k - 1} and {k} both stopped '
                                  f'at {1e3 * stops[-1]:.3f} mm')
                    break
                smallest = step * 0.5 ** cutbacks
                continue
            out.update(status='ok', attempt=k, max_step_m=step,
                       **path_record(res, name, point, direction, scene))
            break
    if res is None:
        out.update(error='; '.join(errors), attempts=len(stops), depths_m=[], forces_N=[],
                   status='failed' if best is None else 'partial')
        if best is not None:
            out.update(attempt=best_k, max_step_m=attempts[best_k - 1][0] * scene.max_step,
                       missing_depths_m=[float(d) for d in scene.depths
                                         if d > best.depths[-1] + 1e-12],
                       **path_record(best, best_name, point, direction, scene))
    out['wall_time_s'] = time.perf_counter() - t0
    out['cpu_time_s'] = time.process_time() - c0
    out['scene_sha256'] = scene.sha256()
    return out


def _same_limit(stops: list[float | None], tol: float) -> bool:
    """Whether the last two attempts stopped at the same depth (within ``tol`` [m]: the
    earlier attempt's smallest increment)."""
    return (len(stops) >= 2 and stops[-1] is not None and stops[-2] is not None
            and abs(stops[-1] - stops[-2]) <= tol)


def path_record(res, name: str, point: list[float], direction: np.ndarray,
                scene: Scene) -> dict[str, Any]:
    """The record fields of a (full or partial) load path: depths, forces, mesh and solver
    figures, the skin's displacement profile at each depth reached."""
    return dict(depths_m=res.depths.tolist(),
                forces_N=np.asarray(res.forces).reshape(-1, 3).tolist(), ndof=res.ndof,
                ncells=res.ncells, probe_edge_m=res.probe_edge_size,
                newton_iterations=res.newton_iterations, cutbacks=res.cutbacks,
                linear_solver=name,
                solver_info={k: v for k, v in res.info.items()
                             if k in ('factorisations', 'analyses', 'krylov_solves',
                                      'krylov_iterations')},
                displacement=profile_record(res, point, direction, scene.probe_radius))


def _store_task(scene: Scene, point: list[float], probe_cells: int, store_dir: str,
                manifest: dict[str, Any], solve: Callable = solve_point,
                retry_partial: bool = False) -> dict[str, Any]:
    """Worker: the stored record if the point is on disk (unless it is partial and
    ``retry_partial``), else solve, store, return."""
    store = PointStore(store_dir, manifest)
    key = point_key(point[1], point[2])
    if store.has(key):
        rec = store.load(key)
        if not (retry_partial and rec.get('status') == 'partial'):
            rec['from_store'] = True
            return rec
    rec = solve(scene, point, probe_cells)
    try:  # the worker writes it too: nothing finished is lost if the submitter dies
        store.save_record(key, rec)
        rec['stored_by_worker'] = True
    except OSError:  # the store is not reachable from this worker: the submitter writes it
        pass
    journal = os.environ.get(JOURNAL_ENV)
    if journal:  # one line per finished solve (tests prove no point is solved twice)
        with open(journal, 'a', encoding='utf-8') as f:
            f.write(f'{store_dir} {key}\n')
    return rec


@dataclass
class PointSweepResult:
    """What a sweep did: keys solved now, already on disk, failed (with the error), partial
    (solved now or on disk, with the depths [m] they lack), seconds."""

    solved: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    partial: dict[str, list[float]] = field(default_factory=dict)
    elapsed_s: float = 0.0
    cpu_s: float = 0.0


class _Bar:
    """tqdm when importable, else a status line on stderr."""

    def __init__(self, total: int, desc: str, enabled: bool) -> None:
        self.n, self.total, self.desc, self.t0 = 0, total, desc, time.time()
        self.tq = None
        self.enabled = enabled and total > 0
        if self.enabled and tqdm is not None:
            self.tq = tqdm(total=total, desc=desc, unit='pt', file=sys.stderr,
                           dynamic_ncols=True)

    def update(self, note: str = '') -> None:
        self.n += 1
        if not self.enabled:
            return
        if self.tq is not None:
            self.tq.update(1)
            if note:
                self.tq.set_postfix_str(note)
            return
        dt = time.time() - self.t0
        eta = dt / self.n * (self.total - self.n)
        print(f'\r{self.desc}: {self.n}/{self.total} points, {dt:.0f} s, ETA {eta:.0f} s {note}',
              end='', file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.tq is not None:
            self.tq.close()
        elif self.enabled:
            print(file=sys.stderr, flush=True)


def _is_dask(executor: Any) -> bool:
    return type(executor).__module__.split('.')[0] == 'distributed'


def run_point_sweep(scene: Scene, store: PointStore, points: np.ndarray, probe_cells: int, *,
                    executor: Any = None, workers: int = 2, progress: bool = True,
                    retry_failed: bool = False, solve: Callable = solve_point,
                    desc: str | None = None) -> PointSweepResult:
    """Solve every point of ``points`` (P, 3) [m] that ``store`` lacks; resumable, any executor.

    Points with a failure record or a partial point file are skipped unless ``retry_failed``
    (a retried partial point keeps its file until a solve reaches deeper). Returns what was
    solved, skipped (already on disk), failed and partial.
    """
    t0 = time.time()
    out = PointSweepResult()
    keys = [point_key(p[1], p[2]) for p in points]
    if len(set(keys)) != len(keys):
        raise ValueError('two loading points share one (y, z) key (closer than 1 µm)')
    on_disk, failed, partial = store.solved(), store.failed(), store.partial()
    todo = []
    for p, k in zip(points, keys):
        if k in partial and not retry_failed:
            out.skipped.append(k)
            out.partial[k] = partial[k]
        elif (k in on_disk and k not in partial) or (k in failed and not retry_failed):
            out.skipped.append(k)
            if k in failed and k not in on_disk:
                out.failed[k] = failed[k].get('error', 'failed')
        else:
            todo.append((k, [float(v) for v in p]))
    bar = _Bar(len(todo), desc or scene.name, progress)
    if not todo:
        bar.close()
        out.elapsed_s = time.time() - t0
        return out
    args = [(scene, p, probe_cells, str(store.dir), store.manifest, solve, retry_failed)
            for _, p in todo]
    store._ensure_dir()

    def take(rec: dict[str, Any]) -> None:
        k = point_key(rec['surface_point_m'][1], rec['surface_point_m'][2])
        if rec.get('from_store'):
            out.skipped.append(k)
        else:
            if not rec.get('stored_by_worker'):
                store.save_record(k, rec)
            if rec['status'] == 'failed':
                out.failed[k] = rec.get('error', 'failed')
            else:
                out.solved.append(k)
                out.cpu_s += float(rec.get('cpu_time_s', 0.0))
            if rec['status'] == 'partial':
                out.partial[k] = rec['missing_depths_m']
        bar.update('' if rec['status'] == 'ok' else f'{k} {rec["status"]}')

    own = executor is None
    if _is_dask(executor) and not hasattr(executor, 'scheduler_info'):
        executor = getattr(executor, '_client', executor)  # a ClientExecutor: use its Client
    try:
        if _is_dask(executor):
            futs = [executor.submit(_store_task, *a, pure=False,
                                    key=f'fe-{scene.name}-{k}-{time.time_ns()}')
                    for (k, _), a in zip(todo, args)]
            # one result fetched at a time (with_results=True gathers every future in its own
            # coroutine: under heavy load that tripped a tornado write assertion here)
            for fut in distributed.as_completed(futs):
                take(fut.result())
                fut.release()
        else:
            if own:
                executor = cf.ProcessPoolExecutor(max_workers=max(1, workers))
            futs = [executor.submit(_store_task, *a) for a in args]
            for fut in cf.as_completed(futs):
                take(fut.result())
    finally:
        bar.close()
        if own and executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)
    out.elapsed_s = time.time() - t0
    return out

"""A case's FE points in the committed per-point store (``fe_store/``): sweep, status, records.

A case's store holds its loading points (:func:`haptic_anfis.tissue.geometry.loading_points`) at
the validated mesh density, and a ``twin`` sub-store with the lesion-free twin (the same scene
without its lesions) solved over each lesion's centre, where the lesion's force contrast is
measured. ``--coarse`` stores live beside them as ``<case>-coarse`` (another density is never
mixed in: each store's manifest names its scene hash and density). Pure Python, no ROS.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..tissue.geometry import loading_points
from ..tissue.pointsweep import run_point_sweep
from ..tissue.scene import Scene, surface_height
from ..tissue.store import (PointStore, default_store_root, failure_summary, point_key,
                            store_manifest)
from .library import Case, CaseError

__all__ = ['CaseStores', 'StoreStatus', 'case_stores', 'sweep_case_store', 'store_status',
           'twin_scene', 'twin_points', 'stored_records']


def twin_scene(scene: Scene) -> Scene:
    """The lesion-free twin: the same breast, tissue, probe, protocol and mesh, no lesions."""
    return dataclasses.replace(scene, name=f'{scene.name}-twin', tumours=())


def twin_points(scene: Scene) -> np.ndarray:
    """(L, 3) surface points [m] over each lesion's centre (where contrast is measured)."""
    out = []
    for t in scene.tumours:
        y, z = t.centre[1], t.centre[2]
        out.append([float(surface_height(np.array(y), np.array(z), scene.radii)), y, z])
    return np.array(out, dtype=float).reshape(-1, 3)


@dataclass
class CaseStores:
    """The point stores of one case at one density: its own points and the twin's."""

    case: Case
    probe_cells: int
    main: PointStore
    twin: PointStore | None


def case_stores(case: Case, root: str | os.PathLike | None = None, coarse: bool = False
                ) -> CaseStores:
    """The stores of ``case`` under ``root`` (default :func:`default_store_root`): its own
    directory, or the one of the case its scene names in ``fe_store`` (the same FE problem under
    another name: solved once; the store refuses it if the problems differ)."""
    scene = case.scene
    n = scene.mesh.coarse_probe_cells if coarse else scene.mesh.probe_cells
    base = Path(root) if root is not None else default_store_root()
    suffix = '-coarse' if coarse else ''
    d = base / (case.name + suffix)
    main = PointStore(base / ((scene.fe_store or case.name) + suffix), store_manifest(scene, n))
    twin = PointStore(d / 'twin', store_manifest(twin_scene(scene), n)) if scene.tumours else None
    return CaseStores(case, n, main, twin)


@dataclass
class StoreStatus:
    """How far a case's store is: points total / solved / failed (key: error) / missing keys;
    ``partial``: the solved points whose solve stopped before the deepest depths (key: the
    depths [m] they lack; counted as solved: the case is built without those samples)."""

    case: str
    total: int
    solved: int
    failed: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    partial: dict[str, list[float]] = field(default_factory=dict)
    cpu_s: float = 0.0

    @property
    def complete(self) -> bool:
        return not self.failed and not self.missing


def store_status(stores: CaseStores, with_cpu: bool = False, with_partial: bool = True
                 ) -> StoreStatus:
    """Which of the case's points (and twin points) are solved, failed, missing; and, with
    ``with_partial`` (it reads every point file's meta), which solved points are partial."""
    scene = stores.case.scene
    parts = [(stores.main, loading_points(scene), '')]
    if stores.twin is not None:
        parts.append((stores.twin, twin_points(scene), 'twin/'))
    st = StoreStatus(stores.case.name, 0, 0)
    for store, pts, prefix in parts:
        solved, failed = store.solved(), store.failed()
        partial = store.partial() if with_partial else {}
        for p in pts:
            k = point_key(p[1], p[2])
            st.total += 1
            if k in solved:
                st.solved += 1
                if k in partial:
                    st.partial[prefix + k] = partial[k]
                if with_cpu:
                    st.cpu_s += float(store.load(k).get('cpu_time_s', 0.0))
            elif k in failed:
                st.failed[prefix + k] = failed[k].get('error', 'failed')
            else:
                st.missing.append(prefix + k)
    return st


def sweep_case_store(case: Case, *, root: str | os.PathLike | None = None, coarse: bool = False,
                     executor: Any = None, workers: int = 2, progress: bool = True,
                     retry_failed: bool = False) -> StoreStatus:
    """Solve every missing point of ``case`` (then its twin points) into the store; resumable.
    Returns the store's status afterwards."""
    stores = case_stores(case, root, coarse)
    scene = case.scene
    run_point_sweep(scene, stores.main, loading_points(scene), stores.probe_cells,
                    executor=executor, workers=workers, progress=progress,
                    retry_failed=retry_failed, desc=case.name)
    if stores.twin is not None:
        run_point_sweep(twin_scene(scene), stores.twin, twin_points(scene), stores.probe_cells,
                        executor=executor, workers=workers, progress=progress,
                        retry_failed=retry_failed, desc=f'{case.name} (lesion-free twin)')
    return store_status(stores)


def stored_records(stores: CaseStores) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """(records of every loading point in loading-point order, each with its ``point`` id;
    {lesion name: twin record over its centre}).

    Raises:
        CaseError: a point is missing or failed (the first such point is named): a case with a
            hole is never shipped.
    """
    st = store_status(stores)
    if not st.complete:
        bad = next(iter(st.failed.items()), None)
        if bad is not None:
            raise CaseError(f'case {stores.case.name!r}: FE point {bad[0]} did not solve '
                            f'({failure_summary(bad[1])}); {len(st.failed)} failed, '
                            f'{len(st.missing)} missing of {st.total}: refusing to ship a case '
                            'with a hole')
        raise CaseError(f'case {stores.case.name!r}: FE point {st.missing[0]} is not solved yet '
                        f'({st.solved} of {st.total} solved); run `haptic-anfis cases sweep '
                        f'{stores.case.name}` first')
    scene = stores.case.scene
    recs = []
    for i, p in enumerate(loading_points(scene)):
        rec = stores.main.load(point_key(p[1], p[2]))
        rec['point'] = i
        recs.append(rec)
    twins = {}
    if stores.twin is not None:
        for t, p in zip(scene.tumours, twin_points(scene)):
            twins[t.name] = stores.twin.load(point_key(p[1], p[2]))
    return recs, twins

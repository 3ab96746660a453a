"""The smooth breast a nodular case is graded against: what its force map would be without any
nodule, rib or lesion.

A bump is what the hand feels over the breast around it. A trend fitted to the nodular map itself
absorbs part of every bump (a 16 mm probe over a 10 mm lesion makes a bump about 30 mm wide in a
66 mm disc, and every loading point of the nodular series lies within reach of some nodule, so no
region-free points are left to fit a trend on). The reference here is instead the FE of a
lesion-free *smooth* case of the library with the same geometry: same breast radii, probe, mesh
and constitutive model (neo-Hookean, same Poisson's ratio). Its force map has no bumps, so a
smooth fit of it (:data:`REF_DEGREE` polynomial in (y, z) per depth) only interpolates between its
grid and the nodular case's points. A different base modulus is scaled: with the geometry, the
displacement and the Poisson's ratio fixed, a neo-Hookean body's force is proportional to its
Young's modulus.

A breast over **ribs** is graded against the smooth breast over the same ribs (no nodule, no
lesion): the ribs belong to the body, and they raise the force everywhere, by 8-26 % at 2-16 mm in
the small fatty breast, also between them (measured: docs/measurements/nodule_contrast.md). A
polynomial cannot follow their ridges (12 mm wide, 30 mm apart), so such a reference is
interpolated (piecewise cubic, Clough-Tocher) between its own points, which are the nodular
cases' loading grid.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.interpolate import CloughTocher2DInterpolator, NearestNDInterpolator

from ..tissue.scene import Scene
from .background import basis, force_map
from .library import Case, CaseError, CaseLibrary, library
from .sweeps import case_stores, stored_records

__all__ = ['REF_DEGREE', 'SmoothReference', 'smooth_reference', 'reference_case', 'ribs_of']

#: polynomial degree of the fit of the smooth breast's force map per depth (its residual is
#: 0.2 % of |F| at 2-8 mm and 1 % at 16 mm on lib_free_s_fatty: see bench_nodule_contrast)
REF_DEGREE = 6


@dataclass(frozen=True)
class SmoothReference:
    """The force map of a smooth breast: ``name`` (the library case), ``scale`` (the graded
    scene's Young's modulus over the reference's), its point ``records`` and ``ribs`` (the ribs
    under it, :class:`~haptic_anfis.tissue.background.Rib`; empty: a flat chest wall)."""
    name: str
    scale: float
    records: tuple[dict[str, Any], ...]
    ribs: tuple = ()

    def forces(self, yz: np.ndarray, depth: float) -> np.ndarray:
        """(P,) |F| [N] of the smooth breast at ``depth`` [m] at the points ``yz`` (P, 2) [m]:
        a polynomial fit over a flat chest wall, an interpolation over ribs (the nearest point
        beyond its points' hull)."""
        ryz, rf = force_map(self.records, depth, skip_missing=True)
        yz = np.asarray(yz, float)
        if self.ribs:
            f = CloughTocher2DInterpolator(ryz, rf)(yz)
            out = ~np.isfinite(f)
            if out.any():
                f[out] = NearestNDInterpolator(ryz, rf)(yz[out])
            return self.scale * f
        scale = float(np.abs(ryz).max()) or 1.0
        coef = np.linalg.lstsq(basis(ryz, scale, REF_DEGREE), rf, rcond=None)[0]
        return self.scale * (basis(yz, scale, REF_DEGREE) @ coef)


def ribs_of(scene: Scene) -> tuple:
    """The ribs under ``scene``'s breast (empty over a flat chest wall)."""
    return scene.background.ribs if scene.background is not None else ()


def _same_body(a: Scene, b: Scene) -> bool:
    """The two scenes differ at most in the base modulus, the nodules and lesions and the loading
    grid (both neo-Hookean: the only constitutive model of a scene); their ribs are the same."""
    return (np.allclose(a.radii, b.radii) and a.probe_radius == b.probe_radius
            and a.material.poisson == b.material.poisson
            and a.mesh == b.mesh and set(a.depths) <= set(b.depths)
            and ribs_of(a) == ribs_of(b))


def reference_case(case: Case) -> Case:
    """The case whose smooth breast grades ``case``: a scene file beside its own (the same
    library; else the package's library) with no lesion and no nodule and the same body
    (:func:`_same_body`: the same ribs, if any); the same base modulus first, then by name.

    Raises:
        CaseError: no such case, naming what it needs.
    """
    scene = case.scene
    beside = CaseLibrary(case.scene_path.parent, case.dataset_path.parents[2],
                         work_root=case.work_dir.parent)
    found = []
    for lib in (beside, library()):   # a user's case may grade against a package case
        for n in lib.names():
            c = lib.get(n)
            sc = c.scene
            if sc.tumours or (sc.background is not None and sc.background.nodules) \
                    or not _same_body(scene, sc):
                continue
            found.append((sc.material.youngs != scene.material.youngs, n, c))
        if found:
            break
    if not found:
        raise CaseError(f'case {case.name!r}: no smooth lesion-free case in '
                        f'{str(case.scene_path.parent)!r} or the package library with its '
                        f'breast radii {tuple(round(r * 1e3, 1) for r in scene.radii)} mm, '
                        f'probe, mesh, Poisson ratio, depths and {len(ribs_of(scene))} ribs to '
                        'grade its background against')
    return min(found, key=lambda t: t[:2])[2]


def smooth_reference(case: Case, store_root: str | os.PathLike | None = None,
                     coarse: bool = False) -> SmoothReference:
    """The :class:`SmoothReference` of ``case`` from its reference case's store (the same
    density as the case's: ``coarse``).

    Raises:
        CaseError: no reference case, or its store lacks a point (naming it).
    """
    ref = reference_case(case)
    recs, _ = stored_records(case_stores(ref, store_root, coarse))
    return SmoothReference(ref.name, case.scene.material.youngs / ref.scene.material.youngs,
                           tuple(recs), ribs_of(ref.scene))

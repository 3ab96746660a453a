"""Finite-element solve of one loading point's indentation path with felupe.

Model (docs/design.md, "What was learned on these machines"): nearly incompressible Neo-Hookean tissue on
mean-dilatation (three-field, statically condensed) hexahedra; the probe is a bonded rigid indenter,
i.e. every surface node under its footprint gets the same prescribed displacement (all three
components); Newton-Raphson with load steps of at most ``max_step`` and cut-back that restores the
solver state (felupe checkpoint/restore, including the condensed pressure/volume fields) before
retrying with half the increment. One load path yields the forces at every requested depth.

Units: SI (m, Pa, N). Force convention: the reaction on the probe, e.g. Fx > 0 when the tissue
pushes the probe out of the body (+x).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..errors import HapticAnfisError
from ..optional import optional
from .background import rib_floor
from .geometry import indentation_direction
from .linsolve import PardisoLDLSolver, ReusedFactorSolver, backend_name
from .mesh import Domain, HexMesh, build_mesh, cell_samples, tumour_fractions
from .scene import Scene, surface_height

fem = optional('felupe')  # the FE stack: the 'fe' extra (not needed to run the simulator)


class FESolveError(HapticAnfisError, RuntimeError):
    """The load path could not be followed even with the smallest allowed increment."""


@dataclass
class LoadPathResult:
    """Forces along one load path.

    Attributes:
        depths: (D,) indentation depths [m] at which forces were recorded.
        forces: (D, 3) reaction force on the probe (Fx, Fy, Fz) [N] at each depth.
        ndof: number of displacement degrees of freedom of the mesh.
        ncells: number of hexahedra.
        probe_edge_size: element edge along the probe outline [m].
        newton_iterations: total Newton iterations; cutbacks: number of halved increments.
        wall_time: seconds for mesh + solve.
        skin_displacements: (D, S, 3) displacement [m] of the mesh's skin nodes (``mesh.skin``)
            at each recorded depth, tissue frame; (D, 0, 3) if the mesh names no skin.
        mesh: the mesh solved on (its skin nodes and faces locate the displacements).
    """

    depths: np.ndarray
    forces: np.ndarray
    ndof: int
    ncells: int
    probe_edge_size: float
    newton_iterations: int = 0
    cutbacks: int = 0
    wall_time: float = 0.0
    info: dict = field(default_factory=dict)
    skin_displacements: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))
    mesh: HexMesh | None = None


def default_linear_solver() -> tuple[str, Callable]:
    """A fresh linear solver for one load path and its name: with the optional pypardiso a
    :class:`~.linsolve.PardisoLDLSolver` ('pardiso-ldl': an LDL^T factorisation per Newton
    iteration, the ordering kept for the path's fixed sparsity pattern), else a
    :class:`~.linsolve.ReusedFactorSolver` ('reused-factor/scipy-superlu-sym': the last SuperLU
    factor kept and used to precondition the next Newton systems)."""
    if backend_name() == 'pypardiso':
        return 'pardiso-ldl', PardisoLDLSolver()
    solver = ReusedFactorSolver()
    return f'reused-factor/{solver.backend}', solver


def load_steps(depths: Sequence[float], max_step: float) -> list[float]:
    """Increasing depths [m] from 0 that include every requested depth, increments <= max_step."""
    out, prev = [], 0.0
    for d in depths:
        k = max(1, int(np.ceil((d - prev) / max_step - 1e-9)))
        out.extend(prev + (d - prev) * np.arange(1, k + 1) / k)
        prev = d
    return [float(v) for v in out]


def solve_load_path(mesh: HexMesh, shear: np.ndarray | float, bulk: np.ndarray | float,
                    direction: Sequence[float], depths: Sequence[float], max_step: float = 2e-3,
                    max_cutbacks: int = 6, tol: float = 1e-6, maxiter: int = 16,
                    solver: Callable | None = None, bonded: bool = True,
                    hold_cutback: bool = True) -> LoadPathResult:
    """Indent ``mesh``'s footprint along the unit vector ``direction`` to each of ``depths`` [m].

    Args:
        mesh: the hexahedral mesh with its footprint and clamped node sets.
        shear, bulk: shear and bulk moduli [Pa], scalars or (M,) per cell.
        bonded: prescribe all three displacement components of the footprint (default, the
            robust choice); False prescribes only the components along ``direction``
            (a frictionless probe, for validation against frictionless analytic solutions).
        direction: (3,) unit vector the probe moves along (into the tissue).
        depths: increasing depths [m] to record; the path is stepped by at most ``max_step``.
        hold_cutback: after a cut-back, keep later increments at most the halved one (default);
            False goes back to ``max_step`` after each (the benchmark's baseline).
    Raises:
        FESolveError if an increment fails after ``max_cutbacks`` halvings or would need to be
        smaller than the smallest planned load step halved ``max_cutbacks`` times; it carries ``partial`` (the depths reached),
        ``depth`` (the deepest converged state [m]) and ``increment`` (the last one tried [m]).
    """
    if fem is None:
        raise ImportError('the FE solver needs felupe (the fe extra: pip install felupe)')
    t0 = time.perf_counter()
    if solver is None:
        solver = default_linear_solver()[1]  # a new one per path: its factor belongs to this mesh
    direction = np.asarray(direction, dtype=float)
    direction = direction / np.linalg.norm(direction)
    fmesh = fem.Mesh(mesh.points, mesh.cells, 'hexahedron')
    region = fem.RegionHexahedron(fmesh)
    field = fem.FieldContainer([fem.Field(region, dim=3)])
    solid = fem.SolidBodyNearlyIncompressible(_CellwiseScaled(fem.NeoHooke(mu=1.0), shear),
                                              field, bulk=bulk)

    npts = len(mesh.points)
    fixed = np.zeros(npts, dtype=bool)
    fixed[mesh.fixed] = True
    probe = np.zeros(npts, dtype=bool)
    probe[mesh.footprint] = True
    bounds = {'fixed': fem.Boundary(field[0], mask=fixed)}
    for i, ax in enumerate('xyz'):
        if not bonded and abs(direction[i]) < 1e-12:
            continue
        skip = [1, 1, 1]
        skip[i] = 0
        bounds[f'probe_{ax}'] = fem.Boundary(field[0], mask=probe, skip=tuple(skip))
    dof0, dof1 = fem.dof.partition(field, bounds)

    steps = load_steps(depths, max_step)
    floor = float(np.min(np.diff([0.0, *steps]))) * 0.5 ** max_cutbacks  # [m] see the cut-back
    wanted = set(np.round(np.asarray(depths) / 1e-9).astype(np.int64).tolist())
    forces, recorded, skin_u = [], [], []
    done, iters, cutbacks = 0.0, 0, 0
    queue = list(steps)
    halvings = 0
    # After a cut-back the increments stay at most the halved one: a path that failed once
    # gets stiffer further in, and each failed attempt costs Newton iterations and
    # factorisations for nothing (the equilibrium at a recorded depth does not depend on the
    # steps taken to it: hyperelastic, no history).
    limit = np.inf
    while queue:
        parts = int(np.ceil((queue[0] - done) / limit - 1e-6)) if np.isfinite(limit) else 1
        if parts > 1:  # equal sub-increments of at most ``limit`` up to the next queued depth
            queue.insert(0, done + (queue[0] - done) / parts)
        target = queue[0]
        state = solid.checkpoint()
        for i in range(3):
            if f'probe_{"xyz"[i]}' in bounds:
                bounds[f'probe_{"xyz"[i]}'].update(target * direction[i])
        ext0 = fem.dof.apply(field, bounds, dof0)
        try:
            with np.errstate(all='ignore'):
                res = fem.newtonraphson(items=[solid], dof1=dof1, dof0=dof0, ext0=ext0,
                                        solver=solver, tol=tol, maxiter=maxiter, verbose=0)
            iters += res.iterations
        except (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError) as exc:
            # NewtonConvergenceError is a ValueError; singular/NaN systems land here too.
            solid.restore(state)
            cutbacks += 1
            halvings += 1
            # No increment below the smallest planned one halved max_cutbacks times: without
            # that floor a path that meets a limit (a collapsing cell) creeps towards it in ever
            # smaller increments, each success resetting the halvings, for minutes of CPU.
            if halvings > max_cutbacks or 0.5 * (target - done) < floor:
                err = FESolveError(f'no convergence from depth {done * 1e3:.3f} mm towards '
                                   f'{target * 1e3:.3f} mm after {max_cutbacks} cut-backs: {exc}')
                err.depth = done  # [m] the deepest converged state
                err.increment = target - done  # [m] the last increment tried
                err.partial = LoadPathResult(  # the depths reached before the failure
                    depths=np.array(recorded), forces=np.array(forces).reshape(-1, 3),
                    ndof=3 * npts, ncells=len(mesh.cells), probe_edge_size=mesh.probe_edge_size,
                    newton_iterations=iters, cutbacks=cutbacks,
                    wall_time=time.perf_counter() - t0,
                    skin_displacements=np.array(skin_u).reshape(len(recorded), -1, 3), mesh=mesh)
                raise err from None
            queue.insert(0, 0.5 * (done + target))
            if hold_cutback:
                limit = 0.5 * (target - done)
            continue
        halvings = 0
        done = queue.pop(0)
        if int(round(done / 1e-9)) in wanted:
            r = np.asarray(solid.results.force.toarray() if hasattr(solid.results.force, 'toarray')
                           else solid.results.force).ravel()
            # Internal nodal forces at the footprint equal the load the probe applies to the
            # tissue; the tissue pushes back on the probe with the opposite sign.
            forces.append(-r.reshape(-1, 3)[mesh.footprint].sum(axis=0))
            # The skin's displacement field at this depth: the dent the display shows.
            skin_u.append(np.array(field[0].values[mesh.skin], dtype=float))
            recorded.append(done)
    return LoadPathResult(depths=np.array(recorded), forces=np.array(forces), ndof=3 * npts,
                          ncells=len(mesh.cells), probe_edge_size=mesh.probe_edge_size,
                          newton_iterations=iters, cutbacks=cutbacks,
                          wall_time=time.perf_counter() - t0,
                          skin_displacements=np.array(skin_u).reshape(len(recorded), -1, 3),
                          mesh=mesh, info=_solver_info(solver))


def _solver_info(solver: Callable) -> dict:
    """Counters of a :mod:`~.linsolve` solver (empty for a plain function)."""
    keys = ('factorisations', 'analyses', 'krylov_solves', 'krylov_iterations')
    return {k: getattr(solver, k) for k in keys if hasattr(solver, k)}


class _CellwiseScaled:
    """A felupe umat times a per-cell factor: Neo-Hooke is linear in mu, so mu = 1 scaled by
    (M,) moduli gives heterogeneous tissue on one body (felupe evaluates umats in chunks of
    cells, so an array-valued mu cannot be passed to NeoHooke itself)."""

    def __init__(self, base, scale: np.ndarray | float) -> None:
        self.base = base
        self.scale = scale
        self.x = base.x

    def gradient(self, x):
        P, statevars = self.base.gradient(x)
        return [P * self.scale, statevars]

    def hessian(self, x):
        return [self.base.hessian(x)[0] * self.scale]


def scene_domain(scene: Scene) -> Domain:
    """The meshed breast: the base ellipse shrunk to ``mesh.rim`` (the rim is clamped; the
    semi-ellipsoid's zero thickness at the very edge would give degenerate cells)."""
    rim = scene.mesh.rim
    radii = scene.radii
    floor = float(surface_height(np.array(rim * radii[1]), np.array(0.0), radii))

    def height(y: np.ndarray, z: np.ndarray) -> np.ndarray:
        return np.maximum(surface_height(y, z, radii), floor)

    ribs = scene.background.ribs if scene.background is not None else ()

    def ribs_floor(y: np.ndarray, z: np.ndarray) -> np.ndarray:
        return rib_floor(y, z, ribs, height(y, z))

    return Domain(ry=rim * radii[1], rz=rim * radii[2], height=height, fix_rim=True,
                  floor=ribs_floor if ribs else None)


def scene_moduli(scene: Scene, mesh: HexMesh) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell shear and bulk moduli (M,) [Pa]: tissue, changed by each region's volume fraction
    in the cell (lesions and background nodules; Voigt mixing, the same Poisson's ratio
    everywhere; regions never overlap, so the fractions add up to at most 1). Ribs are not a
    modulus: they are the mesh's rigid floor (:func:`scene_domain`)."""
    mat = scene.material
    mu = np.full(len(mesh.cells), mat.shear)
    bg = scene.background
    spheres = list(scene.tumours) + (list(bg.nodules) if bg is not None else [])
    if not spheres:
        return mu, mu * mat.bulk_ratio()
    samples = cell_samples(mesh.points, mesh.cells)
    frac = tumour_fractions(mesh, [(t.centre, t.radius) for t in spheres], samples)
    for k, t in enumerate(spheres):
        mu += frac[:, k] * (t.youngs / (2.0 * (1.0 + mat.poisson)) - mat.shear)
    return mu, mu * mat.bulk_ratio()


def scene_mesh(scene: Scene, centre_yz: Sequence[float], probe_cells: int) -> HexMesh:
    """The mesh of ``scene`` for a probe centred over ``centre_yz`` (y, z) [m], with the scene's
    edge grading and edge offset."""
    return build_mesh(scene_domain(scene), (float(centre_yz[0]), float(centre_yz[1])),
                      scene.probe_radius, probe_cells, refine=scene.mesh.edge_refine,
                      edge_offset=scene.mesh.edge_offset)


def solve_scene_point(scene: Scene, point: Sequence[float], coarse: bool = False,
                      probe_cells: int | None = None, solver: Callable | None = None,
                      max_step: float | None = None, max_cutbacks: int = 6,
                      hold_cutback: bool = True) -> LoadPathResult:
    """Mesh and solve the load path at a surface point (x, y, z) [m] of ``scene``
    (load steps of at most ``max_step`` [m], default the scene's; ``hold_cutback`` as in
    :func:`solve_load_path`)."""
    n = probe_cells or (scene.mesh.coarse_probe_cells if coarse else scene.mesh.probe_cells)
    point = np.asarray(point, dtype=float)
    mesh = scene_mesh(scene, point[1:], n)
    mu, bulk = scene_moduli(scene, mesh)
    direction = indentation_direction(scene, point[None])[0]
    res = solve_load_path(mesh, mu, bulk, direction, scene.depths, max_step or scene.max_step,
                          max_cutbacks=max_cutbacks, solver=solver, hold_cutback=hold_cutback)
    res.info.update(probe_cells=n, edge_refine=scene.mesh.edge_refine,
                    edge_offset=scene.mesh.edge_offset, direction=direction.tolist(),
                    footprint_radius=mesh.footprint_radius)
    return res

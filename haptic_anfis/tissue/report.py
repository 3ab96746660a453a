"""Validation report for the FE force data: numbers (JSON) and PNG plots.

- Small-depth flat punch vs Sneddon (thick block, a/h = 1/40) and vs Hayes et al. (1972)
  (a = 8 mm on a 40 mm layer), at several mesh densities including the default scene's.
- Mesh-convergence study: one loading point (the dome's apex) to 16 mm on four meshes.
- Force-depth curves (FE vs the small-strain analytic lines) and a map of Fx at 8 mm.

Each FE case is cached in ``DIR/validation.json``; re-running only computes what is missing.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .dataset import DEFAULT_DATASET, load_dataset
from .fe import FESolveError, solve_scene_point
from .geometry import loading_points
from .scene import Scene
from .validation import fe_punch_on_layer, hayes_kappa, sneddon_force

try:  # matplotlib: an optional dependency (the 'report' and 'fe' extras); PNG files, no display
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
except ImportError:
    plt = None

SMALL_DEPTH = 0.2e-3  # m: delta / a = 0.025, where the Neo-Hookean punch is still linear


def punch_case(scene: Scene, kind: str, probe_cells: int, depths: tuple[float, ...] = (SMALL_DEPTH,),
               edge_offset: float | None = None) -> dict[str, Any]:
    """FE punch on a flat layer ('hayes': h = 5a = 40 mm for a = 8 mm; 'sneddon': h = 40a) with the
    scene's probe, tissue and mesh settings (``edge_offset`` overrides the scene's); returns FE and
    analytic forces and the relative errors."""
    offset = scene.mesh.edge_offset if edge_offset is None else edge_offset
    a, E, nu = scene.probe_radius, scene.material.youngs, scene.material.poisson
    h = 5.0 * a if kind == 'hayes' else 40.0 * a
    radius = 5.0 * h if kind == 'hayes' else h
    res = fe_punch_on_layer(h, a, E, nu, depths=depths, probe_cells=probe_cells, radius=radius,
                            refine=scene.mesh.edge_refine, edge_offset=offset)
    kappa = hayes_kappa(a / h, nu)
    sned = sneddon_force(a, E, nu, res.depths)
    fx = res.forces[:, 0]
    return {'kind': kind, 'h_m': h, 'a_m': a, 'probe_cells': probe_cells, 'edge_offset': offset,
            'ndof': res.ndof,
            'probe_edge_m': res.probe_edge_size, 'depths_m': res.depths.tolist(),
            'fe_N': fx.tolist(), 'sneddon_N': sned.tolist(), 'kappa': kappa,
            'hayes_N': (kappa * sned).tolist(),
            'err_vs_sneddon': (fx / sned - 1.0).tolist(),
            'err_vs_hayes': (fx / (kappa * sned) - 1.0).tolist(), 'wall_time_s': res.wall_time}


def convergence_case(scene: Scene, probe_cells: int, point_index: int | None = None
                     ) -> dict[str, Any]:
    """Load path of one loading point (default: the apex) on a mesh with ``probe_cells``."""
    pts = loading_points(scene)
    i = int(np.argmin(np.hypot(pts[:, 1], pts[:, 2]))) if point_index is None else point_index
    try:
        res, error = solve_scene_point(scene, pts[i], probe_cells=probe_cells), None
    except FESolveError as exc:  # report how deep it got rather than nothing
        res, error = exc.partial, str(exc)
    return {'point': i, 'surface_point_m': pts[i].tolist(), 'probe_cells': probe_cells,
            'edge_refine': scene.mesh.edge_refine, 'edge_offset': scene.mesh.edge_offset,
            'error': error,
            'ndof': res.ndof, 'ncells': res.ncells, 'probe_edge_m': res.probe_edge_size,
            'depths_m': res.depths.tolist(), 'forces_N': res.forces.tolist(),
            'wall_time_s': res.wall_time, 'newton_iterations': res.newton_iterations}


def _cached(store: dict[str, Any], path: Path, key: str, fn, *args, **kw) -> dict[str, Any]:
    if key not in store:
        store[key] = fn(*args, **kw)
        tmp = path.with_name(path.name + '.tmp')
        tmp.write_text(json.dumps(store, indent=1) + '\n')
        os.replace(tmp, path)
    return store[key]


def write_report(scene: Scene, out_dir: str | os.PathLike, data: str | os.PathLike | None = None,
                 coarse: bool = False) -> Iterator[str]:
    """Compute (or reuse) the validation cases and write plots into ``out_dir``; yields lines."""
    if plt is None:
        raise ImportError('the validation report needs matplotlib (the fe extra)')
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jpath = out / 'validation.json'
    store: dict[str, Any] = json.loads(jpath.read_text()) if jpath.is_file() else {}
    if store.get('scene_sha256') != scene.sha256():  # cached cases of another scene / mesh
        store = {'scene_sha256': scene.sha256()}
    default_n = scene.mesh.probe_cells
    ns = [scene.mesh.coarse_probe_cells] if coarse else sorted(
        {scene.mesh.coarse_probe_cells, default_n, default_n + 2, default_n + 4})
    for kind in ('hayes', 'sneddon'):
        # The 320 mm Sneddon block costs ~2.5x the DOF of the layer: stop one density earlier.
        for n in (ns if kind == 'hayes' else ns[:3]):
            c = _cached(store, jpath, f'{kind}_n{n}', punch_case, scene, kind, n)
            yield (f'{kind:8s} n={n:2d} ({c["ndof"]:6d} DOF, edge {c["probe_edge_m"] * 1e3:.2f} mm): '
                   f'FE {c["fe_N"][0]:.4f} N, vs Sneddon {100 * c["err_vs_sneddon"][0]:+.2f} %, '
                   f'vs Hayes (kappa {c["kappa"]:.3f}) {100 * c["err_vs_hayes"][0]:+.2f} %')
    if scene.mesh.edge_offset and not coarse:
        for kind in ('hayes', 'sneddon'):  # the same mesh without the edge offset, for comparison
            c = _cached(store, jpath, f'{kind}_n{default_n}_no_offset', punch_case, scene, kind,
                        default_n, edge_offset=0.0)
            yield (f'{kind:8s} n={default_n:2d} without edge offset: FE {c["fe_N"][0]:.4f} N, '
                   f'vs Sneddon {100 * c["err_vs_sneddon"][0]:+.2f} %, '
                   f'vs Hayes {100 * c["err_vs_hayes"][0]:+.2f} %')
    curve = _cached(store, jpath, f'hayes_curve_n{ns[0] if coarse else default_n}', punch_case,
                    scene, 'hayes', ns[0] if coarse else default_n, tuple(scene.depths))
    conv = [_cached(store, jpath, f'convergence_n{n}', convergence_case, scene, n) for n in ns]
    full = [c for c in conv if len(c['forces_N']) == len(scene.depths)]
    ref = full[-1]['forces_N'][-1][0] if full else float('nan')
    for c in conv:
        if c in full:
            f16 = c['forces_N'][-1][0]
            yield (f'convergence n={c["probe_cells"]:2d} ({c["ndof"]:6d} DOF, edge '
                   f'{c["probe_edge_m"] * 1e3:.2f} mm): Fx(16 mm) {f16:.3f} N '
                   f'({100 * (f16 / ref - 1):+.2f} % vs finest), {c["wall_time_s"]:.0f} s')
        else:
            yield (f'convergence n={c["probe_cells"]:2d} ({c["ndof"]:6d} DOF): FAILED after '
                   f'{len(c["forces_N"])} of {len(scene.depths)} depths: {c["error"]}')

    # Force-depth: FE on the 40 mm layer vs the small-strain lines; the dome apex too.
    fig, ax = plt.subplots(figsize=(6, 4.2))
    d = np.array(curve['depths_m']) * 1e3
    dd = np.linspace(0, d.max(), 50)
    ax.plot(d, curve['fe_N'], 'o-', label=f'FE, 40 mm layer (n={curve["probe_cells"]})')
    ax.plot(dd, curve['kappa'] * sneddon_force(scene.probe_radius, scene.material.youngs,
                                               scene.material.poisson, dd * 1e-3), '--',
            label=f'Hayes 1972, kappa={curve["kappa"]:.3f} (small strain)')
    ax.plot(dd, sneddon_force(scene.probe_radius, scene.material.youngs, scene.material.poisson,
                              dd * 1e-3), ':', label='Sneddon half-space (small strain)')
    apex = conv[ns.index(default_n) if default_n in ns else 0]
    ax.plot(np.array(apex['depths_m']) * 1e3, np.array(apex['forces_N'])[:, 0], 's-',
            label=f'FE, breast apex (n={apex["probe_cells"]})')
    ax.set_xlabel('indentation depth [mm]')
    ax.set_ylabel('Fx on probe [N]')
    ax.set_title('Flat 16 mm probe: FE vs analytic')
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / 'force_depth.png', dpi=120)
    plt.close(fig)
    yield f'wrote {out / "force_depth.png"}'

    # Convergence study.
    fig, ax = plt.subplots(figsize=(6, 4.2))
    h = np.array([c['probe_edge_m'] for c in conv]) * 1e3
    for j, depth in enumerate(scene.depths):
        # every mesh that reached this depth; the reference is the finest of them
        have = [c for c in conv if len(c['forces_N']) > j]
        f = np.array([c['forces_N'][j][0] for c in have])
        hj = np.array([c['probe_edge_m'] for c in have]) * 1e3
        if len(f):
            ax.plot(hj, 100 * (f / f[-1] - 1), 'o-', label=f'{depth * 1e3:g} mm')
    for kind, mk in (('hayes', 'k^--'), ('sneddon', 'kv:')):
        have = [k for k, n in enumerate(ns) if f'{kind}_n{n}' in store]
        e = [100 * store[f'{kind}_n{ns[k]}']['err_vs_hayes'][0] for k in have]
        ax.plot(h[have], e, mk, label=f'{kind} small depth vs Hayes kappa')
    ax.axhline(-3, color='r', lw=0.8)
    ax.axhline(3, color='r', lw=0.8)
    ax.set_xlabel('element edge along the probe outline [mm]')
    ax.set_ylabel('force error [%] (apex: vs finest mesh reaching that depth)')
    ax.set_title('Mesh convergence')
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / 'convergence.png', dpi=120)
    plt.close(fig)
    yield f'wrote {out / "convergence.png"}'

    # Map of Fx at 8 mm over the palpable region, tumour outlined.
    path = Path(data) if data else DEFAULT_DATASET
    if path.is_file():
        ds = load_dataset(path)
        sel = np.isclose(ds.X[:, 3], 0.008)
        if sel.any():
            fig, ax = plt.subplots(figsize=(5.6, 4.8))
            sc = ax.scatter(ds.X[sel, 1] * 1e3, ds.X[sel, 2] * 1e3, c=ds.Y[sel, 0], s=60,
                            cmap='viridis')
            for t in scene.tumours:
                ax.add_patch(plt.Circle((t.centre[1] * 1e3, t.centre[2] * 1e3), t.radius * 1e3,
                                        fill=False, color='r', lw=1.5))
            fig.colorbar(sc, label='Fx at 8 mm [N]')
            ax.set_aspect('equal')
            ax.set_xlabel('y [mm]')
            ax.set_ylabel('z [mm]')
            ax.set_title(f'{path.name}: Fx at 8 mm (red: tumour)')
            fig.tight_layout()
            fig.savefig(out / 'surface_map_8mm.png', dpi=120)
            plt.close(fig)
            yield f'wrote {out / "surface_map_8mm.png"}'

"""FE timings for the default scene: per-point mesh build and load path (apex point), coarse and
default meshes. Prints a table; asserts nothing. Needs the `fe` extra. The full validation report
is `haptic-anfis dataset --report DIR`."""
from __future__ import annotations

import argparse
import os
import sys
import time

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

import numpy as np  # noqa: E402

from haptic_anfis.tissue.fe import default_linear_solver, scene_mesh, solve_scene_point  # noqa: E402
from haptic_anfis.tissue.geometry import loading_points  # noqa: E402
from haptic_anfis.tissue.scene import load_scene  # noqa: E402
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])


def main() -> None:
    argparse.ArgumentParser(description=__doc__).parse_args()  # no options; --help says so
    scene = load_scene()
    pts = loading_points(scene)
    apex = pts[int(np.argmin(np.hypot(pts[:, 1], pts[:, 2])))]
    print(f'linear solver: {default_linear_solver()[0]}; {len(pts)} loading points')
    print(f'{"mesh":>8s} {"DOF":>7s} {"mesh ms":>8s} {"solve s":>8s} {"Newton":>7s} '
          f'{"Fx@16mm N":>10s} {"sweep est. min (2 workers)":>27s}')
    for label, n in (('coarse', scene.mesh.coarse_probe_cells), ('default', scene.mesh.probe_cells)):
        t0 = time.perf_counter()
        for _ in range(10):
            scene_mesh(scene, apex[1:], n)
        t_mesh = (time.perf_counter() - t0) / 10
        res = solve_scene_point(scene, apex, probe_cells=n)
        print(f'{label:>8s} {res.ndof:7d} {1e3 * t_mesh:8.1f} {res.wall_time:8.1f} '
              f'{res.newton_iterations:7d} {res.forces[-1, 0]:10.3f} '
              f'{len(pts) * res.wall_time / 2 / 60:27.1f}')


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

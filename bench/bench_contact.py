"""Contact detection speed: ContactDetector vs trimesh.proximity.closest_point (printed only).

Meshes: closed ellipsoid domes (the tissue shape) of ~5k, 20k and 80k faces. Probes: palpation-like
points within 20 mm of the skin (inside and outside), random over the palpable disc.
Single-query latency is measured per call from Python (what a 1 kHz node pays), batch throughput
with ``query_many``. Run: ``.venv/bin/python bench/bench_contact.py [--quick]``.
``--counts`` instead prints the work per call (tree nodes opened, triangle tests; see
:func:`counting_kernels`), which unlike the timings does not depend on the machine's load.
"""
from __future__ import annotations

import argparse
import contextlib
import platform
import sys
import time
import types
from collections import Counter

import numpy as np
import trimesh

from haptic_anfis.contact import ContactDetector, ContactTracker, bvh, ellipsoid_dome
from haptic_anfis.contact import detector as detector_module, proxy as proxy_module
from haptic_anfis.tissue.synthetic import surface_x
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

try:  # trimesh's proximity queries need rtree, which haptic_anfis itself does not
    import rtree  # noqa: F401  (only its presence matters)
    HAVE_RTREE = True
except ImportError:
    HAVE_RTREE = False

RADII = (0.045, 0.070, 0.070)
SIZES = {'5k': (25, 100), '20k': (50, 200), '80k': (100, 400)}


def probes(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r = 0.055 * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * np.pi, n)
    y, z = r * np.cos(a), r * np.sin(a)
    return np.column_stack([surface_x(y, z, RADII) - rng.uniform(-0.004, 0.016, n), y, z])


def percentiles_us(samples_ns: np.ndarray) -> tuple[float, float]:
    return tuple(np.percentile(samples_ns, [50, 99]) / 1e3)


def time_each(fn, points) -> np.ndarray:
    out = np.empty(len(points))
    for i, p in enumerate(points):
        t0 = time.perf_counter_ns()
        fn(p)
        out[i] = time.perf_counter_ns() - t0
    return out


def _float64_args(fn):
    """Python floats in as numpy float64 (numba's float semantics: 1 / 0.0 is inf, not an error)."""
    def call(*args):
        return fn(*(np.float64(a) if type(a) is float else a for a in args))
    return call


@contextlib.contextmanager
def counting_kernels(counts: Counter):
    """Run the bvh kernels as plain Python (their ``py_func``s) and count work while inside.

    Every kernel line marked ``# count: LABEL`` in bvh.py adds one to ``counts['FUNC.LABEL']``
    each time it runs (line tracing), e.g. ``closest.node`` (tree nodes popped) and
    ``closest.tri`` (closest-point-on-triangle tests). The counts depend on the algorithm only,
    not on the machine's load.
    """
    import numba
    ns = dict(vars(bvh))
    marks = {}
    for name, obj in vars(bvh).items():
        if isinstance(obj, numba.core.registry.CPUDispatcher):
            f = obj.py_func
            ns[name] = _float64_args(
                types.FunctionType(f.__code__, ns, name, f.__defaults__, f.__closure__))
            lines, first = __import__('inspect').getsourcelines(f)
            for i, line in enumerate(lines):
                if '# count:' in line:
                    label = line.split('# count:')[1].split()[0]
                    marks.setdefault(f.__code__, {})[first + i] = f'{name}.{label}'

    def local(frame, event, arg):
        if event == 'line':
            label = marks[frame.f_code].get(frame.f_lineno)
            if label is not None:
                counts[label] += 1
        return local

    def tracer(frame, event, arg):
        return local if frame.f_code in marks else None

    users = [m for m in (detector_module, proxy_module) if hasattr(m, 'bvh')]
    mirror = types.SimpleNamespace(**ns)
    for m in users:
        m.bvh = mirror
    sys.settrace(tracer)
    try:
        with np.errstate(all='ignore'):  # numba's error_model='numpy': 1/0 -> inf
            yield
    finally:
        sys.settrace(None)
        for m in users:
            m.bvh = bvh


def work_counts(det: ContactDetector, P: np.ndarray, traj: np.ndarray) -> dict:
    """Mean work per det.query(p) over P and per tracker.update over traj (see counting_kernels)."""
    q, t = Counter(), Counter()
    with counting_kernels(q):
        for p in P:
            det.query(p)
    tr = ContactTracker(det)
    with counting_kernels(t):
        for p in traj:
            tr.update(p)
    return dict(query={k: v / len(P) for k, v in sorted(q.items())},
                tracker={k: v / len(traj) for k, v in sorted(t.items())})


def trajectory(n: int) -> np.ndarray:
    """Hand-like path in and out of the dome (coherent hints, ray casts, saturation)."""
    s = np.linspace(0, 1, n)
    return np.column_stack([0.05 - 0.06 * np.abs(np.sin(7 * s)), 0.04 * np.sin(3 * s),
                            0.04 * np.cos(5 * s)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='fewer points (smoke run)')
    ap.add_argument('--counts', action='store_true',
                    help='only count work per query/update (kernels run as Python, traced)')
    args = ap.parse_args()
    if args.counts:
        n = 100 if args.quick else 500
        for name, (nt, nphi) in SIZES.items():
            det = ContactDetector(ellipsoid_dome(RADII, n_theta=nt, n_phi=nphi, closed=True),
                                  direction=(-1.0, 0.0, 0.0))
            w = work_counts(det, probes(n, seed=1), trajectory(n))
            for what, c in w.items():
                print(f'{name:>4} {what:<8} ' + '  '.join(f'{k} {v:.1f}' for k, v in c.items()))
        print(f'mean work per call over {n} probes / {n} trajectory samples '
              '(node = tree nodes popped, tri = triangle tests)')
        return
    n_single, n_batch, n_tm_single, n_tm_batch = (
        (300, 5000, 5, 50) if args.quick else (5000, 100_000, 30, 500))
    print(f'contact detection bench  ({platform.processor() or platform.machine()}, '
          f'trimesh {trimesh.__version__}; times per query)')
    rows = []
    for name, (nt, nphi) in SIZES.items():
        mesh = ellipsoid_dome(RADII, n_theta=nt, n_phi=nphi, closed=True)
        t0 = time.perf_counter()
        det = ContactDetector(mesh, direction=(-1.0, 0.0, 0.0))
        build_ms = (time.perf_counter() - t0) * 1e3
        P = probes(n_single, seed=1)
        for p in P[:200]:  # warm caches
            det.query(p)
        single = time_each(det.query, P)
        traj = trajectory(n_single)
        tr = ContactTracker(det)
        tracker = time_each(tr.update, traj)
        PB = probes(n_batch, seed=2)
        t0 = time.perf_counter()
        b = det.query_many(PB)
        batch_s = time.perf_counter() - t0
        row = dict(tm_p50=np.nan, tm_batch=np.nan, diff=np.nan, worse=-1, excess=np.nan)
        if HAVE_RTREE:  # trimesh on a subset of the same points (slow: keep the counts small)
            PT = PB[:n_tm_batch]
            tm_single = time_each(lambda p: trimesh.proximity.closest_point(mesh, p[None]),
                                  P[:n_tm_single])
            t0 = time.perf_counter()
            tm_q, tm_d, _ = trimesh.proximity.closest_point(mesh, PT)
            tm_batch_s = time.perf_counter() - t0
            ours_d = np.abs(b.signed_distance[:n_tm_batch])
            row = dict(tm_p50=np.median(tm_single) / 1e3, tm_batch=n_tm_batch / tm_batch_s,
                       diff=float(np.max(ours_d - tm_d)), worse=int(np.sum(tm_d - ours_d > 1e-12)),
                       excess=float(np.max(tm_d - ours_d)))
        rows.append(dict(row,
            name=name, faces=len(mesh.faces), build_ms=build_ms,
            p50=percentiles_us(single)[0], p99=percentiles_us(single)[1],
            trk50=percentiles_us(tracker)[0], trk99=percentiles_us(tracker)[1],
            batch=n_batch / batch_s))
    hdr = (f"{'mesh':>5} {'faces':>6} {'build':>7} | {'query p50':>9} {'p99':>7} | "
           f"{'tracker p50':>11} {'p99':>7} | {'batch q/s':>10} | {'trimesh 1-pt':>12} "
           f"{'trimesh q/s':>11} | {'x single':>8} {'x batch':>7} | {'trimesh farther (worst)':>26}")
    print(hdr)
    print('-' * len(hdr))
    for r in rows:
        print(f"{r['name']:>5} {r['faces']:>6} {r['build_ms']:>5.0f}ms | {r['p50']:>7.1f}us "
              f"{r['p99']:>5.1f}us | {r['trk50']:>9.1f}us {r['trk99']:>5.1f}us | "
              f"{r['batch']:>10.3g} | {r['tm_p50']:>10.0f}us {r['tm_batch']:>11.3g} | "
              f"{r['tm_p50'] / r['p50']:>7.0f}x {r['batch'] / r['tm_batch']:>6.0f}x | "
              f"{r['worse']:>4} of {n_tm_batch:<4} pts ({r['excess'] * 1e6:6.1f} um)")
    if not HAVE_RTREE:
        print('trimesh columns skipped: trimesh.proximity needs rtree (pip install rtree)')
    print(f'single queries: {n_single} calls of det.query(p) (p50/p99 of per-call wall time); '
          f'tracker: ContactTracker.update on a {n_single}-sample trajectory; batch: query_many on '
          f'{n_batch} points; trimesh: {n_tm_single} single calls, {n_tm_batch}-point batch. '
          "'trimesh farther': points where trimesh's closest point is > 1e-12 m farther than ours "
          f'(max ours - trimesh distance: {max(r["diff"] for r in rows):.1e} m).')


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))

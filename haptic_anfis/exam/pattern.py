"""Search pattern of a palpation path (no ROS): vertical strips, spiral / circles, radial spokes.

The three patterns compared by Saunders, Pilgrim & Pennypacker (Cancer 1986) and taught by the
MammaCare method (vertical strips). A pattern is a property of the path at the scale of the search
(the probe footprint), not of the millimetre motion under the finger: the rendered tissue force
pushes the probe along the skin's normal, whose chest-plane part is *radial*, so every change of
pressure (and any wobble of the hand against the tissue, which grows when the servo loop is
starved on a loaded machine) moves the contact point radially by a millimetre or two. Sampled
every 2 mm that motion alone made a vertical-strip exam come out 'radial'. So the in-contact path
is first averaged over ``smooth`` seconds (when sample times are given), then resampled every
``step`` metres (default: the footprint radius) in the chest plane (y, z); each step's direction
is compared with the vertical (z), the radial direction from the nipple axis and the tangential
one. A step along two of them (a vertical step near the z axis is also radial) is *ambiguous* and
decides nothing: the pattern is the class with the largest share of path that only it explains,
provided the class explains (alone or shared) at least ``min_share`` of the path; else 'mixed'
('none' without contact).
"""
from __future__ import annotations

import math

import numpy as np

COS = math.cos(math.radians(25.0))   # within 25 deg of a direction counts as along it
CLASSES = ('vertical_strip', 'spiral_circular', 'radial')


def smooth_path(yz: np.ndarray, t: np.ndarray, segment: np.ndarray, window: float) -> np.ndarray:
    """``yz`` (n, 2) averaged over a centred ``window`` [s] of sample times ``t`` (n,) [s],
    within each contact episode (``segment`` ids, n): removes motion faster than the search
    (hand / tissue wobble of tens of Hz) whatever the sampling rate."""
    yz = np.asarray(yz, float).reshape(-1, 2)
    out = yz.copy()
    if window <= 0 or len(yz) < 3:
        return out
    t = np.asarray(t, float)
    cuts = np.flatnonzero(np.diff(segment)) + 1
    for piece in np.split(np.arange(len(yz)), cuts):
        if len(piece) < 3:
            continue
        tp = t[piece]
        c = np.vstack([np.zeros((1, 2)), np.cumsum(yz[piece], axis=0)])
        lo = np.searchsorted(tp, tp - window / 2, side='left')
        hi = np.searchsorted(tp, tp + window / 2, side='right')
        out[piece] = (c[hi] - c[lo]) / (hi - lo)[:, None]
    return out


def resample(yz: np.ndarray, segment: np.ndarray, step: float) -> list[np.ndarray]:
    """Split the (n, 2) path at changes of ``segment`` id (contact episodes) and keep points at
    least ``step`` apart along each piece."""
    out = []
    if len(yz) == 0:
        return out
    cuts = np.flatnonzero(np.diff(segment)) + 1
    ys, zs = np.asarray(yz, float).T.tolist()   # plain floats: a sample costs ~0.2 us, not ~5
    hypot = math.hypot
    for a, b in zip([0, *cuts.tolist()], [*cuts.tolist(), len(ys)]):
        py, pz = ys[a], zs[a]
        pts = [(py, pz)]
        for y, z in zip(ys[a + 1:b], zs[a + 1:b]):
            if hypot(y - py, z - pz) >= step:
                py, pz = y, z
                pts.append((y, z))
        if len(pts) > 1:
            out.append(np.array(pts))
    return out


def classify(yz: np.ndarray, segment: np.ndarray, footprint_radius: float,
             step: float | None = None, min_share: float = 0.5, t: np.ndarray | None = None,
             smooth: float = 0.1) -> dict:
    """Pattern of the in-contact path ``yz`` (n, 2) [m] with contact-episode ids ``segment`` (n,)
    and, optionally, sample times ``t`` (n,) [s] (then the path is averaged over ``smooth`` s
    first). ``step`` [m] is the resampling distance (None = ``footprint_radius``).

    Returns {pattern, shares: {vertical_strip, spiral_circular, radial}: the share of the path
    length along only that class, along: the same counting the ambiguous steps in every class
    they fit, ambiguous: the share along more than one class, step_mm, strips: {count,
    spacing_mm, overlap, gaps}} where strips are vertical runs >= 10 mm grouped by y (each within
    half a footprint radius of the next, a strip at most a footprint radius wide: lanes closer
    than half a footprint radius are grouped, a few to a strip), spacing the mean distance
    between neighbouring strips, overlap = 1 - spacing / footprint diameter (negative = gaps)
    and gaps = neighbouring strips farther apart than the footprint diameter.
    """
    step = float(footprint_radius if step is None else step)
    yz = np.asarray(yz, float).reshape(-1, 2)
    segment = np.asarray(segment)
    if t is not None and len(yz):
        yz = smooth_path(yz, t, segment, smooth)
    pieces = resample(yz, segment, step)
    only = dict.fromkeys(CLASSES, 0.0)
    along = dict.fromkeys(CLASSES, 0.0)
    ambiguous = 0.0
    length = 0.0
    runs = []   # (y, length) of vertical runs
    for pts in pieces:
        d = np.diff(pts, axis=0)
        L = np.hypot(d[:, 0], d[:, 1])
        u = d / L[:, None]
        mid = 0.5 * (pts[1:] + pts[:-1])
        r = np.hypot(mid[:, 0], mid[:, 1])
        rhat = mid / np.maximum(r, 1e-9)[:, None]
        far = r > 0.005   # near the nipple axis radial / tangential are undefined
        vert = np.abs(u[:, 1]) >= COS
        rad = far & (np.abs((u * rhat).sum(axis=1)) >= COS)
        tang = far & (np.abs(u[:, 0] * -rhat[:, 1] + u[:, 1] * rhat[:, 0]) >= COS)
        flags = {'vertical_strip': vert, 'spiral_circular': tang, 'radial': rad}
        n_fit = vert.astype(int) + rad + tang
        for k, f in flags.items():
            along[k] += L[f].sum()
            only[k] += L[f & (n_fit == 1)].sum()
        ambiguous += L[n_fit > 1].sum()
        length += L.sum()
        # vertical runs: consecutive vertical steps
        start = None
        for i in range(len(vert) + 1):
            if i < len(vert) and vert[i]:
                start = i if start is None else start
            elif start is not None:
                seg = pts[start:i + 1]
                if abs(seg[-1, 1] - seg[0, 1]) >= 0.010:
                    runs.append((float(np.median(seg[:, 0])), float(abs(seg[-1, 1] - seg[0, 1]))))
                start = None
    share = {k: (v / length if length > 0 else 0.0) for k, v in only.items()}
    share_along = {k: (v / length if length > 0 else 0.0) for k, v in along.items()}
    if length <= 0:
        pattern = 'none'
    else:
        best = max(share, key=share.get)
        pattern = best if share[best] > 0 and share_along[best] >= min_share else 'mixed'
    ys = sorted(y for y, _ in runs)
    strips = []
    for y in ys:  # runs closer than half a footprint radius to the last are one strip (a strip's
        # runs wobble by millimetres), up to a footprint radius wide: denser lanes must not chain
        # into one strip across the breast
        if strips and y - strips[-1][-1] <= 0.5 * footprint_radius \
                and y - strips[-1][0] <= footprint_radius:
            strips[-1].append(y)
        else:
            strips.append([y])
    centres = [float(np.mean(s)) for s in strips]
    spacing = np.diff(centres)
    dia = 2 * footprint_radius
    return {'pattern': pattern, 'shares': {k: round(float(v), 4) for k, v in share.items()},
            'along': {k: round(float(v), 4) for k, v in share_along.items()},
            'ambiguous': round(float(ambiguous / length), 4) if length > 0 else 0.0,
            'step_mm': round(step * 1e3, 2),
            'strips': {'count': len(centres),
                       'spacing_mm': round(float(spacing.mean()) * 1e3, 2) if len(spacing) else None,
                       'overlap': round(float(1 - spacing.mean() / dia), 3) if len(spacing) else None,
                       'gaps': int((spacing > dia).sum())}}

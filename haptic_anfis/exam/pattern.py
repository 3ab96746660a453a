"""Search pattern of a palpation path (no ROS): vertical strips, spiral / circles, radial spokes.

The three patterns compared by Saunders, Pilgrim & Pennypacker (Cancer 1986) and taught by the
MammaCare method (vertical strips). The in-contact path is resampled every ``step`` metres in the
chest plane (y, z); each step's direction is compared with the vertical (z), the radial direction
from the nipple axis and the tangential one. The pattern is the direction class holding the largest
share of path length when that share is at least ``min_share``; else 'mixed' ('none' without
contact).
"""
from __future__ import annotations

import math

import numpy as np

COS = math.cos(math.radians(25.0))   # within 25 deg of a direction counts as along it


def resample(yz: np.ndarray, segment: np.ndarray, step: float) -> list[np.ndarray]:
    """Split the (n, 2) path at changes of ``segment`` id (contact episodes) and keep points at
    least ``step`` apart along each piece."""
    out = []
    if len(yz) == 0:
        return out
    cuts = np.flatnonzero(np.diff(segment)) + 1
    for piece in np.split(np.arange(len(yz)), cuts):
        pts = [yz[piece[0]]]
        for i in piece[1:]:
            if np.hypot(*(yz[i] - pts[-1])) >= step:
                pts.append(yz[i])
        if len(pts) > 1:
            out.append(np.array(pts))
    return out


def classify(yz: np.ndarray, segment: np.ndarray, footprint_radius: float, step: float = 0.002,
             min_share: float = 0.5) -> dict:
    """Pattern of the in-contact path ``yz`` (n, 2) [m] with contact-episode ids ``segment`` (n,).

    Returns {pattern, shares: {vertical_strip, spiral_circular, radial}, strips: {count,
    spacing_mm, overlap, gaps}} where strips are vertical runs >= 10 mm grouped by y (within half
    a footprint radius), spacing
    the mean distance between neighbouring strips, overlap = 1 - spacing / footprint diameter
    (negative = gaps) and gaps = neighbouring strips farther apart than the footprint diameter.
    """
    pieces = resample(np.asarray(yz, float).reshape(-1, 2), np.asarray(segment), step)
    tot = {'vertical_strip': 0.0, 'spiral_circular': 0.0, 'radial': 0.0}
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
        tot['vertical_strip'] += L[vert].sum()
        tot['radial'] += L[rad].sum()
        tot['spiral_circular'] += L[tang].sum()
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
    shares = {k: (v / length if length > 0 else 0.0) for k, v in tot.items()}
    if length <= 0:
        pattern = 'none'
    else:
        best = max(shares, key=shares.get)
        pattern = best if shares[best] >= min_share else 'mixed'
    ys = sorted(y for y, _ in runs)
    strips = []
    for y in ys:  # group runs closer than half a footprint radius into one strip
        if strips and y - strips[-1][-1] <= 0.5 * footprint_radius:
            strips[-1].append(y)
        else:
            strips.append([y])
    centres = [float(np.mean(s)) for s in strips]
    spacing = np.diff(centres)
    dia = 2 * footprint_radius
    return {'pattern': pattern, 'shares': {k: round(v, 4) for k, v in shares.items()},
            'strips': {'count': len(centres),
                       'spacing_mm': round(float(spacing.mean()) * 1e3, 2) if len(spacing) else None,
                       'overlap': round(float(1 - spacing.mean() / dia), 3) if len(spacing) else None,
                       'gaps': int((spacing > dia).sum())}}

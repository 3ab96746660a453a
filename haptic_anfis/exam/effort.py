"""What predicts finding lumps, from an exam's samples: time per area and per pressure level, and
the force used when palpating against searching.

Search time was the one consistent predictor of lumps found on silicone models (Fletcher et al.,
JAMA 1985, r = 0.59); successful examiners pressed about 15 % harder when palpating than when
searching, and those who searched too lightly missed the deep masses (Laufer, Klatzky & Pugh,
Acad Med 2024). Our definitions (there are no agreed ones):

- **time at a pressure level**: time in contact with the depth in [light, medium), [medium,
  deep), >= deep (the exam's levels), or below light;
- **time per area**: time in contact over each quarter of the palpable region (by the sign of the
  contact point's y and z, tissue frame) and its centre (within one probe footprint of the nipple
  axis); the tissue frame does not say which breast, so the quarters are named by their axes;
- **palpating / searching**: a contact sample is *palpating* when the contact point stays within
  one probe diameter (twice the footprint radius: 16 mm, the size of MammaCare's small circles)
  of where it is over the centred :data:`WINDOW` (the probe works one spot), else *searching*
  (it travels between spots, faster than about 16 mm/s); the force of each is the mean |F| of
  the force samples at those times. Only samples at or beyond the light level count in either
  mode: shallower, the probe touches down, lifts off or turns at a strip's end, in place but not
  examining anything (counted as palpating, those moments made a scripted vertical-strip search
  cut short before its marking presses read palpating far lighter than searching, from a fraction
  of a second of touch-downs). The comparison needs :data:`MIN_MODE_S` of each mode
  (one :data:`WINDOW`: less is a few transitions, not a way of examining); below it the ratio is
  None. Laufer, Klatzky & Pugh parse the modes from the force record with a trained classifier;
  this kinematic split is a stand-in, so their +15 % is a direction, not a target.

Pure numpy, no ROS.
"""
from __future__ import annotations

import numpy as np

__all__ = ['WINDOW', 'STEP', 'MAX_GAP', 'MIN_MODE_S', 'AREAS', 'effort']

#: [s] the window over which the contact point's travel tells palpating from searching
WINDOW = 1.0
#: [s] the grid the travel is read on
STEP = 0.02
#: [s] a longer gap between contact samples counts as this (a pause in the stream, not contact)
MAX_GAP = 0.05
#: [s] the least time in each mode for the palpating / searching force ratio (one window)
MIN_MODE_S = WINDOW
AREAS = ('centre', 'y+ z+', 'y+ z-', 'y- z+', 'y- z-')


def _interval(c: np.ndarray) -> np.ndarray:
    """Each sample's share of time [s]: the gap to the next sample, at most :data:`MAX_GAP`."""
    if len(c) < 2:
        return np.zeros(len(c))
    return np.r_[np.clip(np.diff(c[:, 0]), 0.0, MAX_GAP), 0.0]


def effort(contacts: np.ndarray, forces: np.ndarray, thresholds: tuple[float, float, float],
           footprint_radius: float) -> dict:
    """The figures of the module doc from contact samples ``contacts`` (n, 6): t [s], x, y, z
    [m], depth [m], in contact (0/1), time-sorted; ``forces`` (m, 4): t [s], fx, fy, fz [N]
    (tissue force); ``thresholds``: the levels' depths (light, medium, deep) [m];
    ``footprint_radius`` [m]. Times in s, forces in N; None where there is no sample."""
    c = np.asarray(contacts, float).reshape(-1, 6)
    dt = _interval(c)
    inside = c[:, 5] > 0.5
    light, medium, deep = thresholds
    d = c[:, 4]
    bands = {'below_light': inside & (d < light), 'light': inside & (d >= light) & (d < medium),
             'medium': inside & (d >= medium) & (d < deep), 'deep': inside & (d >= deep)}
    out: dict = {'time_at_level_s': {k: round(float(dt[m].sum()), 3) for k, m in bands.items()}}
    r = np.hypot(c[:, 2], c[:, 3])
    centre = r <= footprint_radius
    areas = {'centre': centre}
    for name, py, pz in (('y+ z+', True, True), ('y+ z-', True, False), ('y- z+', False, True),
                         ('y- z-', False, False)):
        areas[name] = ~centre & ((c[:, 2] >= 0) == py) & ((c[:, 3] >= 0) == pz)
    out['area_time_s'] = {k: round(float(dt[inside & m].sum()), 3) for k, m in areas.items()}
    pressing = inside & (d >= light)   # touching down / lifting off is neither mode
    palp = pressing & _dwelling(c, inside, 2.0 * footprint_radius)
    search = pressing & ~palp
    out['palpating_s'] = round(float(dt[palp].sum()), 3)
    out['searching_s'] = round(float(dt[search].sum()), 3)
    f = np.asarray(forces, float).reshape(-1, 4)
    fp, fs = _mean_force(c, palp, f), _mean_force(c, search, f)
    out['force_palpating_n'] = None if fp is None else round(fp, 3)
    out['force_searching_n'] = None if fs is None else round(fs, 3)
    enough = out['palpating_s'] >= MIN_MODE_S and out['searching_s'] >= MIN_MODE_S
    out['palpating_vs_searching_pct'] = (None if fp is None or fs is None or fs <= 0
                                         or not enough else round(100.0 * (fp / fs - 1.0), 1))
    return out


def _dwelling(c: np.ndarray, inside: np.ndarray, radius: float) -> np.ndarray:
    """In-contact samples whose contact point stays within ``radius`` of its own over the
    centred :data:`WINDOW`, read on a :data:`STEP` grid (the contact stream runs at up to 1 kHz;
    the hand does not move a footprint in 20 ms)."""
    out = np.zeros(len(c), bool)
    if not inside.any():
        return out
    t = c[:, 0]
    grid = np.arange(t[0], t[-1] + STEP, STEP)
    k = np.clip(np.searchsorted(t, grid, side='right') - 1, 0, len(t) - 1)
    yz, ok = c[k, 2:4], inside[k]
    half = int(round(WINDOW / 2 / STEP))
    still = ok.copy()
    for o in range(-half, half + 1):
        j = np.clip(np.arange(len(grid)) + o, 0, len(grid) - 1)
        far = np.hypot(*(yz[j] - yz).T) > radius
        still &= ~(ok[j] & far)
    g = np.clip(np.round((t - grid[0]) / STEP).astype(int), 0, len(grid) - 1)
    return inside & still[g]


def _mean_force(c: np.ndarray, mask: np.ndarray, f: np.ndarray) -> float | None:
    """Mean |F| [N] of the force samples whose time falls on a contact sample in ``mask`` (the
    contact sample at or just before it)."""
    if not len(f) or not mask.any():
        return None
    k = np.searchsorted(c[:, 0], f[:, 0], side='right') - 1
    ok = k >= 0
    sel = np.zeros(len(f), bool)
    sel[ok] = mask[k[ok]]
    if not sel.any():
        return None
    return float(np.linalg.norm(f[sel, 1:4], axis=1).mean())

"""Applied-force error of a recorded servo session (no ROS): what the device applied at every tick
vs what the ideal loop (zero latency: the force model evaluated at that tick's own pose) would
have applied.

Input: the driver's tick trace (:mod:`.trace`, tissue frame) and the ideal forces at the traced
positions (the caller runs the contact tracker and the force model over them, in order, so the
tracker's state follows the session as in the live graph). Only ticks where the ideal loop is in
contact count. The ideal force is clamped to the device's force limit, as the safety layer would.

Figures (:func:`force_error`):

- ``force_error_rms_n``, ``force_error_p99_n``: RMS and 99th percentile of |F_applied - F_ideal| [N].
- ``force_error_rms_pct``: 100 * RMS(error) / RMS(|F_ideal|) over the contact ticks — the RMS
  error as a % of the (RMS) force; stable where single ticks have near-zero force (contact onset).
- ``force_error_p99_pct``: 99th percentile of the per-tick error as % of that tick's force, over
  ticks with |F_ideal| >= ``min_force`` (default 0.5 N; below it a % says little).
- ``contact_ticks``: ticks in contact.

Where the error is (:func:`error_by_phase`): the contact ticks split into onset (within a window
after the ideal loop enters contact), offset (within the window before it leaves) and steady (the
rest), each with its tick count, RMS error and share of the total squared error.
"""
from __future__ import annotations

import math

import numpy as np

#: [N] a dropout tick: in contact, exactly 0 N applied while the ideal force is above this
DROPOUT_IDEAL = 1.0
#: [N] a phantom tick: not in contact and more than this applied (a force on a free probe)
PHANTOM_FORCE = 0.1


def dropout_ticks(applied_n: np.ndarray, ideal_n: np.ndarray, in_contact: np.ndarray,
                  dropout_ideal: float = DROPOUT_IDEAL) -> np.ndarray:
    """Mask of the dropout ticks: ``in_contact``, 0 N applied, the ideal force above
    ``dropout_ideal`` (``applied_n``, ``ideal_n``: force magnitudes (n,) [N])."""
    return np.asarray(in_contact, dtype=bool) & (applied_n == 0.0) & (ideal_n > dropout_ideal)


def phantom_ticks(applied_n: np.ndarray, in_contact: np.ndarray) -> np.ndarray:
    """Mask of the phantom ticks: not ``in_contact``, more than :data:`PHANTOM_FORCE` applied
    (``applied_n``: force magnitudes (n,) [N])."""
    return ~np.asarray(in_contact, dtype=bool) & (applied_n > PHANTOM_FORCE)


def force_error(applied: np.ndarray, ideal: np.ndarray, in_contact: np.ndarray,
                max_force: float = math.inf, min_force: float = 0.5) -> dict:
    """Error figures (see the module docstring).

    Args:
        applied: (n, 3) force the device applied at each tick [N], tissue frame.
        ideal: (n, 3) the ideal loop's force at each tick [N] (clamped here to ``max_force``).
        in_contact: (n,) bool, the ideal loop is in contact.
        max_force: device force limit [N] (tissue frame): one, or (n,) per tick.
        min_force: smallest force [N] a per-tick % is computed for.

    Raises:
        ValueError: shapes that do not match.
    """
    applied = np.asarray(applied, dtype=np.float64)
    ideal = np.asarray(ideal, dtype=np.float64)
    mask = np.asarray(in_contact, dtype=bool)
    if applied.shape != ideal.shape or applied.ndim != 2 or applied.shape[1] != 3 \
            or mask.shape != (len(applied),):
        raise ValueError(f'force_error: expected applied and ideal (n, 3) and in_contact (n,), '
                         f'got {applied.shape}, {ideal.shape}, {mask.shape}')
    ideal, n = _clamped(ideal, max_force)
    e = np.linalg.norm(applied - ideal, axis=1)[mask]
    f = n[mask]
    out = {'contact_ticks': int(mask.sum())}
    if not len(e):
        return {**out, 'force_error_rms_n': None, 'force_error_p99_n': None,
                'force_error_rms_pct': None, 'force_error_p99_pct': None,
                'force_rms_n': None}
    rms_e = float(np.sqrt(np.mean(e * e)))
    rms_f = float(np.sqrt(np.mean(f * f)))
    big = f >= min_force
    return {**out, 'force_error_rms_n': rms_e, 'force_error_p99_n': float(np.percentile(e, 99)),
            'force_error_rms_pct': 100.0 * rms_e / rms_f if rms_f > 0 else None,
            'force_error_p99_pct': (float(np.percentile(100.0 * e[big] / f[big], 99))
                                    if big.any() else None),
            'force_rms_n': rms_f}


def runs_of(mask) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends) of the runs of True in the 1-D ``mask``: indices, ends exclusive."""
    edges = np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def _clamped(ideal: np.ndarray, max_force) -> tuple[np.ndarray, np.ndarray]:
    """(ideal (n, 3) with magnitudes clamped to ``max_force`` [N] (one limit, or (n,): a trace
    across force-scale switches), the clamped magnitudes (n,))."""
    n = np.linalg.norm(ideal, axis=1)
    lim = np.broadcast_to(np.asarray(max_force, dtype=np.float64), n.shape)
    over = n > lim
    ideal = ideal.copy()
    ideal[over] *= (lim[over] / n[over])[:, None]
    return ideal, np.minimum(n, lim)


PHASES = ('onset', 'offset', 'steady')


def error_by_phase(applied: np.ndarray, ideal: np.ndarray, in_contact: np.ndarray,
                   times: np.ndarray, window: float = 0.02, max_force: float = math.inf) -> dict:
    """Where the applied-force error of :func:`force_error` lies in each contact.

    A contact tick is ``onset`` when it is less than ``window`` [s] after the first tick of its
    contact (a run of in-contact ticks), else ``offset`` when less than ``window`` before the
    last tick of a contact that ends inside the trace, else ``steady``. Arguments as
    :func:`force_error`, plus ``times`` (n,) [s], increasing.

    Returns:
        {phase: {'ticks', 'rms_n' (None without ticks), 'share_pct' (of the summed squared error
        over all contact ticks; None when that is zero)}} for each of :data:`PHASES`, and
        ``'contacts'``: the number of contacts (runs).
    """
    applied = np.asarray(applied, dtype=np.float64)
    mask = np.asarray(in_contact, dtype=bool)
    t = np.asarray(times, dtype=np.float64)
    if applied.shape != np.shape(ideal) or t.shape != mask.shape or mask.shape != (len(applied),):
        raise ValueError(f'error_by_phase: expected applied and ideal (n, 3), in_contact and '
                         f'times (n,), got {applied.shape}, {np.shape(ideal)}, {mask.shape}, '
                         f'{t.shape}')
    ideal, _ = _clamped(np.asarray(ideal, dtype=np.float64), max_force)
    e2 = np.sum((applied - ideal) ** 2, axis=1)
    starts, ends = runs_of(mask)
    ends = ends - 1  # inclusive
    phase = np.full(len(mask), -1)
    for a, b in zip(starts, ends):
        tt = t[a:b + 1]
        ph = np.full(len(tt), 2)
        if b < len(mask) - 1:  # the contact ends inside the trace
            ph[t[b] - tt < window] = 1
        ph[tt - t[a] < window] = 0
        phase[a:b + 1] = ph
    total = float(e2[mask].sum())
    out: dict = {'contacts': int(len(starts))}
    for i, name in enumerate(PHASES):
        sel = phase == i
        k = int(sel.sum())
        out[name] = {'ticks': k, 'rms_n': float(np.sqrt(e2[sel].mean())) if k else None,
                     'share_pct': 100.0 * float(e2[sel].sum()) / total if total > 0 else None}
    return out


def ripple_and_dropouts(times: np.ndarray, applied: np.ndarray, ideal: np.ndarray,
                        in_contact: np.ndarray, max_force: float = math.inf,
                        mean_window: float = 0.05, window: float = 0.2, ripple: float = 0.1,
                        dropout_ideal: float = DROPOUT_IDEAL) -> dict:
    """The buzz and the dropouts a hand feels, over the ticks in contact.

    - ``ripple_windows_pct``: share of the ``window`` [s] (200 ms) windows of contact ticks in
      which the applied force leaves its own centred ``mean_window`` (50 ms) moving mean by more
      than ``ripple`` N (0.1 N) somewhere; ``ripple_windows_ideal_pct``: the same of the ideal
      force (what the tissue itself varies at that scale: the floor for the applied figure).
      A window counts when at least half its span is in contact.
    - ``zero_force_ticks``: ticks in contact with exactly 0 N applied while the ideal force is
      above ``dropout_ideal`` N (1 N): a dropout.
    - ``longest_dropout_ms``: the longest run of such ticks, in time.

    Arguments as :func:`error_by_phase` (times (n,) [s], increasing).
    """
    t = np.asarray(times, dtype=np.float64)
    applied = np.asarray(applied, dtype=np.float64)
    mask = np.asarray(in_contact, dtype=bool)
    if applied.shape != np.shape(ideal) or t.shape != mask.shape or mask.shape != (len(applied),):
        raise ValueError(f'ripple_and_dropouts: expected applied and ideal (n, 3), in_contact '
                         f'and times (n,), got {applied.shape}, {np.shape(ideal)}, {mask.shape}, '
                         f'{t.shape}')
    ideal, n_ideal = _clamped(np.asarray(ideal, dtype=np.float64), max_force)
    n_app = np.linalg.norm(applied, axis=1)
    drop = dropout_ticks(n_app, n_ideal, mask, dropout_ideal)
    longest = 0.0
    if drop.any():
        starts, ends = runs_of(drop)
        for a, b in zip(starts, ends - 1):
            longest = max(longest, float(t[b] - t[a]) + (float(np.median(np.diff(t)))
                                                         if len(t) > 1 else 0.0))
    out = {'zero_force_ticks': int(drop.sum()), 'longest_dropout_ms': 1e3 * longest}
    for key, f in (('ripple_windows_pct', applied), ('ripple_windows_ideal_pct', ideal)):
        out[key] = _ripple_share(t, f, mask, mean_window, window, ripple)
    return out


def ripple_windows(times: np.ndarray, force: np.ndarray, in_contact: np.ndarray,
                   mean_window: float = 0.05, window: float = 0.2, ripple: float = 0.1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The windows :func:`ripple_and_dropouts` counts, one by one (to find what made each).

    Args:
        times: (n,) [s], increasing; force: (n, 3) [N]; in_contact: (n,) bool; the rest as
            :func:`ripple_and_dropouts`.

    Returns:
        ``counted`` (w,) bool: window k (ticks with ``times - times[0]`` in [k, k+1) *
        ``window``) is at least half in contact; ``bad`` (w,) bool: somewhere in it the force
        leaves its centred moving mean by more than ``ripple``; ``worst`` (w,) int: the tick of
        its largest deviation (-1 where the window holds no tick); ``deviation`` (n,) [N]:
        each tick's (0 where its averaging window is not all in contact: the contact's edge).

    Raises:
        ValueError: fewer than two ticks, or shapes that do not match (named).
    """
    t = np.asarray(times, dtype=np.float64)
    f = np.asarray(force, dtype=np.float64)
    mask = np.asarray(in_contact, dtype=bool)
    if len(t) < 2 or f.shape != (len(t), 3) or mask.shape != t.shape:
        raise ValueError(f'ripple_windows: expected times (n,) with n >= 2, force (n, 3) and '
                         f'in_contact (n,), got {t.shape}, {f.shape}, {mask.shape}')
    # centred moving mean of each component over mean_window, by time (cumulative sums)
    c = np.vstack([np.zeros((1, 3)), np.cumsum(f, axis=0)])
    lo = np.searchsorted(t, t - mean_window / 2, side='left')
    hi = np.searchsorted(t, t + mean_window / 2, side='right')
    mean = (c[hi] - c[lo]) / (hi - lo)[:, None]
    # ticks whose averaging window is not all in contact measure the contact's edge: skip them
    cm = np.concatenate([[0], np.cumsum(mask)])
    inner = mask & ((cm[hi] - cm[lo]) == (hi - lo))
    dev = np.where(inner, np.linalg.norm(f - mean, axis=1), 0.0)
    k = np.floor((t - t[0]) / window).astype(np.int64)
    nwin = int(k[-1]) + 1
    dur = np.bincount(k, weights=mask.astype(np.float64), minlength=nwin)
    per_tick = np.median(np.diff(t))
    counted = dur * per_tick >= window / 2
    bad = np.bincount(k[dev > ripple], minlength=nwin) > 0
    worst = np.full(nwin, -1, dtype=np.int64)
    # ticks sorted by window, then by deviation: each window's last is its worst
    order = np.lexsort((dev, k))
    last = np.flatnonzero(np.diff(k[order], append=nwin))
    worst[k[order[last]]] = order[last]
    return counted, bad, worst, dev


def _ripple_share(t, f, mask, mean_window, window, ripple) -> float | None:
    """% of the windows (see :func:`ripple_and_dropouts`) whose deviation exceeds ``ripple``."""
    if len(t) < 2:
        return None
    counted, bad, _, _ = ripple_windows(t, f, mask, mean_window, window, ripple)
    n = int(counted.sum())
    return 100.0 * float((bad & counted).sum()) / n if n else None

"""A trainee's own stiffness-discrimination threshold: a two-alternative forced-choice (2AFC)
adaptive track and a maximum-likelihood estimate of the difference answered correctly
:data:`TARGET_CORRECT` (79.4 %) of the time, the point a 3-down-1-up staircase converges on
(Levitt 1971, "Transformed up-down methods in psychoacoustics", J Acoust Soc Am 49:467-477): the
threshold keeps that definition.

Each trial presents two presses, one on the reference stiffness and one on a stiffer one
(``1 + delta``), in random order; the trainee says which was stiffer. The track is Levitt's
transformed up-down rule with ``down`` correct answers in a row making ``delta`` smaller and one
wrong answer larger; with ``down = 4`` (the default) it places the trials around 84.1 % correct
(0.5 ** (1 / 4)), above the 79.4 % point: a 2AFC trial tells more about the threshold the higher
the proportion correct it is placed at, up to a "sweet point" near 94 % for this observer model
(Green 1990, "Stimulus selection in adaptive psychophysical procedures", J Acoust Soc Am
87:2662-2674; Fisher information of :func:`p_correct` in the threshold), while a rule that climbs
higher needs long runs of correct answers to come down from the start. The steps are geometric
(the threshold is a Weber fraction): ``STEPS[0]`` until ``coarse_reversals`` reversals, then
``STEPS[1]``; a step down is :data:`DOWN_RATIO` of a step up. The run ends after ``reversals``
reversals (or ``max_trials``).

The threshold is the maximum-likelihood fit of :func:`p_correct` to EVERY trial of the run
(:meth:`Staircase.threshold`; the adaptive-ML estimate of Pentland 1980 and QUEST, Watson & Pelli
1983, Perception & Psychophysics 33:113-120), not the mean of the last reversals: on a simulated
observer of known threshold a single 3-down-1-up run averaged over its last 20 reversals landed
within 20 % of it in about two runs of three, the fit on a 4-down-1-up track in far more
(docs/measurements/threshold.md, bench/bench_threshold.py: both procedures' rows); reversal
deltas are a small, correlated sample of the track, the fit uses all the answers (Kaernbach 2001,
"Slope bias of psychometric functions derived from adaptive data", Perception & Psychophysics
63:1389-1398, finds the threshold from such fits unbiased, only the slope biased, which this
one-parameter fit fixes by the observer model). The geometric mean of
the last ``averaged`` reversals is still reported (:meth:`Staircase.reversal_threshold`).

The model (:func:`p_correct`): the trainee perceives each press's stiffness with log-normal
noise (a Weber-law observer, Thurstone case V), so the log stiffness difference over its spread
sets the proportion correct, with a small lapse rate :data:`LAPSE` (a press missed or an answer
slipped: a fit without one is pulled low by a single wrong answer at a large difference,
Wichmann & Hill 2001, Perception & Psychophysics 63:1293-1313).

:class:`SimulatedObserver` answers with a known threshold (tests, ``haptic-anfis threshold
--backend sim``): it perceives each press's stiffness (force over depth, as rendered by the
device) with log-normal noise whose spread makes it 79.4 % correct at its threshold.

Pure Python and numpy, no ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np
from scipy.special import ndtr

__all__ = ['TARGET_CORRECT', 'STEPS', 'DOWN_RATIO', 'LAPSE', 'Staircase', 'SimulatedObserver',
           'noise_for_threshold', 'p_correct', 'ml_threshold']

#: the proportion correct a 3-down-1-up staircase converges on (Levitt 1971): 0.5 ** (1 / 3)
#: of the runs of three stay correct, so p ** 3 = 0.5
TARGET_CORRECT = 0.5 ** (1.0 / 3.0)
#: geometric step factors (of an up step): coarse until ``coarse_reversals`` reversals, then fine
STEPS = (1.5, 1.2)
#: a down step over an up step, in log delta. With equal steps (Levitt's) a 3-down-1-up track
#: settles below its nominal 79.4 % correct, and Garcia-Perez (1998, "Forced-choice staircases
#: with fixed step sizes: asymptotic and small-sample properties", Vision Research 38:1861-1881)
#: gives 0.7393 to reach it for his observers; on :class:`SimulatedObserver` (a log-normal one)
#: the median of 120 seeded runs was 11 % low with 1.0 and 10 % high with 0.7393, 2 % high with
#: 0.87 (the value used: a calibration of the procedure against an observer of known threshold)
DOWN_RATIO = 0.87
#: the lapse rate the fit allows for (a share of trials answered at random whatever the
#: difference): Wichmann & Hill 2001 found fits robust with a small fixed lapse, biased by none
LAPSE = 0.02
#: [fraction] the differences the fit considers (a log grid of FIT_POINTS)
FIT_RANGE = (0.005, 3.0)
FIT_POINTS = 800


@dataclass
class Staircase:
    """A transformed up-down staircase (``down``-down-1-up) on the stiffness difference
    ``delta`` [fraction, 0.22 = 22 %]; the threshold is the maximum-likelihood fit to every trial.

    Args:
        start: the first trial's delta.
        reversals: reversals that end the run.
        averaged: the last reversals whose deltas' geometric mean :meth:`reversal_threshold` is.
        down: correct answers in a row that make delta smaller (3: Levitt's 79.4 % track).
        lapse: the lapse rate of the fit (:func:`ml_threshold`).
        coarse_reversals: reversals taken with the coarse step.
        max_trials: the run ends here even without ``reversals`` reversals.
        floor, ceiling: delta stays within these.
    """

    start: float = 0.6
    reversals: int = 30
    averaged: int = 20
    down: int = 4
    lapse: float = LAPSE
    coarse_reversals: int = 3
    max_trials: int = 200
    floor: float = 0.005
    ceiling: float = 3.0
    trials: list[tuple[float, bool]] = field(default_factory=list)
    reversal_deltas: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and self.floor <= self.start <= self.ceiling):
            raise ValueError(f'staircase start: expected a difference within {self.floor:g}-'
                             f'{self.ceiling:g} (0.6 = 60 %), got {self.start!r}')
        if not (isinstance(self.reversals, int) and self.reversals >= 2
                and 1 <= self.averaged <= self.reversals):
            raise ValueError(f'staircase reversals: expected an integer >= 2 and 1 <= averaged <= '
                             f'reversals, got {self.reversals!r}, {self.averaged!r}')
        if not (isinstance(self.down, int) and 1 <= self.down <= 6):
            raise ValueError(f'staircase down: expected correct answers in a row 1-6, got '
                             f'{self.down!r}')
        if not (math.isfinite(self.lapse) and 0.0 <= self.lapse < 0.5):
            raise ValueError(f'staircase lapse: expected a rate in [0, 0.5), got {self.lapse!r}')
        self.delta = float(self.start)
        self._run = 0          # correct answers in a row at this delta
        self._direction = 0    # -1 going down, +1 going up, 0 not yet moved

    @property
    def done(self) -> bool:
        return (len(self.reversal_deltas) >= self.reversals
                or len(self.trials) >= self.max_trials)

    def answer(self, correct: bool) -> None:
        """Record the answer to the trial at :attr:`delta` and move it."""
        if self.done:
            raise ValueError('the staircase is done: no more trials')
        self.trials.append((self.delta, bool(correct)))
        if correct:
            self._run += 1
            if self._run < self.down:
                return
            self._move(-1)
        else:
            self._move(+1)

    def _move(self, direction: int) -> None:
        self._run = 0
        if self._direction and direction != self._direction:
            self.reversal_deltas.append(self.delta)
        self._direction = direction
        step = STEPS[0] if len(self.reversal_deltas) < self.coarse_reversals else STEPS[1]
        # down steps DOWN_RATIO of an up step (in log delta): with equal steps a 3-down-1-up
        # track settles below its nominal 79.4 % (Garcia-Perez 1998)
        e = DOWN_RATIO if direction < 0 else 1.0
        self.delta = min(max(self.delta * step ** (direction * e), self.floor), self.ceiling)

    def threshold(self) -> float:
        """The maximum-likelihood threshold [fraction] of every trial so far
        (:func:`ml_threshold`).

        Raises:
            ValueError: fewer reversals than ``averaged`` so far (the run is not long enough).
        """
        self._check_long_enough()
        return ml_threshold(self.trials, self.lapse)

    def reversal_threshold(self) -> float:
        """The geometric mean of the deltas at the last ``averaged`` reversals (Levitt's
        estimate; reported beside :meth:`threshold`).

        Raises:
            ValueError: fewer reversals than ``averaged`` so far.
        """
        self._check_long_enough()
        last = self.reversal_deltas[-self.averaged:]
        return float(math.exp(sum(math.log(d) for d in last) / len(last)))

    def _check_long_enough(self) -> None:
        if len(self.reversal_deltas) < self.averaged:
            raise ValueError(f'staircase: {len(self.reversal_deltas)} reversals, the threshold '
                             f'needs {self.averaged}')


def p_correct(delta: np.ndarray | float, threshold: np.ndarray | float,
              lapse: float = LAPSE) -> np.ndarray:
    """The proportion correct of the model observer at a difference ``delta`` whose threshold
    (:data:`TARGET_CORRECT` correct without lapses) is ``threshold`` (fractions; broadcast):
    ``lapse / 2 + (1 - lapse) * Phi(z * ln(1 + delta) / ln(1 + threshold))``, ``z`` the normal
    quantile of :data:`TARGET_CORRECT` (a log-normal stiffness percept: the log difference over
    its spread is the 2AFC's z)."""
    z = NormalDist().inv_cdf(TARGET_CORRECT)
    x = z * np.log1p(np.asarray(delta, float)) / np.log1p(np.asarray(threshold, float))
    return 0.5 * lapse + (1.0 - lapse) * ndtr(x)


def ml_threshold(trials: list[tuple[float, bool]], lapse: float = LAPSE) -> float:
    """The threshold [fraction] that makes ``trials`` ((delta, correct) pairs) most likely
    under :func:`p_correct`, on a log grid of :data:`FIT_POINTS` over :data:`FIT_RANGE`.

    Raises:
        ValueError: no trials.
    """
    if not trials:
        raise ValueError('threshold fit: no trials')
    d = np.array([t[0] for t in trials], float)
    c = np.array([bool(t[1]) for t in trials])
    grid = np.exp(np.linspace(math.log(FIT_RANGE[0]), math.log(FIT_RANGE[1]), FIT_POINTS))
    p = np.clip(p_correct(d[None, :], grid[:, None], lapse), 1e-12, 1.0 - 1e-12)
    ll = np.where(c[None, :], np.log(p), np.log1p(-p)).sum(axis=1)
    return float(grid[int(np.argmax(ll))])


def noise_for_threshold(threshold: float) -> float:
    """The standard deviation of log-perceived stiffness that makes a 2AFC observer
    :data:`TARGET_CORRECT` correct at a difference ``threshold`` (fraction): the two presses'
    log difference over sqrt(2) sigma is the normal quantile of that proportion."""
    if not (math.isfinite(threshold) and threshold > 0):
        raise ValueError(f'observer threshold: expected a fraction > 0 (0.22 = 22 %), got '
                         f'{threshold!r}')
    return math.log1p(threshold) / (math.sqrt(2.0) * NormalDist().inv_cdf(TARGET_CORRECT))


class SimulatedObserver:
    """A 2AFC observer of known ``threshold`` (fraction): it perceives each press's stiffness
    (rendered force over probe depth) with log-normal noise (:func:`noise_for_threshold`) and
    names the press it perceived stiffer. Seeded: the same seed answers the same."""

    def __init__(self, threshold: float, seed: int = 0) -> None:
        self.threshold = float(threshold)
        self.sigma = noise_for_threshold(self.threshold)
        self.rng = np.random.default_rng(seed)

    def choose(self, stiffness_a: float, stiffness_b: float) -> int:
        """0 when press A felt stiffer, else 1 (stiffnesses [N/m] as measured on the device)."""
        a = math.log(stiffness_a) + self.sigma * self.rng.standard_normal()
        b = math.log(stiffness_b) + self.sigma * self.rng.standard_normal()
        return 0 if a > b else 1

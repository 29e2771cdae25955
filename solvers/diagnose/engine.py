"""The generic diagnosis engine: baseline vs candidate extensions of a shared forward model.

A :class:`Problem` is what a procedure hands over: ``residual(params) -> model − data``
(flat, in the data's unit) built on the shared forward model, its per-row noise ``sigma``,
a CV ``groups`` label per row (position, epoch or time block), the baseline blocks with
their free mask, and the :class:`Candidate` effects (the extra blocks of
``solvers.models.*.EFFECTS``, at their null values).

Method (docs/diagnose.md):

1. Fit the baseline (``solvers.fit.fit``), then linearise the weighted residual at the
   solution: ``r ≈ r0 + J0 δ``; each candidate adds columns ``Jc`` (its blocks' Jacobian at
   their null values; a scalar that cannot be linearised, the hard-iron step time, is
   scanned on a grid).
2. A candidate's columns that the baseline already spans (projected norm below
   ``DEAD_RTOL`` of their own) are not identifiable from this capture: when none is left
   the candidate is *unresolvable* and reported with the reason, never as absent.
3. Information criterion: Gaussian BIC with unknown noise scale,
   ``BIC = n ln(RSS/n) + k ln n`` on the weighted residual, so correlated noise that makes
   the stated ``sigma`` optimistic does not make every effect look significant.
4. Held-out validation: the linearised least-squares problem is solved leaving out one
   fold of groups at a time and the held-out rows are predicted; ``cv_rms`` is the RMS of
   those predictions (data units). For a linear model this is exact refitting.
5. Greedy forward selection: a candidate with ``k`` identifiable parameters, one of ``m``,
   is selected when ``ΔBIC < k ln n − F·χ²_k(1 − α/m)`` (a deviance test at level α/m
   written as a ΔBIC bound; ``F``, the procedure's ``threshold``, is measured on null
   simulations: ``THRESHOLDS`` in ``solvers.diagnose.problems``) *and* it lowers
   ``cv_rms`` *and* leaves at least MIN_DOF degrees of freedom. Other candidates that also
   pass and whose fitted signatures correlate with the chosen one's by more than
   ``CONFUSION_CORR`` are reported with it (``confused_with``) and not fitted on top.
   A candidate that moves only the rows of one kind with a threshold of its own
   (``Problem.kind_thresholds``: the compass dip rows) is tested on those rows alone, with
   the exact F test of their own count and degrees of freedom (``kind_quantile``).
6. The extended model is refitted nonlinearly (``solvers.fit``) with the selected blocks;
   its residuals are tested for whiteness (Ljung–Box on time-ordered rows) or against χ².
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.special import fdtri, gammaincc, gammainccinv

from solvers import linalg
from solvers.fit import FitResult, fit
from solvers.params import Packer, as_params

DEAD_RTOL = 1e-2  # a column whose part outside the baseline's span is below this fraction: not identifiable
CONFUSION_CORR = 0.9  # |corr| of a generic term's signature with a library candidate's span: the same structure
ALIAS_CORR = 0.99  # a generic term's signature this close to one library candidate's span: that candidate
RIVAL_CORR = 0.8  # |corr| of two candidates' fitted signatures above this: compared head to head
MAX_FOLDS = 10
ALPHA = 0.05  # family-wise level the per-candidate deviance quantiles start from
WHITE_P = 0.01  # a residual test's p above this: the residuals are noise-like
MIN_DOF = 3  # an extension must leave this many degrees of freedom
REFIT_MAX_MATRIX_CHANGE = 0.5  # a refit that moves a model matrix by more than this share of its norm ran off
# ... unless the data fix the move: held where it was, the model leaves this many times the χ² of
# the free refit (a 10 m/s LDV offset the baseline X had taken: held, 1e5 times; a run-off along a
# direction the data hardly fix costs a few units of χ² when held)
REFIT_HELD_CHI2_RATIO = 4.0
REFIT_FIRM_MAX_SCALE = 4.0  # ... and only where the matrix keeps its norm within this factor
GROUPS_TOL = 1e-6  # round-off in an effective count of groups (a step between two holds leaves a whole number)
# a generic term displaces library effects whose columns hold most (> CONFUSION_CORR) of its
# signature only when its model's BIC is lower by this much (χ²₁(0.95)): a clearly better fit
DISPLACE_MARGIN = 3.84
# the final named model: an effect without which the held-out RMS is lower by more than this
# fraction is not named (``_held_out_guard``). Not 0: a 10σ quadratic and a periodic bias in a
# labelled P1 series (seed 513003) are reported at gains of −2.3 % and −6.6 %, the final refit's
# held-out RMS a little above the first round's; an effect that only trades with another what a
# large effect's linearisation left is reported at −100 % to −550 %
GUARD_CV_RTOL = 0.25
# the same for an effect validated on some rows only (compass dip rows), on those rows: its own test
# already asked for a lower held-out RMS there, linearised; refitted, any loss is a contradiction
GUARD_ROWS_RTOL = 0.0
# where the residual wanders (``Problem.wander_calibrated``), a candidate whose profiled ratio passes
# χ²_k at this tail is calibrated on this many draws of the wander fitted beside it (``WanderModel.null_lr``)
WANDER_NULL_P = 0.05
WANDER_NULL_DRAWS = 100


@dataclass
class Candidate:
    """One effect: its null-valued blocks, which elements are free, an optional scanned scalar
    (``scan = (block, grid)``), or ``reason`` when the capture cannot resolve it at all."""

    name: str
    blocks: dict = field(default_factory=dict)
    free: dict | None = None
    scan: tuple[str, np.ndarray] | None = None
    reason: str | None = None
    setup: Callable[[], None] | None = None  # generic candidates: write the driver basis into the conditions
    folds: str | None = None  # the problem's fold set that validates it (None: the default groups)
    # the free elements once it is in the model (the refits), where they are more than those it is
    # tested with: directions that only a large effect makes count (None: the tested ones)
    refit_free: dict | None = None


@dataclass
class Problem:
    procedure: str
    model: str
    residual: Callable[[dict], np.ndarray]
    sigma: np.ndarray
    groups: np.ndarray
    baseline: dict
    free: dict
    candidates: list[Candidate]
    threshold: float
    unit: str = ""
    time_ordered: bool = False  # rows are a time series (Ljung–Box) or averages (χ²)
    row_labels: list[str] | None = None  # a name per row for quality findings
    rows_are: str = ""  # what a residual row is, said beside its RMS (P4: "10 s block means")
    extended_model: Callable[[list[str]], str] | None = None
    row_types: np.ndarray | None = None
    # the row kinds whose σ is measured (the held-out RMS is taken on them; no noise scale fitted):
    # kind 0, and e.g. P1's changes across a hold (a noise scale of their own in the deviance)
    measured_kinds: frozenset = frozenset({0})
    drivers: dict = field(default_factory=dict)  # name → per-row value (time, temperature, input …) for plots
    channels: int = 1  # time-ordered rows interleave this many channels (axes, beams)
    series: np.ndarray | None = None  # per row: id of its time-ordered series (−1: none), for serial correlation
    scale_free: dict = field(default_factory=dict)  # blocks freed only to measure auxiliary rows' noise scale
    generic: list = field(default_factory=list)  # [(Conditions, {driver: per-sample values})] for residual:<driver>
    generic_width: int = 3  # outputs per sample the generic extension adds to (axes, beams)
    # driver → where a step is likeliest (P1: between holds in time, where the unit is handled);
    # the step scan's grid is moved to the nearest of them and refined over them as well
    step_places: dict = field(default_factory=dict)
    # driver → further places a step may fall (P1: between the parts of a hold, a knock or a
    # switched current during a hold): the grid is moved to the nearest of them as well, those
    # members counted as tests too, and the refinement runs over them
    step_places_within: dict = field(default_factory=dict)
    # whether a pulse in time (a bias on between two places) is among the generic shapes: in a
    # continuous series (compass, LDV), not where the unit rests in holds (P1, P4), where a bias on
    # for a hold or two is what a knock does to them, which the quality screen reports by line (a
    # pulse over P1 holds 7 and 8 took a 0.02 m/s² knock on hold 7), and where P4 bias steps at 10σ
    # were named 8 times in 10 with it, 9 without (seeds 763000+)
    pulses: bool = False
    generic_scale: float = 2.0  # the generic extension's margin over the canonical test (nulls)
    fold_sets: dict = field(default_factory=dict)  # other CV groupings by name (e.g. "time": blocks within holds)
    dead_rtol: float = DEAD_RTOL  # a candidate column less outside the baseline's span than this: dead
    cv_rows: dict = field(default_factory=dict)  # fold set name → rows its held-out RMS is taken on
    cv_groups: np.ndarray | None = None  # the default CV folds when they are not ``groups`` (P2: rows across mountings)
    cv_max_folds: int = MAX_FOLDS  # at most this many default folds (more groups are dealt into them in order)
    screened: list = field(default_factory=list)  # quality findings of rows left out before the effect search
    findings: list = field(default_factory=list)  # other quality findings the problem's rows gave (compass dip)
    # a constant the baseline lacks → {time-like candidate: its driver}: the constant is that candidate's
    # value at its own zero, which the data do not fix (a drift from power-up has a mean); both named: tied
    intercept_of: dict = field(default_factory=dict)
    # row kind → scale F of the exact F test of a candidate whose columns touch only that kind's
    # rows (its own rows, noise scale and residual degrees of freedom: ``kind_quantile``); a
    # candidate touching several kinds, or a kind not listed, keeps the procedure's test
    kind_thresholds: dict = field(default_factory=dict)
    # candidate name → its own scale F, where the nulls measured it apart from the procedure's:
    # a noise that wanders slowly in time (bias instability, a hard iron that creeps) inflates
    # the deviance of candidates with slow signatures far more than of those that change with
    # each orientation, which the serial-correlation inflation (a finite window) under-corrects
    cand_thresholds: dict = field(default_factory=dict)
    # per row: the id of the group of rows whose noise is one (``independent_groups``); None:
    # every row its own. What the generic extension's degrees of freedom are counted in.
    shared_noise: np.ndarray | None = None
    # the shared-noise test (``shared_inflation``) from the first candidate on, not only beside effects
    # already named: P4's block means share a bias instability over tens of seconds, which a line or
    # a step in time fits on the first round (blind generator nulls: 18 of 20 named)
    shared_first: bool = False
    # the groups a generic term must leave free beside the model it is named in (``independent_groups``)
    min_groups: float = MIN_DOF
    # a row the tested model fits with a leverage above this is left out of the held-out comparison
    # of that model with the current one (None: every row counts): it alone determines some
    # direction of the parameters, so its held-out prediction is an extrapolation along that
    # direction and tests nothing (a P2 table with one high speed: each of its rows carries the
    # baseline's D and the cubic's C3 by itself, and their held-out errors, 10-100 times the
    # noise, decided against a 10σ cubic)
    cv_max_leverage: float | None = None
    # whether a generic term (``residual:<driver>``) is compared on those rows too (False: on every
    # row): a flexible term overfits exactly where a row alone fixes a direction, which is what the
    # held-out test of a 6–12 parameter function must see (P1 tables of averages)
    cv_leverage_generic: bool = True
    # the auxiliary rows' noise scale (variance components) measured again after each selection,
    # against the refitted extended model, instead of once on the baseline (compass: measured there)
    aux_scale_refit: bool = False
    # per auxiliary row kind, the least σ its measured scale may give a row (that kind's units):
    # on exact data the scale would follow the rounding down (compass dip rows 1e-10, 1e10 below
    # the magnitude rows, and the refit went astray: an exact tumble named `field_anomaly`)
    aux_noise_floor: dict = field(default_factory=dict)
    # per auxiliary row kind, each row's white noise from the noise model (that kind's units): a
    # candidate that touches that kind and others counts that kind as ``ΔRSS / s²`` with the
    # scale ``s`` measured on the candidate's own residual there (its degrees of freedom), never
    # below this, instead of ``n ln(RSS₀/RSS₁)``, whose scale the effect itself inflates in the
    # baseline and which saturates on a few rows (compass dip rows, 17 holds: a temperature bias
    # at 10σ, ΔRSS 12.4 at that scale, counted 26.3 there, 34.0 so; unnamed before); empty: off
    aux_noise_model: dict = field(default_factory=dict)
    # the noise of each ``series`` was measured as the spread of the baseline's residual: after each
    # selection it is measured again on the refitted model's residual and lowered where that is
    # smaller (an LDV offset of 10 m/s left 3.8 m/s of baseline residual against 0.01 m/s of noise,
    # and every later test and the offset's own uncertainty were 300 times too lenient)
    series_scale_refit: bool = False
    # the smallest noise a real capture of this kind has (data units of the measured rows): a model
    # whose residual RMS is below it has nothing left to explain, and no candidate is sought beside
    # it (a simulator's exact table at full precision: the F tests, scale-free, found a quadratic
    # and a scale asymmetry in a P1 baseline's 3e-7 m/s² of rounding; None: no floor)
    noise_floor: float | None = None
    # per row: its time (s) where the rows of each ``series`` share a slow wander (bias instability):
    # a candidate's deviance is then taken net of a white + Gauss–Markov noise fitted by REML on
    # the residual its own model leaves (``wander.WanderModel``); None: no such model
    wander_t_s: np.ndarray | None = None
    # with ``wander_t_s``: a candidate is also tested against the wander where the residual the
    # model leaves *without* it wanders (a line or a step that takes a wander whole leaves a white
    # residual of its own), and its profiled ratio is calibrated on records of noise alone drawn
    # from the wander fitted beside it (``WanderModel.null_lr``; ``_null_equivalent``)
    wander_calibrated: bool = False
    series_names: dict = field(default_factory=dict)  # a series id's name for a person (P4's axes, the LDV's beams)
    # series 0's whiteness test (primary rows beside auxiliary ones, the compass) also over this many
    # lags, the rows of some seconds (Bonferroni over the two): 20 lags at 8 Hz span 2.5 s, and a
    # bias that swings over 8–25 s left p 0.08 there, 3e-6 over 10 s (QA s27d seed 700125); None: 20 lags
    whiteness_lags: int | None = None
    # narrow candidate → wide candidate whose span holds the narrow one's whole (P4 without headings:
    # the Earth rate's up part is an isotropic G f): the narrow one named, the wide one is tied to it
    nested: dict = field(default_factory=dict)
    # named candidate → (other candidate, fn(params, sigma) → reason or None): after the final refit,
    # the other goes in the named one's ``confused_with`` (with the reason) when fn says it could have
    # made what the named one fitted (P4 without headings: G f no larger than the Earth rate can be)
    could_be: dict = field(default_factory=dict)
    # per row pair: the covariance of a slow noise the rows share, in the data's unit squared, known
    # before the fit (a prior: P2's bias instability between hold means, sized from the within-hold
    # white noise, ``solvers.allan``). A candidate's deviance is then taken net of it: its likelihood
    # ratio under the rows' noise ``diag(σ²) + slow_cov`` (``slow_prior_lr``). None: the rows' σ alone
    slow_cov: np.ndarray | None = None
    # what the slow-noise prior is (or why there is none), for the report
    slow_noise: dict = field(default_factory=dict)
    _wander: object = None
    _slow_chol: tuple | None = None


@dataclass
class Diagnosis:
    procedure: str
    baseline: FitResult
    baseline_cv_rms: float
    candidates: list[dict]
    effects: list[dict]
    verdict: list[str]
    extended: FitResult
    extended_cv_rms: float
    extended_names: list[str]
    residual_test: dict
    studentized: np.ndarray  # extended residual / (sigma · noise scale)
    model: str
    extended_model: str
    problem: Problem
    deviance: dict = field(default_factory=dict)  # first round: {name: {D, k, q, cv_lower}} (benchmark)
    subs: dict = field(default_factory=dict)  # {key: (Diagnosis, input)} of a second sensor (station diagnose)

    def rms(self, fitres: FitResult) -> float:
        """Residual RMS in data units over the primary rows (all rows of one kind)."""
        r = fitres.residuals
        if self.problem.row_types is not None:
            r = r[np.asarray(self.problem.row_types) == 0]
        return float(np.sqrt(np.mean(r**2))) if r.size else 0.0


# ---------------------------------------------------------------- linear algebra helpers


def _weighted(problem: Problem, params: dict) -> np.ndarray:
    return np.asarray(problem.residual(params), dtype=float).ravel() / problem.sigma


def jacobian(problem: Problem, params: dict, free: dict) -> tuple[np.ndarray, list[str], Packer]:
    """Central-difference Jacobian of the weighted residual w.r.t. the free elements."""
    packer = Packer.build(params, free)
    x0 = packer.pack(packer.template)
    J = np.empty((problem.sigma.size, x0.size))
    for k in range(x0.size):
        h = 1e-6 * max(1.0, abs(x0[k]))
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        J[:, k] = (_weighted(problem, packer.unpack(xp)) - _weighted(problem, packer.unpack(xm))) / (2 * h)
    return J, packer.names, packer


def _solve_normal(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimum-norm solution of ``G x = b`` (G a Gram matrix), columns scaled first."""
    d = np.sqrt(np.clip(np.diag(G), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    x, *_ = linalg.lstsq(G / np.outer(d, d), b / d, rcond=1e-12)
    return x / d


def _lstsq_rss(A: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float]:
    """``d`` minimising ``|r + A d|²`` and that minimum."""
    if A.shape[1] == 0:
        return np.zeros(0), float(r @ r)
    d = _solve_normal(A.T @ A, -(A.T @ r))
    e = r + A @ d
    return d, float(e @ e)


def folds_of(groups: np.ndarray, max_folds: int = MAX_FOLDS) -> np.ndarray:
    """Fold index per row: each group its own fold, or groups dealt into ``max_folds`` folds in order."""
    uniq, inv = np.unique(np.asarray(groups), return_inverse=True)
    if len(uniq) <= max_folds:
        return inv
    return (inv * max_folds) // len(uniq)


def cv_rms(A: np.ndarray, r: np.ndarray, sigma: np.ndarray, folds: np.ndarray, primary=None, rows=None) -> float:
    """RMS (data units) of held-out predictions of the linearised model ``r + A d``, over the
    ``primary`` rows (all when None; auxiliary rows of other units still help the fit);
    only over ``rows`` (a mask) when given."""
    out = r.copy()
    if A.shape[1]:
        G, b = A.T @ A, A.T @ r
        for f in np.unique(folds):
            test = folds == f
            At, rt = A[test], r[test]
            d = _solve_normal(G - At.T @ At, -(b - At.T @ rt))
            out[test] = rt + At @ d
    if primary is not None:
        # rows of several kinds: weighted residuals in noise-equivalent units of the primary rows
        e = out * float(np.median(sigma[primary]))
    else:
        e = out * sigma
    if rows is not None:
        e = e[rows]
    return float(np.sqrt(np.mean(e**2)))


def chi2_isf(p: float, k: int) -> float:
    """Upper-tail quantile of χ²_k."""
    return 2.0 * float(gammainccinv(k / 2.0, p))


def deviance_quantile(problem: Problem, k: int, m: int, n: int, dof: int, scale: float = 1.0) -> float:
    """Level-α/m bound, at noise scale ``scale``, on the deviance ``n ln(RSS₀/RSS₁)`` of k added
    parameters with an unknown noise scale and ``dof`` residual degrees of freedom left: the exact
    F test, ``n ln(1 + k F_k,dof(1 − α/m) / dof)``, which tends to ``χ²_k(1 − α/m)`` for many rows.
    A table of a few dozen rows (P2) would otherwise pass a candidate on noise far more often
    than α says. One kind of rows: ``scale`` times that bound. Several kinds (one noise scale
    each, the deviance summed over them): ``scale`` holds the F statistic, as ``kind_quantile``
    does, ``n ln(1 + k·scale·F / dof)``; with hundreds of rows both are ``scale·χ²_k``, and with a
    table of averages of 10–30 positions the χ² bound passed a second candidate on the few
    degrees of freedom the first one left (P1: ``residual:temperature`` beside a quadratic)."""
    k = max(k, 1)
    p = ALPHA / max(m, 1)
    if dof <= 0:
        return scale * chi2_isf(p, k)
    if problem.row_types is not None:
        return n * math.log1p(k * scale * float(fdtri(k, dof, 1.0 - p)) / dof)
    return scale * n * math.log1p(k * float(fdtri(k, dof, 1.0 - p)) / dof)


def kind_quantile(k: int, m: int, n_kind: int, dof_kind: float, scale: float = 1.0) -> float:
    """Bound on the deviance ``n_t ln(RSS₀/RSS₁)`` over the ``n_t`` rows of one kind when k
    parameters that move only those rows are added, with that kind's noise scale unknown
    (estimated from the same rows) and ``dof_kind`` degrees of freedom left in them: the exact
    F test at level α/m, ``n_t ln(1 + k·scale·F_k,dof(1 − α/m) / dof)``, its F statistic
    ``(RSS₀ − RSS₁)/k / (RSS₁/dof)`` held to ``scale`` times the F quantile (a noise that is
    not white inflates that variance ratio). With a dozen rows (the compass dip rows) this
    is far above ``χ²_k``, and a χ² bound would saturate: the deviance of a large effect grows
    only as ``n_t ln(1 + λ/n_t)``."""
    k = max(k, 1)
    p = ALPHA / max(m, 1)
    if dof_kind <= 0:
        return math.inf
    return n_kind * math.log1p(k * scale * float(fdtri(k, dof_kind, 1.0 - p)) / dof_kind)


def selection_threshold(problem: Problem, k: int, n: int, m: int) -> float:
    """ΔBIC below which a k-parameter candidate (one of m) is selected:
    ``k ln n − F·χ²_k(1 − α/m)`` — a deviance test at level α/m whose scale ``F`` (the
    procedure's ``threshold``) is measured on null simulations, written as a ΔBIC bound."""
    return k * math.log(n) - problem.threshold * chi2_isf(ALPHA / max(m, 1), max(k, 1))


def bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def floored_rss(e: np.ndarray, floor=None) -> float:
    """``e·e``; with ``floor`` = (σ, f) of the same rows (``row_floor``, data units), scaled up to
    the floor where the residual in data units is below it (exact data: rounding, whose ratio
    between two fits is arbitrary, counts as the floor in both)."""
    r = float(e @ e)
    if floor is None:
        return r
    sigma, f = floor
    r_data, f_data = float(np.sum((e * sigma) ** 2)), float(np.sum(f**2))
    return r * f_data / max(r_data, 1e-300) if r_data < f_data else r


def typed_fit_term(e: np.ndarray, types, floor=None) -> float:
    """``Σ_t n_t ln(RSS_t / n_t)``: the Gaussian profile likelihood term with an unknown noise
    scale per kind of row (one kind when ``types`` is None); each RSS ``floored_rss``."""
    if types is None:
        return bic(floored_rss(e, floor), e.size, 0)
    out = 0.0
    for t in np.unique(types):
        sel = types == t
        fl = None if floor is None else (floor[0][sel], floor[1][sel])
        out += bic(floored_rss(e[sel], fl), int(sel.sum()), 0)
    return out


def row_floor(problem, sigma: np.ndarray, r_base: np.ndarray):
    """(σ, per-row noise floor) in data units for ``typed_fit_term``, or None: ``Problem.noise_floor``
    on the measured rows, ``aux_noise_floor`` on the others, each kind only where the baseline's
    weighted residual ``r_base`` is already below it there (exact data; a kind that a model with
    many parameters fits to 1e-8 of its noise is no rounding and keeps its RSS)."""
    if problem.noise_floor is None and not problem.aux_noise_floor:
        return None
    sigma = np.asarray(sigma, float)
    types = np.zeros(sigma.shape, int) if problem.row_types is None else np.asarray(problem.row_types)
    kinds = problem.measured_kinds if problem.row_types is not None else {0}
    f = np.zeros(sigma.shape)
    for t in np.unique(types):
        sel = types == t
        fl = problem.noise_floor if int(t) in kinds else problem.aux_noise_floor.get(int(t))
        if fl and float(np.sqrt(np.mean((r_base[sel] * sigma[sel]) ** 2))) <= fl:
            f[sel] = fl
    return (sigma, f) if f.any() else None


def _orth(A: np.ndarray) -> np.ndarray:
    """Orthonormal basis of A's column space (through the scaled Gram matrix)."""
    if A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    d = np.linalg.norm(A, axis=0)
    d = np.where(d > 0, d, 1.0)
    As = A / d
    w, V = linalg.eigh(As.T @ As)
    keep = w > 1e-12 * max(w.max(), 1e-300)
    return (As @ V[:, keep]) / np.sqrt(w[keep])


def ljung_box(x: np.ndarray, lags: int = 20) -> dict:
    """Ljung–Box portmanteau test of whiteness on a time-ordered series."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    lags = max(1, min(lags, n // 5))
    den = float(x @ x)
    if n < 10 or den <= 0:
        return {"test": "ljung-box", "n": n, "statistic": None, "p_value": None, "white": None}
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(x[k:] @ x[:-k]) / den
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    p = float(gammaincc(lags / 2.0, q / 2.0))
    return {"test": "ljung-box", "lags": lags, "n": n, "statistic": q, "p_value": p, "white": bool(p > WHITE_P)}


def chi2_test(rw: np.ndarray, dof: int) -> dict:
    c = float(rw @ rw)
    dof = max(int(dof), 1)
    p = float(gammaincc(dof / 2.0, c / 2.0))
    return {
        "test": "chi-square",
        "chi2": c,
        "dof": dof,
        "reduced_chi2": c / dof,
        "p_value": p,
        "white": bool(p > WHITE_P),
    }


# ---------------------------------------------------------------- candidates


@dataclass
class _Cand:
    cand: Candidate
    params: dict  # null blocks (with the best scanned value)
    free: dict
    J: np.ndarray  # weighted Jacobian columns (identifiable ones)
    names: list[str]
    reason: str | None = None
    model_free: dict | None = None  # once picked: its free elements in the model (``refit_free`` when it earned them)


def _free_of(c: Candidate) -> dict:
    if c.free is not None:
        return dict(c.free)
    return {k: True for k in c.blocks if not (c.scan and k == c.scan[0])}


def _free_in_model(cc: _Cand) -> dict:
    """The free elements of a picked candidate's blocks in the extended model's refits."""
    free = cc.model_free if cc.model_free is not None else cc.free
    return {k: v for k, v in free.items() if k in cc.params}


def _with_refit_free(problem: Problem, cc: _Cand, fit_: FitResult, free: dict, sigma: np.ndarray):
    """``(fit, free)`` of the model with the picked ``cc`` given its ``refit_free`` elements, when they
    lower χ² by the decisive margin of as many parameters, ``F·k·F_{k,ν}(1 − α)`` with the noise
    scale taken beside them on ν degrees of freedom (none left: never); else ``fit_`` and ``free``
    as they are. Sets ``cc.model_free`` to what the model keeps."""
    rf = cc.cand.refit_free
    if rf is None:
        return fit_, free
    free2 = {**free, **{k: v for k, v in rf.items() if k in cc.params}}
    k_extra = len(Packer.build(fit_.params, free2).names) - len(Packer.build(fit_.params, free).names)
    if k_extra <= 0:
        return fit_, free
    try:
        fit2 = _refit(problem, dict(fit_.params), free2, sigma)
    except Exception:
        return fit_, free
    if fit2.dof < 1 or not (np.isfinite(fit2.chi2) and fit2.chi2 > 0):
        return fit_, free  # no noise left to measure the gain against (a table of as many rows as parameters)
    s2 = fit2.chi2 / fit2.dof
    # the decisive margin with the noise scale estimated on fit2.dof degrees of freedom (F, not χ²)
    margin = problem.threshold * k_extra * float(fdtri(k_extra, fit2.dof, 1.0 - ALPHA))
    if (fit_.chi2 - fit2.chi2) / s2 <= margin:
        return fit_, free
    cc.model_free = free2
    return fit2, free2


def _tie_intercepts(problem: Problem, named: list[dict]) -> None:
    """Each named constant of ``problem.intercept_of`` and each named time-like effect it is the zero
    point of go in each other's ``confused_with``, with the correlation of the constant and the
    driver counted from its lowest value (a drift that starts at zero)."""
    by_name = {e["name"]: e for e in named}
    for const, drivers in problem.intercept_of.items():
        for other, x in drivers.items():
            if const not in by_name or other not in by_name or x is None:
                continue
            d = np.asarray(x, float) - float(np.nanmin(x))
            rms = float(np.sqrt(np.nanmean(d * d)))
            corr = float(np.nanmean(d) / rms) if rms > 0 else 0.0
            for a, b in ((const, other), (other, const)):
                if all(c["name"] != b for c in by_name[a]["confused_with"]):
                    by_name[a]["confused_with"] = [*by_name[a]["confused_with"], {"name": b, "correlation": corr}]


def _tie_could_be(problem: Problem, named: list[dict], fitres: FitResult) -> None:
    """``problem.could_be``: a named effect whose fitted size another candidate could have made
    too gets that one in its ``confused_with``, with the reason (``why``) instead of a correlation."""
    names = {e["name"] for e in named}
    for e in named:
        other, fn = problem.could_be.get(e["name"], (None, None))
        if other is None or other in names or any(c["name"] == other for c in e["confused_with"]):
            continue
        why = fn(fitres.params, fitres.sigma)
        if why:
            e["confused_with"] = [*e["confused_with"], {"name": other, "why": why}]


def _candidate_columns(problem: Problem, base_params: dict, c: Candidate, Q: np.ndarray, r0: np.ndarray) -> _Cand:
    """Jacobian columns of ``c`` at ``base_params`` (best grid value when scanned), with the
    columns the baseline already spans removed (fixed at their null values)."""
    grid = [None] if c.scan is None else list(c.scan[1])
    r_perp = r0 - Q @ (Q.T @ r0)
    tried: dict = {}  # scanned value -> (rss, blocks, J, perp, names, free): a value on two grids is fitted once

    def evaluate(value):
        if value not in tried:
            blocks = as_params(c.blocks)
            if value is not None:
                blocks[c.scan[0]] = np.array(float(value))
            params = {**base_params, **blocks}
            free = {k: False for k in base_params}
            free.update(_free_of(c))
            J, names, _ = jacobian(problem, params, free)
            perp = J - Q @ (Q.T @ J)
            tried[value] = (_lstsq_rss(perp, r_perp)[1], blocks, J, perp, names, free)
        return tried[value]

    if c.scan is not None and len(grid) > 2:
        # coarse grid, then finer ones around the best value, each a tenth of the last: a step's
        # time matters only through the samples it falls between, and at 1/400 of the span a
        # large step put a few samples on the wrong side, which a generic step then took
        step = float(grid[1] - grid[0])
        scores = [evaluate(float(v))[0] for v in grid]
        v0, best_rss = float(grid[int(np.argmin(scores))]), min(scores)
        for _ in range(SCAN_ZOOMS - 1):
            fine = np.linspace(v0 - step, v0 + step, 21)
            scores = [evaluate(float(v))[0] for v in fine]
            if min(scores) >= best_rss:  # nothing finer to find (the RSS is flat between samples)
                break
            v0, best_rss = float(fine[int(np.argmin(scores))]), min(scores)
            step /= 10.0
        grid = [float(v) for v in np.linspace(v0 - step, v0 + step, 21)]
    best = None
    for value in grid:
        ev = evaluate(value)
        if ev[2].shape[1] and (best is None or ev[0] < best[0]):
            best = ev
    if best is None:
        return _Cand(c, {}, {}, np.zeros((len(r0), 0)), [], "no free parameter")
    _, blocks, J, perp, names, free = best
    norm = np.linalg.norm(J, axis=0)
    pnorm = np.linalg.norm(perp, axis=0)
    keep = (norm > 0) & (pnorm > problem.dead_rtol * np.where(norm > 0, norm, 1.0))
    if not keep.any():
        return _Cand(
            c,
            blocks,
            free,
            J[:, :0],
            [],
            "its signature is indistinguishable from the baseline "
            "parameters in this capture (the data do not vary its driver independently)",
        )
    # fix the dead elements at their null values
    packer = Packer.build({**{k: v for k, v in blocks.items()}}, {k: free.get(k, False) for k in blocks})
    dead = [n for n, k in zip(names, keep) if not k]
    if dead:
        mask = {k: np.array(packer.free[k]) for k in blocks}
        for name in dead:
            block, idx = _split_name(name)
            if block in mask:
                m = mask[block]
                if m.ndim == 0:
                    mask[block] = np.array(False)
                else:
                    m[idx] = False
        free = {**{k: False for k in base_params}, **mask}
    return _Cand(c, blocks, free, J[:, keep], [n for n, k in zip(names, keep) if k])


def _split_name(name: str):
    if "[" not in name:
        return name, ()
    block = name[: name.index("[")]
    idx = tuple(int(p) for p in name[name.index("[") + 1 : -1].split("]["))
    return block, idx


# ---------------------------------------------------------------- serial correlation


def _acf(x: np.ndarray, lags: int) -> np.ndarray:
    """Autocorrelation ρ(0..lags) of a (mean-removed) series by FFT."""
    n = len(x)
    m = 1 << int(math.ceil(math.log2(max(2 * n, 2))))
    f = np.fft.rfft(x, m)
    ac = np.fft.irfft(f * np.conj(f), m)[: lags + 1]
    return ac / ac[0] if ac[0] > 0 else np.zeros(lags + 1)


def serial_inflation(e: np.ndarray, s: np.ndarray, series: np.ndarray | None) -> float:
    """How much serial correlation of the residual ``e`` inflates the variance of the
    statistic ``sᵀe`` (``s`` a fitted signature) over white noise: per time-ordered series,
    ``1 + 2 Σ_k w_k ρ_e(k) ρ_s(k)`` with a Bartlett taper ``w_k = 1 − k/(L+1)``, L = n/4,
    weighted by each series' share of ``|s|²``; rows outside a series (−1) count 1. At
    least 1: a deviance is never made larger than the white-noise one."""
    if series is None:
        return 1.0
    series = np.asarray(series)
    num = den = 0.0
    for sid in np.unique(series):
        m = series == sid
        ss = s[m]
        w2 = float(ss @ ss)
        if w2 <= 0:
            continue
        den += w2
        n = int(m.sum())
        if sid < 0 or n < 8:
            num += w2
            continue
        L = max(2, n // 4)
        ee = e[m] - np.mean(e[m])
        taper = 1.0 - np.arange(1, L + 1) / (L + 1.0)
        re, rs = _acf(ee, L), _acf(ss - np.mean(ss) if n > 1 else ss, L)
        num += w2 * (1.0 + 2.0 * float(np.sum(taper * re[1:] * rs[1:])))
    return max(1.0, num / den) if den > 0 else 1.0


def _group_directions(groups: np.ndarray, sigma: np.ndarray):
    """(means, spread, ng): the ``ng`` groups' mean directions in the weighted rows, orthonormal
    (row i of group g has ``w_i / |w_g|``, ``w = 1/σ``: a common offset of the group in the
    data). ``means(x)`` gives a row vector's or matrix's coordinates on them, ``spread(U)`` puts
    such coordinates back on the rows."""
    _, inv = np.unique(groups, return_inverse=True)
    ng = int(inv.max()) + 1 if inv.size else 0
    w = 1.0 / sigma
    u = w / np.sqrt(np.bincount(inv, weights=w**2, minlength=ng))[inv]

    def col(x: np.ndarray) -> np.ndarray:
        return u.reshape((-1,) + (1,) * (x.ndim - 1))

    def means(x: np.ndarray) -> np.ndarray:
        U = np.zeros((ng,) + x.shape[1:])
        np.add.at(U, inv, col(x) * x)
        return U

    def spread(U: np.ndarray) -> np.ndarray:
        return col(U) * U[inv]

    return means, spread, ng


def group_means(groups: np.ndarray, sigma: np.ndarray):
    """(means, ng): ``means(x)`` gives a row vector's or matrix's coordinates on the ``ng`` groups'
    mean directions in the weighted rows (``_group_directions``)."""
    means, _, ng = _group_directions(groups, sigma)
    return means, ng


def shared_inflation(problem: Problem, Q: np.ndarray, e: np.ndarray, s: np.ndarray) -> float:
    """How much noise that the rows of a group share (``problem.shared_noise``: the parts of a P1
    hold share its slow bias instability) inflates the variance of the statistic ``sᵀe`` over the
    one noise scale the deviance assumes: a one-way random-effects split of the residual ``e`` of
    the tested model (orthonormal columns ``Q``), on the groups of two rows or more, into the
    mean square of the group means (directions ``1/σ`` of each group's weighted rows) and the mean
    square within groups, each over its own degrees of freedom (the model's leverage on those
    directions taken out). ``s``'s energy on the group means is weighed with the first, the rest
    of it with the second, against the pooled mean square; rows in no shared group count 1. A
    signature that lives on the hold means (a line in time) is tested against the scatter of the
    hold means, not against the within-hold scatter that makes most of the rows' residual. At
    least 1; 1 where either part has no degrees of freedom left."""
    if problem.shared_noise is None:
        return 1.0
    g = np.asarray(problem.shared_noise)
    _, inv, cnt = np.unique(g, return_inverse=True, return_counts=True)
    multi = (cnt[inv] >= 2) & (g >= 0)
    if not multi.any():
        return 1.0
    idx = np.flatnonzero(multi)
    means, ng = group_means(inv[idx], np.asarray(problem.sigma, float)[idx])
    eg, sg, Qg = e[idx], s[idx], Q[idx]
    ssb = float(np.sum(means(eg) ** 2))
    ssw = float(eg @ eg) - ssb
    tr_b = float(np.sum(means(Qg) ** 2)) if Qg.shape[1] else 0.0
    tr_w = float(np.sum(Qg**2)) - tr_b
    dof_b, dof_w = ng - tr_b, len(idx) - ng - tr_w
    if dof_b < 1 or dof_w < 1 or ssw <= 0:
        return 1.0
    msb, msw = ssb / dof_b, ssw / dof_w
    pooled = (ssb + ssw) / (dof_b + dof_w)
    s2 = float(sg @ sg)
    tot = float(s @ s)
    if s2 <= 0 or tot <= 0:
        return 1.0
    sb = float(np.sum(means(sg) ** 2))
    var = (sb * msb + (s2 - sb) * msw) / pooled
    return max(1.0, (var + (tot - s2)) / tot)


# ---------------------------------------------------------------- generic extension

GENERIC_STEP_GRID = np.linspace(0.1, 0.9, 13)  # step positions, fractions of the driver's range
# periodic: cycles over the span scanned half a cycle apart; counted as tests one cycle apart (sines
# a whole cycle apart over the span are orthogonal: the independent ones). One apart, a period
# midway between two members left each of them sinc²(½) = 40 % of its signal, and the refinement
# went to a member the noise favoured (a compass periodic bias at 10σ: D 47 there, 125 at its period)
GENERIC_CYCLES = np.arange(1.5, 30.01, 0.5)
GENERIC_CYCLE_TESTS = int(round(float(GENERIC_CYCLES[-1] - GENERIC_CYCLES[0]))) + 1
SCAN_ZOOMS = 4  # a library candidate's scanned scalar: the coarse grid's step over 10, 100, 1000 around its best
GENERIC_REFINE = 21  # a scanned family's best member is refined on this many values within ±1 grid step
GENERIC_SMOOTH_KNOTS = (3, 5)  # piecewise-linear bases (complexity chosen by CV)


def _hat_basis(x: np.ndarray, knots: int) -> np.ndarray:
    """Piecewise-linear (hat) functions on ``knots`` equally spaced knots over x's range, minus the constant."""
    lo, hi = np.nanmin(x), np.nanmax(x)
    c = np.linspace(lo, hi, knots)
    h = (hi - lo) / max(knots - 1, 1)
    B = np.clip(1.0 - np.abs(x[:, None] - c[None, :]) / h, 0.0, None)
    return B[:, 1:] - B[:, 1:].mean(axis=0)


def _slope(fn, x: np.ndarray) -> np.ndarray:
    """``d fn(x)[n, p, k] / d x[n, k]`` of a per-axis basis (central differences, 1e-6 of each axis' range)."""
    e = 1e-6 * np.maximum(np.ptp(x, axis=0), 1e-300)
    return (fn(x + e) - fn(x - e)) / (2 * e)


def _fold_for(driver: str) -> str | None:
    """Temporal and thermal structure is validated on time blocks where a problem has them, a
    generic function of the input on the problem's ``input`` folds where it has them (P1: whole
    positions, whose per-position noise a smooth function of the input would fit otherwise)."""
    if driver in ("time", "temperature"):
        return "time"
    return "input" if driver in ("input", "input_axis") else None


def generic_candidates(problem: Problem, pulses: bool = True) -> list[tuple[Candidate, dict]]:
    """The ``residual:<driver>`` candidates: (candidate, description) per driver and shape.
    Each candidate's block ``bR`` (p × width) multiplies a basis of the driver that its
    ``setup`` writes into every condition set of ``problem.generic`` (solvers.models.additive_terms).
    ``pulses``: whether a bias on between two places in time (78 pairs, the dearest family) is
    among them."""
    out = []
    if not problem.generic:
        return out
    conds = problem.generic
    width = problem.generic_width
    names = set()
    for _, d in conds:
        names |= {k for k, v in d.items() if v is not None}
    for drv in sorted(names):
        vals = [np.asarray(d.get(drv), float) if d.get(drv) is not None else None for _, d in conds]
        if any(v is None or not np.all(np.isfinite(v)) for v in vals):
            continue
        allv = np.concatenate([v.reshape(len(v), -1)[:, 0] if v.ndim > 1 else v for v in vals])
        lo, hi = float(np.min(allv)), float(np.max(allv))
        span = hi - lo
        if not span > 0 or np.unique(np.round(allv, 9)).size < 4:
            continue
        per_axis = drv.endswith("_axis")

        def make(fn, p, desc, drv=drv, per_axis=per_axis):
            def setup():
                for cond, d in conds:
                    x = np.asarray(d[drv], float)
                    cond.extra["basis"] = fn(x)
                    # d basis / d input per axis (N, p, k): a term in the measured input moves with
                    # the output's noise, which a problem whose weights follow the model needs
                    cond.extra["basis_dinput"] = _slope(fn, x) if per_axis else None

            blocks = {"bR": np.zeros((p, width))}
            return (Candidate(f"residual:{drv}", blocks, setup=setup, folds=_fold_for(drv)), dict(desc, driver=drv))

        if per_axis:  # a smooth function of each axis' own input (its linear part is the scale)
            if all(v.ndim == 2 and v.shape[1] == width for v in vals):
                a_lo = np.min([v.min(axis=0) for v in vals], axis=0)
                a_hi = np.max([v.max(axis=0) for v in vals], axis=0)
                for K in GENERIC_SMOOTH_KNOTS:

                    def axis_fn(x, K=K, a_lo=a_lo, a_hi=a_hi):  # hats on K knots over each axis' range (all rows)
                        out = []
                        for j in range(x.shape[1]):
                            c = np.linspace(a_lo[j], a_hi[j], K)
                            h = max((a_hi[j] - a_lo[j]) / (K - 1), 1e-300)
                            out.append(np.clip(1.0 - np.abs(x[:, j, None] - c[None, 1:]) / h, 0.0, None))
                        return np.stack(out, axis=2)

                    out.append(make(axis_fn, K - 1, {"shape": "smooth", "knots": K, "per_axis": True}))
            continue
        base = drv.split(":")[0]
        if base not in ("time", "temperature"):
            out.append(make(lambda x, lo=lo, span=span: ((x - lo) / span - 0.5)[:, None], 1, {"shape": "linear"}))
        if base in ("time", "temperature") and "input_axis" in names:
            ia = [np.asarray(d["input_axis"], float) for _, d in conds]
            if all(a is not None and a.ndim == 2 for a in ia):

                def scale_fn_factory(drv=drv, lo=lo, span=span):
                    def setup():
                        for cond, d in conds:
                            x = (np.asarray(d[drv], float) - lo) / span - 0.5
                            cond.extra["basis"] = (x[:, None] * np.asarray(d["input_axis"], float))[:, None, :]
                            cond.extra["basis_dinput"] = np.broadcast_to(x[:, None, None], cond.extra["basis"].shape)

                    return setup

                out.append(
                    (
                        Candidate(
                            f"residual:{drv}",
                            {"bR": np.zeros((1, width))},
                            setup=scale_fn_factory(),
                            folds=_fold_for(drv),
                        ),
                        {"shape": "linear", "acts_on": "scale", "driver": drv},
                    )
                )
        if base == "time":  # a bias that jumps (a current switched on, a knock)

            def step(x0, make=make):
                return make(lambda x, x0=x0: (x >= x0).astype(float)[:, None] - 0.5, 1, {"shape": "step", "at": x0})

            dx = float(GENERIC_STEP_GRID[1] - GENERIC_STEP_GRID[0]) * span
            grid = lo + GENERIC_STEP_GRID * span
            places = np.asarray(problem.step_places.get(drv, []), float)
            places = places[(places > lo) & (places < hi)]
            within = np.asarray(problem.step_places_within.get(drv, []), float)
            within = within[(within > lo) & (within < hi)]

            def snap(grid, at):  # each grid value moved to the nearest of the places ``at``
                return np.unique(at[np.argmin(np.abs(grid[:, None] - at[None, :]), axis=1)])

            if places.size or within.size:
                # a step between holds (where the unit is handled) and one within a hold both get their
                # own grid: a step within a hold sits between two parts, and a grid of places between
                # holds only never reached it (a P1 step of 10σ in a hold of 13: ΔBIC 19 at the best
                # place between holds, 153 between the hold's parts)
                grid = np.union1d(
                    snap(grid, places) if places.size else grid, snap(grid, within) if within.size else []
                )
                places = np.union1d(places, within)

            def refine(d, step=step, dx=dx, places=places):
                near = places[np.abs(places - d["at"]) <= dx]
                return [step(at) for at in np.union1d(np.linspace(d["at"] - dx, d["at"] + dx, GENERIC_REFINE), near)]

            out.append(("scan", [step(at) for at in grid], refine))

            def pulse(a, b, make=make):  # on at a, off again at b (a current switched on, then off)
                return make(
                    lambda x, a=a, b=b: ((x >= a) & (x < b)).astype(float)[:, None] - 0.5,
                    1,
                    {"shape": "step", "at": a, "until": b},
                )

            pairs = [(a, b) for i, a in enumerate(grid) for b in grid[i + 1 :]]

            def refine_pulse(d, pulse=pulse, dx=dx, places=places):
                a, b = d["at"], d["until"]
                out_ = []
                for v in np.union1d(np.linspace(a - dx, a + dx, GENERIC_REFINE), places[np.abs(places - a) <= dx]):
                    if v < b:
                        out_.append(pulse(v, b))
                for v in np.union1d(np.linspace(b - dx, b + dx, GENERIC_REFINE), places[np.abs(places - b) <= dx]):
                    if v > a:
                        out_.append(pulse(a, v))
                return out_

            if pairs and pulses and problem.pulses:
                out.append(("scan", [pulse(a, b) for a, b in pairs], refine_pulse))

            def periodic(c, make=make, span=span):  # c cycles over the span
                P = span / c
                return make(
                    lambda x, P=P: np.column_stack([np.sin(2 * np.pi * x / P), np.cos(2 * np.pi * x / P)]),
                    2,
                    {"shape": "periodic", "period": float(P)},
                )

            dc = float(GENERIC_CYCLES[1] - GENERIC_CYCLES[0])
            out.append(
                (
                    "scan",
                    [periodic(c) for c in GENERIC_CYCLES],
                    lambda d, periodic=periodic, span=span, dc=dc: [
                        periodic(c)
                        for c in np.linspace(span / d["period"] - dc, span / d["period"] + dc, GENERIC_REFINE)
                        if c > 0.5
                    ],
                    GENERIC_CYCLE_TESTS,
                )
            )
        for K in GENERIC_SMOOTH_KNOTS:
            if base in ("time", "temperature"):
                # the interior hats only (zero at both ends of the range): what a line (the
                # library's time_drift, temperature_bias) cannot be, so a smooth term never
                # stands in for a linear one

                def interior(x, K=K, lo=lo, hi=hi):
                    c = np.linspace(lo, hi, K)[1:-1]
                    return np.clip(1.0 - np.abs(x[:, None] - c[None, :]) / ((hi - lo) / (K - 1)), 0.0, None)

                out.append(make(interior, K - 2, {"shape": "smooth", "knots": K}))
            else:
                out.append(make(lambda x, K=K: _hat_basis(x, K), K - 1, {"shape": "smooth", "knots": K}))
    return out


# ---------------------------------------------------------------- the engine


def _aux_scales(problem: Problem, fit_: FitResult, free: dict, sigma: np.ndarray) -> None:
    """Variance components: the auxiliary rows (row kinds other than 0, prior σ) get the noise
    scale their residuals show under the model of ``fit_`` (``free``), with the ``scale_free``
    blocks freed for this step only (e.g. the compass dip constant); ``sigma`` is scaled in place.
    The primary rows keep their measured noise (the χ² test is about them)."""
    sfit = fit_
    if problem.scale_free:
        sfit = fit(problem.residual, fit_.params, free={**free, **problem.scale_free}, sigma=sigma)
    rw = sfit.weighted_residuals
    for k in np.unique(problem.row_types):
        if k in problem.measured_kinds:
            continue
        sel = problem.row_types == k
        s = math.sqrt(float(np.mean(rw[sel] ** 2)))
        if s > 0:
            sigma[sel] = np.maximum(sigma[sel] * s, problem.aux_noise_floor.get(int(k), 0.0))


def _series_scales(problem: Problem, fit_: FitResult, sigma: np.ndarray) -> bool:
    """Each series' noise lowered to the RMS its rows' residual has under ``fit_`` where that is
    smaller (``Problem.series_scale_refit``); ``sigma`` is scaled in place. True when it changed."""
    if not problem.series_scale_refit or problem.series is None:
        return False
    rw = fit_.weighted_residuals
    series = np.asarray(problem.series)
    changed = False
    for k in np.unique(series):
        sel = series == k
        s = math.sqrt(float(np.mean(rw[sel] ** 2)))
        if 0 < s < 1.0:
            sigma[sel] *= s
            changed = True
    if changed:
        problem._wander = None  # made with the old weights
    return changed


def below_noise_floor(problem: Problem, rw: np.ndarray, sigma: np.ndarray, primary=None) -> bool:
    """Whether the weighted residual ``rw`` is, in data units over the measured rows, below
    ``problem.noise_floor`` (RMS): nothing is left there for an effect to explain."""
    if problem.noise_floor is None:
        return False
    e = np.asarray(rw, float) * sigma
    if primary is not None:
        e = e[primary]
    return bool(e.size) and float(np.sqrt(np.mean(e * e))) <= problem.noise_floor


def _unresolvable(name: str, reason: str) -> dict:
    """A candidate's entry when it cannot be tested, saying why."""
    return {"name": name, "delta_bic": None, "cv_rms": None, "selected": False, "resolvable": False, "reason": reason}


def _nested_share(J_lib: np.ndarray, J_gen: np.ndarray, Q: np.ndarray) -> float:
    """The least share (0..1) of a library candidate's columns ``J_lib``, outside the baseline's
    span ``Q``, that a generic term's columns ``J_gen`` span: 1 where the library effect is one of
    the generic term's own shapes (an LDV offset, a constant per beam, inside a smooth function of
    each beam's input)."""
    if J_lib.shape[1] == 0 or J_gen.shape[1] == 0:
        return 0.0
    L = J_lib - Q @ (Q.T @ J_lib)
    live = np.linalg.norm(L, axis=0) > DEAD_RTOL * np.linalg.norm(J_lib, axis=0)
    if not live.any():  # the baseline spans it: nothing of it is left to nest
        return 0.0
    L = L[:, live]
    G = _orth(J_gen - Q @ (Q.T @ J_gen))
    return float(np.min(np.linalg.norm(G.T @ L, axis=0) / np.linalg.norm(L, axis=0)))


def _displaced(picked: list, kept: list) -> list:
    """The items of ``picked`` (candidate columns, effect entry) that ``kept`` no longer holds."""
    return [item for item in picked if not any(item[0] is k[0] for k in kept)]


def _refit(problem: Problem, params: dict, free: dict, sigma: np.ndarray) -> FitResult:
    """Nonlinear refit from the linearised step at ``params``. Where the refit or that step runs
    off along a direction the data hardly fix (``_ran_off``), it is done again with the matrix
    blocks that ran off held at their values in ``params``: the added terms take only what the
    model's scale and mounting cannot. A move the data fix firmly (held, the model leaves more
    than ``REFIT_HELD_CHI2_RATIO`` times the free refit's χ²) is kept: then ``params``' matrix
    was the one off, having taken an effect the baseline had no term for."""
    Jx, _, packer = jacobian(problem, params, free)
    d, _ = _lstsq_rss(Jx, _weighted(problem, params))
    start = packer.unpack(packer.pack(packer.template) + d)
    try:
        res = fit(problem.residual, start, free=free, sigma=sigma)
        if res.chi2 > float(np.sum(_weighted(problem, start) ** 2)) * 1.0001:
            raise ValueError("refit worse than its start")
    except Exception:
        res = fit(problem.residual, start, free=free, sigma=sigma, max_nfev=1)
    chi2_at = float(np.sum(_weighted(problem, params) ** 2))
    if not res.chi2 <= chi2_at * 1.0001:
        # the linearised step led into a worse basin than ``params`` (a nested model: an added
        # effect at 0) had: refitted from ``params`` itself, so adding a term never fits worse
        # (a P1 drift beside a scale asymmetry on 11 unlabelled positions: 214 worse in deviance)
        try:
            res = fit(problem.residual, params, free=free, sigma=sigma)
        except Exception:
            pass
    off = _ran_off(params, start, free, problem.baseline) or _ran_off(params, res.params, free, problem.baseline)
    if off:
        held = _refit(problem, params, {**free, **{k: False for k in off}}, sigma)
        if (
            np.isfinite(res.chi2)
            and held.chi2 > REFIT_HELD_CHI2_RATIO * res.chi2
            and _rescaled_within(params, res.params, off)
        ):
            return res
        return held
    return res


def _rescaled_within(before: dict, after: dict, keys) -> bool:
    """Whether each matrix block ``keys`` keeps its norm within a factor ``REFIT_FIRM_MAX_SCALE``
    from ``before`` to ``after``: a move the data fix firmly changes a scale and mounting by a
    fraction (the LDV's X row 1.5 → 1.0 beside a 10 m/s offset), the degenerate fit of a norm-only
    model by orders of magnitude (P1 on unlabelled positions: K 1e5 times its size, every
    position read as one specific force, χ² 1e-8 of the noise's)."""
    for k in keys:
        a, b = float(np.linalg.norm(before[k])), float(np.linalg.norm(after[k]))
        if not (a > 0 and b > 0 and 1.0 / REFIT_FIRM_MAX_SCALE <= b / a <= REFIT_FIRM_MAX_SCALE):
            return False
    return True


def _ran_off(before: dict, after: dict, free: dict, baseline: dict) -> list[str]:
    """The free matrix blocks of the baseline model (a scale and mounting: P1's K, the LDV's X,
    the compass's W; not an effect's blocks) that changed by more than ``REFIT_MAX_MATRIX_CHANGE`` of their norm from
    ``before`` to ``after``. No effect changes a sensor's scale by half; a refit does that only
    where an added term and the model share a direction the data hardly fix: an unlabelled P1
    table with a step in time went to K 25000 times its size, every position read as one
    specific force (held-out RMS 2e-5 m/s², 4 % of the noise); an LDV X shrank 40-fold beside
    a smooth function of each axis' input that took the mapping over, and a time delay named
    there had a gain of −305 %."""
    out = []
    for k, v in before.items():
        a, b = np.asarray(v, float), np.asarray(after.get(k, v), float)
        if k not in baseline or a.ndim != 2 or not np.any(free.get(k, False)) or a.shape != b.shape:
            continue
        size = float(np.linalg.norm(a))
        if size > 0 and float(np.linalg.norm(b - a)) > REFIT_MAX_MATRIX_CHANGE * size:
            out.append(k)
    return out


@dataclass
class _Eval:
    cc: _Cand
    delta_bic: float
    cv: float
    sig: np.ndarray
    k: int
    D: float  # deviance (unknown noise scale per row kind)
    infl: float  # serial-correlation inflation of that deviance
    desc: dict | None = None
    kind: int | None = None  # the one row kind its columns touch, when tested on it alone (kind_thresholds)
    n_kind: int = 0  # rows of that kind
    dof_kind: float = 0.0  # their residual degrees of freedom with the candidate fitted
    groups_left: float | None = None  # a generic term: degrees of freedom left in independent groups
    within: float | None = None  # its deviance on the rows within groups alone (where too few groups are left)
    cv_ref: float | None = None  # the current model's held-out RMS over the rows ``cv`` is taken on (None: all)
    wander_T: float | None = None  # its likelihood ratio with a slow wander profiled out (``WanderModel.lr``)
    wanders: bool = False  # whether the residual with it still wanders (then ``infl`` holds ``D / wander_T``)

    @property
    def D_rob(self) -> float:
        return self.D / self.infl


class _Round:
    """One round of candidate tests at a fixed linearisation ``r0 + A δ``: the Gram blocks of
    ``A`` (total and per CV fold) are formed once, each candidate adds only its own."""

    def __init__(self, A, r0, sigma, folds, primary, rows=None, max_leverage=None):
        self.A, self.r0, self.sigma, self.primary, self.rows = A, r0, sigma, primary, rows
        self.max_leverage = max_leverage
        self.out0 = None  # the current model's held-out residuals (weighted), when rows are masked
        self.fold_ids = [np.flatnonzero(folds == f) for f in np.unique(folds)]
        self.GA = A.T @ A
        self.bA = A.T @ r0
        self.GAf = [A[i].T @ A[i] for i in self.fold_ids]
        self.bAf = [A[i].T @ r0[i] for i in self.fold_ids]
        self.QA = _orth(A)
        self.wander0: dict = {}  # what the slow-noise test keeps of this model (``WanderModel.lr``)

    def _held_out(self, J):
        """Full-fit step δ, residual e and held-out residuals (weighted) of ``r0 + [A J] δ``."""
        A, r0 = self.A, self.r0
        p0 = A.shape[1]
        C = A.T @ J
        G = np.block([[self.GA, C], [C.T, J.T @ J]])
        b = np.concatenate([self.bA, J.T @ r0])
        d = _solve_normal(G, -b)
        e = r0 + A @ d[:p0] + J @ d[p0:]
        out = r0.copy()
        for i, GAf, bAf in zip(self.fold_ids, self.GAf, self.bAf):
            Ai, Ji, ri = A[i], J[i], r0[i]
            Cf = Ai.T @ Ji
            Gf = np.block([[GAf, Cf], [Cf.T, Ji.T @ Ji]])
            bf = np.concatenate([bAf, Ji.T @ ri])
            df = _solve_normal(G - Gf, -(b - bf))
            out[i] = ri + Ai @ df[:p0] + Ji @ df[p0:]
        return d, e, out

    def _rms(self, out, keep=None) -> float:
        if self.primary is not None:
            cv = out * float(np.median(self.sigma[self.primary]))
        else:
            cv = out * self.sigma
        mask = np.ones(len(cv), bool) if self.rows is None else np.asarray(self.rows, bool).copy()
        if keep is not None:
            mask &= keep
        return float(np.sqrt(np.mean(cv[mask] ** 2))) if mask.any() else 0.0

    def solve(self, J, leverage: bool = True):
        """(δ, full residual e, held-out RMS, the current model's held-out RMS over the same rows
        or None when that is all of them) of ``r0 + [A J] δ``; ``leverage`` False: every row
        counts, whatever ``max_leverage`` says."""
        d, e, out = self._held_out(J)
        if self.max_leverage is None or not leverage:
            return d, e, self._rms(out), None
        Q = _orth(np.hstack([self.A, J]))
        keep = np.sum(Q**2, axis=1) <= self.max_leverage
        if self.out0 is None:
            self.out0 = self._held_out(np.zeros((len(self.r0), 0)))[2]
        return d, e, self._rms(out, keep), self._rms(self.out0, keep)


class _Rounds:
    """The rounds of one linearisation, one per fold set (made when first asked for)."""

    def __init__(self, A, r0, sigma, fold_map, primary, max_leverage=None):
        self.args = (A, r0, sigma, primary)
        self.max_leverage = max_leverage
        self.fold_map = fold_map
        self.rounds: dict = {}
        self.cvs: dict = {}

    def get(self, key) -> _Round:
        key = key if key in self.fold_map else None
        if key not in self.rounds:
            A, r0, sigma, primary = self.args
            folds, rows = self._folds(key)
            self.rounds[key] = _Round(A, r0, sigma, folds, primary, rows, self.max_leverage)
        return self.rounds[key]

    def cv0(self, key) -> float:
        key = key if key in self.fold_map else None
        if key not in self.cvs:
            A, r0, sigma, primary = self.args
            folds, rows = self._folds(key)
            self.cvs[key] = cv_rms(A, r0, sigma, folds, primary, rows)
        return self.cvs[key]

    def _folds(self, key):
        """(fold per row, rows the held-out RMS is taken over or None) of a fold set."""
        f = self.fold_map[key]
        return f if isinstance(f, tuple) else (f, None)


def _gram_rank(G: np.ndarray) -> int:
    """Rank of a Gram matrix (columns scaled first), as matrix_rank of the tall matrix would give."""
    if G.shape[0] == 0:
        return 0
    d = np.sqrt(np.clip(np.diag(G), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    w = np.linalg.eigvalsh(G / np.outer(d, d))
    return int(np.sum(w > max(w.max(), 1e-300) * 1e-20)) if w.size else 0


def independent_groups(problem: Problem, A: np.ndarray, J: np.ndarray) -> float:
    """Degrees of freedom the data have left, counted in independent groups of rows, after the
    model ``A`` (weighted Jacobian) and a generic term's columns ``J``: the groups
    (``problem.shared_noise``) minus the rank the model has on the groups' shared noise (each
    column projected per group on the shared direction ``1/σ`` of its rows, as a common offset
    in the data is in the weighted rows) minus the term's **effective** rank there: of the
    term's part beyond the model (orthonormal columns ``q``), the energy ``Σ |P q|²`` that lies
    on the group means the model leaves free (``P``). A model that leaves no group free can fit
    every group's mean, noise included, and the rows within groups cannot test it; a term whose
    energy lies within groups (a period shorter than a hold averages out in its mean) is tested
    by the rows within them, and costs the groups only the part it has on their means.

    What it counts, per procedure: P1 time series, the holds (the 4 parts of a hold share its
    bias instability, so a smooth function of time sees one value per hold beyond what changes
    within it) and each labelled position's direction row (placement errors are independent);
    every other problem (P1 table of averages, P2, compass, P4, LDV), the rows."""
    n = A.shape[0]
    g = np.arange(n) if problem.shared_noise is None else np.asarray(problem.shared_noise)
    use = g >= 0  # −1: a row that carries no group's offset (a change across a hold), not counted
    grp_means, ng = group_means(g[use], np.asarray(problem.sigma, float)[use])

    def means(x):
        return grp_means(x[use])

    UA = means(A)
    r_A = _gram_rank(UA.T @ UA)
    QA = _orth(A)
    Jp = J - QA @ (QA.T @ J)  # the term beyond the model (what its deviance is made of)
    nJ = np.linalg.norm(J, axis=0)
    Uj, sj, _ = np.linalg.svd(Jp / np.where(nJ > 0, nJ, 1.0), full_matrices=False)
    Qt = Uj[:, sj > 1e-10]  # its directions, as many as the rank its test counts (_gram_rank)
    if Qt.shape[1] == 0:
        return float(ng - r_A)
    Ut = means(Qt)
    # the group means the model leaves free: remove the model's span there
    QUA = _orth(UA) if r_A else np.zeros((ng, 0))
    Ut = Ut - QUA @ (QUA.T @ Ut)
    return float(ng - r_A - float(np.sum(Ut**2)))


WITHIN_RANK_TOL = 1e-3  # a model column keeps less than this fraction of its norm within groups: none there


def within_groups_deviance(problem: Problem, A: np.ndarray, J: np.ndarray, r: np.ndarray) -> float:
    """Deviance of the term ``J`` beside the model ``A`` on the rows within groups alone: every
    column and the residual ``r`` (weighted rows) taken off the groups' mean directions (``1/σ``
    per group, what their shared noise moves; rows of group −1 carry none and stay whole), the
    model's part there removed, in units of the residual variance left there. The shared noise
    (a P1 hold's bias instability) is then no part of the test, which needs no free group."""
    g = np.asarray(problem.shared_noise)
    use = np.flatnonzero(g >= 0)
    means, spread, ng = _group_directions(g[use], np.asarray(problem.sigma, float)[use])

    def off(X):
        X = np.array(X, float, copy=True)
        X[use] -= spread(means(X[use]))
        return X

    # the model's part within groups, measured against its whole columns: K and b move the
    # parts of a hold together, and what is left of them within it (the data's own deviations
    # times 1e-4) is no direction the model can fit (orthonormalised alone, it took the effect)
    d = np.linalg.norm(A, axis=0)
    U, sv, _ = np.linalg.svd(off(A) / np.where(d > 0, d, 1.0), full_matrices=False)
    QA = U[:, sv > WITHIN_RANK_TOL]
    # the term's own part within groups, against its whole columns as well: a function of the
    # input, constant within a hold but for the noise, keeps ~1e-4 of itself there and fits nothing
    dj = np.linalg.norm(J, axis=0)
    Jw, rw = off(J) / np.where(dj > 0, dj, 1.0), off(r)
    Jw = Jw - QA @ (QA.T @ Jw)
    rw = rw - QA @ (QA.T @ rw)
    Uj, sj, _ = np.linalg.svd(Jw, full_matrices=False)
    Qj = Uj[:, sj > WITHIN_RANK_TOL]
    ss = float(np.sum((Qj.T @ rw) ** 2))
    dof = len(r) - ng - QA.shape[1] - Qj.shape[1]
    if dof < MIN_DOF or Qj.shape[1] == 0:
        return 0.0
    return ss / max((float(rw @ rw) - ss) / dof, 1e-300)


def _count_groups(problem: Problem, ev: _Eval, A: np.ndarray, scanned: int, r: np.ndarray | None = None) -> _Eval:
    """Set a generic term's ``groups_left`` (``independent_groups``, its ``scanned`` places or period
    counted as parameters) where the problem says which rows share their noise; where
    too few are left and the residual ``r`` is given, its deviance within groups (``within``)."""
    if problem.shared_noise is not None:
        ev.groups_left = independent_groups(problem, A, ev.cc.J) - int(scanned)
        if r is not None and ev.groups_left < problem.min_groups - GROUPS_TOL:
            ev.within = within_groups_deviance(problem, A, ev.cc.J, r)
    return ev


def _aux_model_terms(problem, rnd: _Round, Jp: np.ndarray, e: np.ndarray, types, floor=None) -> float:
    """What the ``aux_noise_model`` kinds add to a candidate's deviance (``Problem.aux_noise_model``):
    per such kind touched by the candidate's columns ``Jp`` (the current model projected out) beside
    other kinds, ``ΔRSS / s² − n ln(RSS₀/RSS₁)``, with ``s²`` the candidate's residual variance on
    those rows over their degrees of freedom left (rows minus both models' leverage on them), at
    least the noise model's mean variance there. ``e``: the candidate's residual (weighted)."""
    tot = float(np.sum(Jp**2))
    if tot <= 0:
        return 0.0
    r_cur = rnd.r0 - rnd.QA @ (rnd.QA.T @ rnd.r0)
    U, sv, _ = np.linalg.svd(Jp, full_matrices=False)
    Qj = U[:, sv > WITHIN_RANK_TOL * max(float(sv[0]), 1e-300)] if sv.size else U[:, :0]
    out = 0.0
    for t, sd_model in problem.aux_noise_model.items():
        sel = types == t
        if not sel.any() or float(np.sum(Jp[sel] ** 2)) <= 1e-9 * tot or float(np.sum(Jp[~sel] ** 2)) <= 1e-9 * tot:
            continue  # not touched, or touched alone (its own exact F test: ``kind_thresholds``)
        fl = None if floor is None else (floor[0][sel], floor[1][sel])
        rss0, rss1 = floored_rss(r_cur[sel], fl), floored_rss(e[sel], fl)
        n_t = int(sel.sum())
        dof = n_t - float(np.sum(rnd.QA[sel] ** 2)) - float(np.sum(Qj[sel] ** 2))
        if dof < MIN_DOF or rss1 <= 0 or rss0 <= rss1:
            continue
        w2 = float(np.mean((np.asarray(sd_model, float) / problem.sigma[sel]) ** 2))
        s2 = max(rss1 / dof, w2)
        out += (rss0 - rss1) / s2 - n_t * math.log(rss0 / rss1)
    return out


def _evaluate(problem, cc: _Cand, rnd: _Round, term_cur, types, n, floor=None, shared: bool = False) -> _Eval:
    """The tests of one candidate added to the round's model; ``floor``: the rows' noise floor
    (``row_floor``, once per analysis); ``shared``: its deviance is also taken net of the noise the
    rows of a group share (``shared_inflation``, a test beside library effects already named)."""
    A, QA = rnd.A, rnd.QA
    Jp = cc.J - QA @ (QA.T @ cc.J)
    k = _gram_rank(Jp.T @ Jp) if Jp.shape[1] else 0
    d, e, cvc, cv_ref = rnd.solve(cc.J, leverage=cc.cand.setup is None or problem.cv_leverage_generic)
    if cc.cand.scan is not None and k > 0:
        k += 1  # the scanned scalar (hard-iron step time) is a parameter too
    D = term_cur - typed_fit_term(e, types, floor)
    if problem.aux_noise_model and types is not None and k > 0:
        D += _aux_model_terms(problem, rnd, Jp, e, types, floor)
    db = max(k, 0) * math.log(n) - D
    sig = cc.J @ d[A.shape[1] :]
    sig = sig - QA @ (QA.T @ sig)
    infl = serial_inflation(e, sig, problem.series)
    if shared and problem.shared_noise is not None:
        infl = max(infl, shared_inflation(problem, _orth(np.hstack([A, cc.J])), e, sig))
    wm = wander_model(problem)
    T_w, wanders = None, False
    if wm is not None and k > 0 and D > 0:
        cal = problem.wander_calibrated
        T_w, wanders = wm.lr(A, cc.J, rnd.r0 - QA @ (QA.T @ rnd.r0), e, rnd.wander0, baseline=cal)
        if wanders and cal and T_w > chi2_isf(WANDER_NULL_P, k):
            T_w = min(T_w, _null_equivalent(T_w, wm.null_lr(A, cc.J, e, WANDER_NULL_DRAWS), k))
        if wanders or cal:
            # calibrated (P4): the ratio with the slow noise profiled out stands even where REML
            # does not call the wander evident: a Gauss–Markov wander of a few percent of a block's
            # variance over hundreds of blocks hides below EVIDENT_LR and still moves a line's white
            # deviance past its bound (indep_s27 P4 nulls 702104, 702125, 702131: 13.6-14.1 against
            # 11.7-12.9; profiled, 6.4 on 702131)
            infl = max(infl, D / max(T_w, 1e-9))
    if problem.slow_cov is not None and k > 0 and D > 0:
        infl = max(infl, D / max(slow_prior_lr(problem, A, cc.J, rnd.r0), 1e-9))
    ev = _Eval(cc, db, cvc, sig, int(k), D, infl, cv_ref=cv_ref)
    ev.wander_T, ev.wanders = T_w, wanders
    t = _only_kind(problem, cc.J, types)
    if t is not None and k > 0:
        # tested on its own rows: their deviance, against the residual degrees of freedom they
        # have left (rows minus the leverage the model puts on them, minus k)
        sel = types == t
        r_cur = rnd.r0 - QA @ (QA.T @ rnd.r0)  # the current model's residual (linearised)
        fl = None if floor is None else (floor[0][sel], floor[1][sel])
        rss0, rss1 = floored_rss(r_cur[sel], fl), floored_rss(e[sel], fl)
        ev.kind, ev.n_kind = int(t), int(sel.sum())
        ev.dof_kind = ev.n_kind - float(np.sum(QA[sel] ** 2)) - k
        ev.D = ev.n_kind * math.log(max(rss0, 1e-300) / max(rss1, 1e-300))
        ev.infl = serial_inflation(np.where(sel, e, 0.0), np.where(sel, sig, 0.0), problem.series)
    return ev


def _held_out_guard(problem, picked, generic_effect, cur_fit, free, refit_with, baseline_fit, cv0, entries, cv_args):
    """The named model as finally refitted, checked on held-out rows (the held-out RMS that each
    effect's reported gain is measured with): an effect without which the rest, refitted, predicts
    the held-out rows better than the whole model by more than ``GUARD_CV_RTOL`` is not named, the
    worst first, until none is. Each effect was tested linearised at the model of its round; the
    final refit moves every parameter at once, and two effects can trade what one large effect's
    linearisation left (an LDV offset of 10 m/s: a time delay of 0.31 s against a periodic term of
    1 m/s in time, gains −550 % and −104 %). Effects validated on some rows only (the compass dip:
    ``Problem.cv_rows``) are checked on those rows, where any loss counts (``GUARD_ROWS_RTOL``): a
    rotation between the sensors named on a TUI sweep read through an uncalibrated accelerometer
    predicted the held-out dip rows 16 % worse than the model without it. A library effect on a
    table (``cv_max_leverage``) is left to its own test.
    Returns (picked, generic_effect, fit, free)."""
    sigma, folds, primary, fold_map = cv_args

    def cv_of(fit_, fr, key=None):
        J, _, _ = jacobian(problem, fit_.params, fr)
        if key is None:
            return cv_rms(J, fit_.weighted_residuals, sigma, folds, primary)
        fs, rows = fold_map[key]
        # weighted again: the dip rows' scale is measured again after each pick (aux_scale_refit)
        return cv_rms(J, _weighted(problem, fit_.params), sigma, fs, primary, rows)

    while picked or generic_effect is not None:
        items = list(picked) + ([(generic_effect[0].cc, None)] if generic_effect is not None else [])
        cv_all = cv_of(cur_fit, free)
        worst = None
        for item in items:
            key = item[0].cand.folds if item[0].cand.folds in problem.cv_rows else None
            if key is None and problem.cv_max_leverage is not None and item[1] is not None:
                # a library effect on a table (P2, P1 averages) was validated on the rows its model
                # does not alone fix, where the whole table's held-out RMS is an extrapolation
                continue
            others = [o for o in items if o is not item]
            fit_wo, fr_wo = refit_with(others, cur_fit) if others else (baseline_fit, dict(problem.free))
            if key is None:
                cv_wo, cv_with, tol = (cv_of(fit_wo, fr_wo) if others else cv0), cv_all, GUARD_CV_RTOL
            else:
                cv_wo, cv_with, tol = cv_of(fit_wo, fr_wo, key), cv_of(cur_fit, free, key), GUARD_ROWS_RTOL
            if cv_wo * (1.0 + tol) < cv_with and (worst is None or cv_wo / cv_with < worst[1]):
                worst = (item, cv_wo / cv_with, fit_wo, fr_wo)
        if worst is None:
            break
        item, _, cur_fit, free = worst
        if item[1] is None:
            generic_effect = None
        else:
            picked = [p for p in picked if p is not item]
            entries[item[0].cand.name]["selected"] = False
    return picked, generic_effect, cur_fit, free


def _refit_evidence_guard(problem, picked, generic, cur_fit, free, refit_with, types, floor, n, entries):
    """A library effect named on its linearised test keeps its name only if the final model,
    refitted without it, fits the rows worse by at least the unscaled level-α/m bound: the
    deviance ``typed_fit_term`` of the nonlinear fits with and without it. A linearised step far
    outside the model's range can pass the test and hold its held-out rows too, the same noise
    in its columns as in the rows (s27 P1 null 721101: a scale asymmetry linearised at A = −1.4
    fitted the changes within holds of an axis near 0, deviance 84, held-out RMS −32 %; refitted,
    A = 0 ± 4e-5 and the residual the baseline's). The worst goes first, until every one stands.
    ``generic``: the named ``residual:`` term's item, kept in every refit; a dropped effect's
    entry is marked not selected. Returns (picked, fit, free)."""
    m = max(len(problem.candidates), 1)
    while picked:
        t_with = typed_fit_term(_weighted(problem, cur_fit.params), types, floor)
        J, _, _ = jacobian(problem, cur_fit.params, free)
        rank = _gram_rank(J.T @ J)
        worst = None
        for item in picked:
            others = [o for o in picked if o is not item] + generic
            fit_wo, fr_wo = refit_with(others, cur_fit)
            k = int(item[0].J.shape[1]) + (1 if item[0].cand.scan is not None else 0)
            q = deviance_quantile(problem, k, m, n, n - rank)
            D = typed_fit_term(_weighted(problem, fit_wo.params), types, floor) - t_with
            if D < q and (worst is None or D / q < worst[1]):
                worst = (item, D / q, fit_wo, fr_wo)
        if worst is None:
            break
        item, _, cur_fit, free = worst
        picked = [p for p in picked if p is not item]
        entries[item[0].cand.name]["selected"] = False
    return picked, cur_fit, free


def _null_equivalent(T: float, null: np.ndarray, k: int) -> float:
    """``T`` as the χ²_k statistic of the same tail probability under ``null``, its distribution
    on noise alone (draws) taken as a scaled χ² of matched mean and variance (Satterthwaite)."""
    m, v = float(np.mean(null)), float(np.var(null, ddof=1))
    if m <= 0 or v <= 0:
        return T
    c, nu = v / (2.0 * m), 2.0 * m * m / v
    p = float(gammaincc(nu / 2.0, T / (2.0 * c)))
    if p <= 0:
        return T
    return chi2_isf(p, k)


def _slow_factor(problem: Problem) -> np.ndarray:
    """The lower Cholesky factor of ``C = I + slow_cov / (σ σᵀ)`` (the rows' noise in weighted
    rows), made once per problem and made again only when ``σ`` or ``slow_cov`` is another
    (compared by value and identity: an address and a sum can both repeat for different rows)."""
    sigma = np.asarray(problem.sigma, float)
    cached = problem._slow_chol
    if cached is None or cached[1] is not problem.slow_cov or not np.array_equal(cached[0], sigma):
        C = np.eye(sigma.size) + np.asarray(problem.slow_cov, float) / np.outer(sigma, sigma)
        problem._slow_chol = cached = (sigma.copy(), problem.slow_cov, linalg.cholesky_lower(C))
    return cached[2]


def slow_prior_lr(problem: Problem, A: np.ndarray, J: np.ndarray, r0: np.ndarray) -> float:
    """The likelihood-ratio statistic (noise scale profiled, as the deviance) of columns ``J``
    beside ``A`` for the linearised weighted residual ``r0 + A δ`` under the rows' noise with the
    known slow part ``Problem.slow_cov``: ``C = I + slow_cov / (σ σᵀ)`` in weighted rows, every
    column and ``r0`` whitened once by its Cholesky factor (generalised least squares). With
    ``Problem.row_types``, a noise scale per kind, as the deviance has (``typed_fit_term``): the
    prior must then not couple rows of two kinds (``set_slow_bias_prior``'s ``rows``), so that
    whitening keeps every row in its kind."""
    L = _slow_factor(problem)
    X = linalg.solve_lower(L, np.column_stack([r0, A, J]))
    y, Xa, Xall = X[:, 0], X[:, 1 : 1 + A.shape[1]], X[:, 1:]

    def resid(Q):
        return y - Q @ (Q.T @ y)

    e0, e1 = resid(_orth(Xa)), resid(_orth(Xall))
    types = problem.row_types
    kinds = [np.ones(y.size, bool)] if types is None else [types == t for t in np.unique(types)]
    out = 0.0
    for sel in kinds:
        rss0, rss1 = float(e0[sel] @ e0[sel]), float(e1[sel] @ e1[sel])
        out += int(sel.sum()) * math.log(max(rss0, 1e-300) / max(rss1, 1e-300))
    return max(0.0, out)


def wander_model(problem: Problem):
    """The problem's slow-noise model (made once), or None."""
    if problem.wander_t_s is None or problem.series is None:
        return None
    if problem._wander is None:
        from solvers.diagnose.wander import WanderModel

        problem._wander = WanderModel(problem.wander_t_s, problem.series, 1.0 / np.asarray(problem.sigma, float))
    return problem._wander


def _only_kind(problem, J: np.ndarray, types) -> int | None:
    """The row kind that holds all of ``J``'s columns (to 1e-9 of their energy) when it has
    its own test (``problem.kind_thresholds``), else None."""
    if types is None or not problem.kind_thresholds or J.shape[1] == 0:
        return None
    tot = float(np.sum(J**2))
    for t in problem.kind_thresholds:
        sel = types == t
        if sel.any() and float(np.sum(J[~sel] ** 2)) <= 1e-9 * tot:
            return t
    return None


def _bound(problem, ev: _Eval, m: int, n: int, rank_cur: int, scale: float = 1.0) -> tuple[float, float]:
    """(bound on ``ev.D_rob``, score): the row kind's own exact F test where the candidate
    touches one kind with a threshold of its own, else the procedure's ``F·q``. The score is the
    threshold scale at which the candidate would sit on the bound (the null benchmark's statistic)."""
    if ev.kind is not None:
        F = candidate_threshold(problem, ev.cc.cand.name, ev.kind) * scale
        fstat = math.expm1(ev.D_rob / ev.n_kind) * ev.dof_kind / max(ev.k, 1) if ev.dof_kind > 0 else 0.0
        crit = float(fdtri(max(ev.k, 1), ev.dof_kind, 1.0 - ALPHA / max(m, 1))) if ev.dof_kind > 0 else math.inf
        return kind_quantile(ev.k, m, ev.n_kind, ev.dof_kind, F), fstat / crit
    dof = n - rank_cur - ev.k
    F = scale * candidate_threshold(problem, ev.cc.cand.name)
    if problem.row_types is not None and dof > 0:
        crit = float(fdtri(max(ev.k, 1), dof, 1.0 - ALPHA / max(m, 1)))
        return deviance_quantile(problem, ev.k, m, n, dof, F), math.expm1(ev.D_rob / n) * dof / (max(ev.k, 1) * crit)
    q = deviance_quantile(problem, ev.k, m, n, dof)
    return F * q, ev.D_rob / q


def candidate_threshold(problem: Problem, name: str, kind: int | None = None) -> float:
    """The scale F of a candidate's test: its own where the nulls measured one, else its row
    kind's (a candidate tested on one kind of rows), else the procedure's."""
    if name in problem.cand_thresholds:
        return problem.cand_thresholds[name]
    return problem.kind_thresholds[kind] if kind is not None else problem.threshold


def _significant(problem, ev: _Eval, m: int, rank_cur: int, n: int, scale: float = 1.0) -> bool:
    """The deviance test alone (no held-out test)."""
    if ev.k <= 0 or n - rank_cur - ev.k < MIN_DOF:
        return False
    if ev.kind is not None and ev.dof_kind < MIN_DOF:
        return False
    if ev.groups_left is not None and ev.groups_left < problem.min_groups - GROUPS_TOL:
        # too few groups left to test it on their means: tested on the rows within them alone
        return ev.within is not None and ev.within > _bound(problem, ev, m, n, rank_cur, scale)[0]
    return ev.D_rob > _bound(problem, ev, m, n, rank_cur, scale)[0]


def _cv_lower(ev: _Eval, cv_cur: float) -> bool:
    """Whether ``ev`` predicts held-out rows better than the current model (held-out RMS
    ``cv_cur``), over the rows its held-out RMS is taken on (``Problem.cv_max_leverage``)."""
    return ev.cv < (cv_cur if ev.cv_ref is None else ev.cv_ref)


def _passes(problem, ev: _Eval, m: int, cv_cur: float, rank_cur: int, n: int, scale: float = 1.0) -> bool:
    return _cv_lower(ev, cv_cur) and _significant(problem, ev, m, rank_cur, n, scale)


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    den = float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(a @ b) / den if den > 0 else 0.0


def _by_evidence(problem: Problem, evs: list, n: int) -> list:
    """Generic shapes that pass, best first: by BIC (the deviance net of serial correlation, each
    parameter and a scanned place or period paid ln n), a simpler shape ahead of a more flexible
    one that beats it by less than the decisive margin (the data cannot tell them apart). A
    held-out RMS prefers the most flexible: a 5-knot smooth term took a P1 bias step at 10σ and
    the bias instability beside it, 0.7 better in BIC than the step."""

    def bic(ev: _Eval) -> float:
        return ev.k * math.log(n) - ev.D_rob

    margin = decisive_margin(problem)
    left = sorted(evs, key=bic)
    out = []
    while left:
        best = left[0]
        simpler = [ev for ev in left if ev.k < best.k and bic(ev) - bic(best) <= margin]
        best = min(simpler, key=lambda ev: (ev.k, bic(ev))) if simpler else best
        out.append(best)
        left = [ev for ev in left if ev is not best]
    return out


# the largest noise scale F the decisive margin takes: a procedure's F is set by its nulls'
# worst candidates (the compass's 4.8 by a hard iron that wanders, which a test of one candidate
# against noise sees whole and a comparison of two candidates that both fit it does not)
TIE_F_MAX = 2.5


def decisive_margin(problem: Problem, k: int = 1) -> float:
    """BIC margin by which one of two correlated candidates of at most ``k`` parameters each
    must beat the other for the data to tell them apart: ``F·χ²_k(1 − α)``. The deviance
    difference of two one-signature models is about N(±s², 4s²) for a separation of s noise
    σ, so a wrong decision past ``F·χ²₁(1 − α)`` has a probability below Φ(−√margin) (< 0.1 %
    at F = 2.5) whatever s is. Two k-parameter candidates whose fitted signatures agree still
    span different k-dimensional spaces: each takes the noise along its own other k − 1
    directions, and the difference of those two χ²-like parts (of up to k degrees of freedom)
    decides between them when the signal does not. ``F`` is capped at ``TIE_F_MAX``: at the
    compass's 4.8 the margin for three parameters was 37.5, and two time-like effects 6σ apart
    (a deviance difference of about 36) were tied in most captures."""
    return min(problem.threshold, TIE_F_MAX) * chi2_isf(ALPHA, max(k, 1))


def _rival_margin(a: _Eval, b: _Eval, n: int) -> float:
    """``score(a) − score(b)`` (> 0: ``b`` explains the data better) with both deviances taken
    net of the larger of their two serial-correlation inflations, or, where a slow-noise model
    sees a wander beside either, both likelihood ratios with it profiled out: two candidates that explain
    the same structure are compared on one noise scale, so the comparison is decided by the fit
    and not by the two inflation estimates (a slow signature's inflation against 1 for one that
    changes with each position)."""
    if a.wander_T is not None and b.wander_T is not None and (a.wanders or b.wanders):
        # a slow wander in either's residual: both on the likelihood with it profiled out (the
        # wander one of them leaves unexplained, e.g. a line beside a temperature warm-up, is not
        # an inflation of the other's deviance)
        return (a.k - b.k) * math.log(n) - (a.wander_T - b.wander_T)
    infl = max(a.infl, b.infl)
    return (a.k - b.k) * math.log(n) - (a.D - b.D) / infl


def _scanned(desc: dict | None) -> int:
    """How many scalars of a generic candidate were searched for (the best member of a scanned
    family), each a parameter more than its columns: a step's place ``at`` or a ``period`` (1),
    a pulse's two places ``at`` and ``until`` (2); 0 for a fixed basis."""
    if not desc:
        return 0
    return int("at" in desc or "period" in desc) + int("until" in desc)


def _single_basis(desc: dict | None) -> bool:
    """Whether a generic candidate is one fixed basis (a line in a driver, a scale linear in
    time or temperature): one test of k parameters, as a library candidate is, so it is compared
    with a library candidate head to head. A scanned family (a step's place, a period) or a smooth
    function (knots chosen by held-out RMS) is the best of many bases: its BIC is biased upward by
    the search and by slow noise the search fits (a P1 step in time, the best of 34 places, beat a
    10σ scale asymmetry by 17.8 in BIC while beside it it explained 4.8 against a margin of 9.6),
    so it must also pass beside the effects it displaces and fit clearly better."""
    return bool(desc) and desc.get("shape") == "linear"


def _nested_ties(problem: Problem, best: _Eval, evals: list, tied: list[dict]) -> list[dict]:
    """``tied`` with the wide candidate of ``problem.nested`` when ``best`` is the narrow one it holds
    whole (the wide one explains the same; the other way round is ``problem.could_be``'s to say)."""
    wide = problem.nested.get(best.cc.cand.name)
    out = list(tied)
    for ev in evals:
        if ev.cc.cand.name == wide and ev.k > 0 and all(c["name"] != wide for c in tied):
            out.append({"name": wide, "correlation": _corr(best.sig, ev.sig)})
    return out


def _head_to_head(problem: Problem, best: _Eval, others: list[_Eval], n: int) -> tuple[list[dict], _Eval | None]:
    """``best`` against each other candidate whose fitted signature (projected off the current
    model) correlates with its own by more than RIVAL_CORR, each alone added to the current model:
    (``confused_with`` entries of the rivals within the decisive margin, the rival that beats
    ``best`` by more than it or None). A rival ``best`` beats by more than the margin is neither:
    it is tested again against the refitted model."""
    tied, better, worst = [], None, 0.0
    for r in others:
        if r is best or r.k <= 0:
            continue
        dec = decisive_margin(problem, max(best.k, r.k))
        corr = _corr(best.sig, r.sig)
        if abs(corr) <= RIVAL_CORR:
            continue
        margin = _rival_margin(best, r, n)  # > 0: r explains the data better
        if margin > dec:
            if margin > worst:
                better, worst = r, margin
        elif margin >= -dec:
            tied.append({"name": r.cc.cand.name, "correlation": corr})
    return tied, better


def diagnose(problem: Problem, baseline_fit: FitResult | None = None) -> Diagnosis:
    """Run the method of the module docstring on ``problem``."""
    sigma = np.asarray(problem.sigma, dtype=float).ravel()
    problem.sigma = sigma
    n = sigma.size
    folds = folds_of(problem.groups if problem.cv_groups is None else problem.cv_groups, problem.cv_max_folds)
    fold_map = {None: folds, **{k: folds_of(v) for k, v in problem.fold_sets.items()}}
    for k, rows in problem.cv_rows.items():  # a fold set whose held-out RMS is taken on some rows only
        fold_map[k] = (fold_map.get(k, folds), np.asarray(rows, bool))
    primary = None if problem.row_types is None else np.isin(problem.row_types, sorted(problem.measured_kinds))
    if baseline_fit is None:
        baseline_fit = fit(problem.residual, problem.baseline, free=problem.free, sigma=sigma)
    if problem.row_types is not None:
        _aux_scales(problem, baseline_fit, problem.free, sigma)
        problem.sigma = sigma
        baseline_fit = fit(problem.residual, baseline_fit.params, free=problem.free, sigma=sigma)
    types = None if problem.row_types is None else np.asarray(problem.row_types)

    base_params = baseline_fit.params
    r_base = _weighted(problem, base_params)
    floor = row_floor(problem, sigma, r_base)  # the kinds the baseline already fits to the noise floor

    def fit_term(e: np.ndarray) -> float:
        """The profile likelihood term of weighted residual ``e`` (``typed_fit_term``, floored)."""
        return typed_fit_term(e, types, floor)

    J_base, _, _ = jacobian(problem, base_params, problem.free)
    cv0 = cv_rms(J_base, r_base, sigma, folds, primary)

    entries: dict[str, dict] = {}
    for c in problem.candidates:
        if c.reason is not None:
            entries[c.name] = _unresolvable(c.name, c.reason)
    state, free = dict(base_params), dict(problem.free)
    cur_fit = baseline_fit
    cv_cur = cv0
    picked: list[tuple[_Cand, dict]] = []  # (candidate columns, effect entry)
    verdict: list[str] = []
    remaining = [c for c in problem.candidates if c.reason is None]
    deviance: dict = {}
    first = True

    def prune(picked, cur_fit, extra=None, min_items=2):
        """Drop each picked effect that no longer passes against all the others (and ``extra``,
        the generic effect, kept), refitted without it; returns (picked, fit, params, free)."""
        if len(picked) + (extra is not None) >= min_items:
            for item in list(picked):
                cc = item[0]
                others = [p for p in picked if p is not item] + ([(extra, None)] if extra is not None else [])
                st = {k: cur_fit.params[k] for k in base_params}
                fr = dict(problem.free)
                for oc, _ in others:
                    st.update({k: cur_fit.params[k] for k in oc.params})
                    fr.update(_free_in_model(oc))
                without = _refit(problem, st, fr, sigma)
                r0 = without.weighted_residuals
                J0, _, _ = jacobian(problem, without.params, fr)
                Q0 = _orth(J0)
                cand = _candidate_columns(problem, without.params, cc.cand, Q0, r0)
                if cand.reason is not None:
                    ok = False
                else:
                    rr = _Rounds(J0, r0, sigma, fold_map, primary, problem.cv_max_leverage)
                    ev = _evaluate(problem, cand, rr.get(cand.cand.folds), fit_term(r0), types, n, floor, shared=True)
                    ok = _passes(
                        problem, ev, len(problem.candidates), rr.cv0(cand.cand.folds), _gram_rank(J0.T @ J0), n
                    )
                if not ok:
                    picked.remove(item)
                    entries[cc.cand.name]["selected"] = False
                    cur_fit = without
        keep = list(picked) + ([(extra, None)] if extra is not None else [])
        free = dict(problem.free)
        for oc, _ in keep:
            free.update(_free_in_model(oc))
        state = {k: v for k, v in cur_fit.params.items() if k in base_params or any(k in oc.params for oc, _ in keep)}
        if keep:
            cur_fit = _refit(problem, state, free, sigma)
            return picked, cur_fit, dict(cur_fit.params), free
        return picked, baseline_fit, dict(base_params), free

    def refit_with(items, fit_):
        """The model with the baseline and ``items``' blocks, refitted from ``fit_``'s values."""
        st = {k: fit_.params[k] for k in base_params}
        fr = dict(problem.free)
        for oc, _ in items:
            st.update({k: fit_.params[k] for k in oc.params})
            fr.update(_free_in_model(oc))
        return (_refit(problem, st, fr, sigma) if items else baseline_fit), fr

    def pairs(picked, cur_fit):
        """Two picked effects whose signatures correlate by more than RIVAL_CORR, each alone added to
        the model with the others: the better (BIC) is kept; the other goes in its ``confused_with``
        when the margin is not decisive, and is dropped when it is."""
        changed = True
        while changed and len(picked) > 1:
            changed = False
            for i in range(len(picked)):
                for j in range(i + 1, len(picked)):
                    a, b = picked[i], picked[j]
                    wo, fr = refit_with([p for p in picked if p is not a and p is not b], cur_fit)
                    r0 = wo.weighted_residuals
                    J0, _, _ = jacobian(problem, wo.params, fr)
                    Q0 = _orth(J0)
                    rr = _Rounds(J0, r0, sigma, fold_map, primary, problem.cv_max_leverage)
                    evs = []
                    for oc, _ in (a, b):
                        cand = _candidate_columns(problem, wo.params, oc.cand, Q0, r0)
                        if cand.reason is None:
                            evs.append(
                                _evaluate(
                                    problem,
                                    cand,
                                    rr.get(cand.cand.folds),
                                    fit_term(r0),
                                    types,
                                    n,
                                    floor,
                                    shared=len(picked) > 2,
                                )
                            )
                    if len(evs) < 2 or min(ev.k for ev in evs) <= 0 or abs(_corr(evs[0].sig, evs[1].sig)) <= RIVAL_CORR:
                        continue
                    margin = _rival_margin(evs[0], evs[1], n)  # > 0: b explains the data better
                    win, lose = (b, a) if margin > 0 else (a, b)
                    if abs(margin) <= decisive_margin(problem, max(ev.k for ev in evs)):
                        corr = _corr(evs[0].sig, evs[1].sig)
                        win[1]["confused_with"] = win[1]["confused_with"] + [
                            {"name": lose[1]["name"], "correlation": corr},
                            *lose[1]["confused_with"],
                        ]
                    picked = [p for p in picked if p is not lose]
                    entries[lose[0].cand.name]["selected"] = False
                    cur_fit, _ = refit_with(picked, cur_fit)
                    changed = True
                    break
                if changed:
                    break
        return picked, cur_fit

    # greedy forward selection; after each pick the extended model is refitted nonlinearly and
    # the rest are tested again against it (a candidate that only soaks up what another one's
    # linearisation left behind does not pass then)
    while remaining:
        r0 = _weighted(problem, state)
        if below_noise_floor(problem, r0, sigma, primary):
            if first:
                e0 = (r0 * sigma)[primary] if primary is not None else r0 * sigma
                why = (
                    f"the baseline fits the data to {float(np.sqrt(np.mean(e0 * e0))):.2g} {problem.unit} RMS, "
                    f"below the {problem.noise_floor:.2g} {problem.unit} of any real capture's noise: "
                    "nothing is left for an effect to explain (exact, noise-free data?)"
                )
                for c in remaining:
                    entries[c.name] = _unresolvable(c.name, why)
            break
        J0, _, _ = jacobian(problem, state, free)
        Q0 = _orth(J0)
        term_cur = fit_term(r0)
        cv_cur = cv_rms(J0, r0, sigma, folds, primary)
        cands = [_candidate_columns(problem, state, c, Q0, r0) for c in remaining]
        rounds = _Rounds(J0, r0, sigma, fold_map, primary, problem.cv_max_leverage)
        evals = []
        for cc in cands:
            if cc.reason is not None:
                if first:
                    entries[cc.cand.name] = _unresolvable(cc.cand.name, cc.reason)
                continue
            ev = _evaluate(
                problem,
                cc,
                rounds.get(cc.cand.folds),
                term_cur,
                types,
                n,
                floor,
                shared=bool(picked) or problem.shared_first,
            )
            evals.append(ev)
            if first:
                entries[cc.cand.name] = {
                    "name": cc.cand.name,
                    "delta_bic": ev.delta_bic,
                    "cv_rms": ev.cv,
                    "selected": False,
                }
        m = len(evals)
        rank_cur = _gram_rank(J0.T @ J0)
        if first:
            for ev in evals:
                left = ev.dof_kind if ev.kind is not None else n - rank_cur - ev.k
                if ev.k > 0 and left < MIN_DOF:
                    rows = f"{ev.n_kind} rows of its kind" if ev.kind is not None else f"{n} rows"
                    entries[ev.cc.cand.name]["resolvable"] = False
                    entries[ev.cc.cand.name]["reason"] = (
                        f"too few rows: {rows} for the model's {rank_cur} parameters and this "
                        f"candidate's {ev.k} leave {left:.0f} degrees of freedom (at least {MIN_DOF} needed)"
                    )
                bound, score = _bound(problem, ev, m, n, rank_cur)
                deviance[ev.cc.cand.name] = {
                    "D": ev.D_rob,
                    "k": ev.k,
                    "q": deviance_quantile(problem, ev.k, m, n, n - rank_cur - ev.k),
                    "bound": bound,
                    "score": score,  # the threshold scale F at which it would just pass
                    "F": candidate_threshold(problem, ev.cc.cand.name, ev.kind),
                    "kind": ev.kind,
                    "cv_lower": _cv_lower(ev, rounds.cv0(ev.cc.cand.folds)),
                    "inflation": ev.infl,
                }
        first = False
        passing = [ev for ev in evals if _passes(problem, ev, m, rounds.cv0(ev.cc.cand.folds), rank_cur, n)]
        if not passing:
            break
        best = min(passing, key=lambda ev: ev.delta_bic)
        confused, better = _head_to_head(problem, best, evals, n)
        if better is not None:
            # a correlated rival explains the data decisively better but fails its held-out test:
            # this one would only stand in for it, and is not named
            remaining = [c for c in remaining if c.name != best.cc.cand.name]
            continue
        confused = _nested_ties(problem, best, evals, confused)
        cc = best.cc
        entries[cc.cand.name]["selected"] = True
        picked.append((cc, {"name": cc.cand.name, "cv_rms_before": cv_cur, "confused_with": confused}))
        state.update(cc.params)
        free.update(_free_in_model(cc))
        cur_fit = _refit(problem, state, free, sigma)
        cur_fit, free = _with_refit_free(problem, cc, cur_fit, free, sigma)
        if problem.aux_scale_refit and types is not None:
            # the auxiliary rows' noise measured again against the model as it now stands: on the
            # baseline an effect not yet modelled (a rotation in the compass dip rows) inflated it
            _aux_scales(problem, cur_fit, free, sigma)
            cur_fit = _refit(problem, dict(cur_fit.params), free, sigma)
        if _series_scales(problem, cur_fit, sigma):
            cur_fit = _refit(problem, dict(cur_fit.params), free, sigma)
        state = dict(cur_fit.params)
        drop = {cc.cand.name} | {c["name"] for c in confused}
        remaining = [c for c in remaining if c.name not in drop]
        if len(picked) > 1:  # the earlier picks must still earn their place beside this one
            picked, cur_fit, state, free = prune(picked, cur_fit)

    # name only what still earns its place against all the others, refitted; of two that the data
    # barely separate, only the better (the other in its confused_with, or dropped when decisively worse)
    if len(picked) > 1:
        picked, cur_fit, state, free = prune(picked, cur_fit)
        picked, cur_fit = pairs(picked, cur_fit)
        picked, cur_fit, state, free = prune(picked, cur_fit)

    # effects outside the library: a smooth function of one driver (residual:<driver>)
    # (a pulse, the dearest family, only where the residual is not noise-like: a pulse at 10σ leaves
    # its whole signature there; a null's residual mostly is noise-like, and the search cost a
    # fifth more time per capture)
    gens = (
        []
        if below_noise_floor(problem, cur_fit.weighted_residuals, sigma, primary)
        else generic_candidates(problem, pulses=not _residual_test(problem, cur_fit).get("white", False))
    )
    # every basis tried is a test (a scan: its grid members, or the independent ones it says)
    m_gen = sum((item[3] if len(item) > 3 else len(item[1])) if item[0] == "scan" else 1 for item in gens)

    def generic_round(state, free, named, ranked=False, allow=frozenset(), groups=True):
        """The best generic candidate that passes against the model at ``state`` and that no
        library candidate (other than ``named``) explains: (eval, correlations, held-out RMS) or None;
        ``ranked``: every such candidate, best first (a list); ``allow``: library candidates whose
        correlation with it does not rule it out (the ones it may displace on a better fit);
        ``groups``: its degrees of freedom in independent groups counted here (False: the caller
        counts them beside the model it is finally named in, ``_groups_ok``).
        "Far from noise along a driver" is what this test asks, every basis counted: a
        portmanteau test first would miss slow structure (a drift, a long period)."""
        r0 = _weighted(problem, state)
        J0, _, _ = jacobian(problem, state, free)
        Q0 = _orth(J0)
        term_cur = fit_term(r0)
        cv_g = cv_rms(J0, r0, sigma, folds, primary)
        rank_cur = _gram_rank(J0.T @ J0)
        evals = []
        rp = r0 - Q0 @ (Q0.T @ r0)
        rounds = _Rounds(J0, r0, sigma, fold_map, primary, problem.cv_max_leverage)
        for item in gens:
            family = item[1] if item[0] == "scan" else [item]
            pool = []  # (residual sum of squares it leaves, candidate, columns, description)

            def add(members, pool=pool):
                for cand, desc in members:
                    cand.setup()
                    cc = _candidate_columns(problem, state, cand, Q0, r0)
                    if cc.reason is not None:
                        continue
                    Jp = cc.J - Q0 @ (Q0.T @ cc.J)
                    pool.append((_lstsq_rss(Jp, rp)[1], cand, cc, desc))

            add(family)
            if not pool:
                continue
            if item[0] == "scan" and len(item) > 2:  # refine around the best grid value (not counted as tests)
                add(item[2](min(pool, key=lambda x: x[0])[3]))
            # a scanned family is represented by its best member (the residual it leaves) that the
            # held-out test accepts: near a place the capture barely resolves (a step with few
            # positions on one side) the held-out fit is ill-conditioned while the next place
            # fits as well; members are tried, best first, while the deviance test holds
            pool.sort(key=lambda x: x[0])
            chosen = None
            for _, cand, cc, desc in pool:
                ev = _evaluate(
                    problem, cc, rounds.get(cand.folds), term_cur, types, n, floor, shared=problem.shared_first
                )
                ev.desc = desc
                ev.k += _scanned(desc)  # the scanned places or period
                if groups:
                    _count_groups(problem, ev, J0, _scanned(desc), r0)
                if chosen is None:
                    chosen = ev
                if not _significant(problem, ev, m_gen, rank_cur, n, problem.generic_scale):
                    break
                if _cv_lower(ev, rounds.cv0(cand.folds)):
                    chosen = ev
                    break
            chosen.cc.cand.setup()
            evals.append(chosen)
        passing = [
            ev
            for ev in evals
            if _passes(problem, ev, m_gen, rounds.cv0(ev.cc.cand.folds), rank_cur, n, problem.generic_scale)
        ]
        if not passing:
            return [] if ranked else None
        lib = []
        for c in problem.candidates:
            if c.reason is not None or c.name in named:
                continue
            cc = _candidate_columns(problem, state, c, Q0, r0)
            if cc.reason is not None or cc.J.shape[1] == 0:
                continue
            lib.append((c.name, _orth(np.hstack([J0, cc.J])), cc))
        out = []
        for best in _by_evidence(problem, passing, n)[: 3 if ranked else 1]:
            corr = {}  # how much of its signature each library candidate's columns hold, at this state
            nb = float(np.linalg.norm(best.sig))
            for name, P, _ in lib:
                proj = P @ (P.T @ best.sig)
                corr[name] = float(np.linalg.norm(proj) / nb) if nb > 0 else 0.0
            # (a library effect it may displace still rules it out where it holds all but 1 % of
            # it: that is the effect itself in other coordinates, an LDV offset as a linear
            # function of the input, unless it fits decisively better below)
            rule = {name for name, v in corr.items() if v > CONFUSION_CORR and (name not in allow or v > ALIAS_CORR)}
            if rule and _single_basis(best.desc):
                # one fixed basis is one test, as a library candidate is: a library candidate that
                # holds most of its signature but fits decisively worse does not explain it
                for name, _, lcc in lib:
                    if name in rule:
                        lev = _evaluate(
                            problem,
                            lcc,
                            rounds.get(lcc.cand.folds),
                            term_cur,
                            types,
                            n,
                            floor,
                            shared=problem.shared_first,
                        )
                        if lev.k > 0 and _rival_margin(lev, best, n) > decisive_margin(problem, max(lev.k, best.k)):
                            rule.discard(name)
            if not rule:
                out.append((best, corr, cv_g))
        if ranked:
            return out
        return out[0] if out else None

    def with_generic(best, state, free):
        best.cc.cand.setup()
        state = {**state, **best.cc.params}
        free = {**free, **_free_in_model(best.cc)}
        fit_ = _refit(problem, state, free, sigma)
        return fit_, dict(fit_.params), free

    def model_bic(fit_, free_) -> float:
        """Gaussian BIC of a fitted model (unknown noise scale per kind of row)."""
        return fit_term(fit_.weighted_residuals) + len(Packer.build(fit_.params, free_).names) * math.log(n)

    def term_of(fit_) -> float:
        return fit_term(fit_.weighted_residuals)

    def npar(free_, fit_) -> int:
        return len(Packer.build(fit_.params, free_).names)

    def _beyond(cand_, fit_, free_) -> bool:
        """Whether generic candidate ``cand_``, fitted beside the library effects of the model
        ``fit_``, explains what they leave: a lower held-out RMS and a deviance above the
        decisive margin (the one that tells two correlated candidates apart, ``F·χ²₁(1 − α)``).
        The library effects it displaces explain nothing beside it (``prune``), so of two
        explanations 0.9 correlated it is the one that holds the other's part and more; its
        extra parameters are paid for in the BIC comparison that follows. (``F·χ²_k(1 − α)``
        here missed a P1 bias step at 10σ, 0.87 correlated with a drift: a line leaves a
        quarter of it.)"""
        r0_ = fit_.weighted_residuals
        J0_, _, _ = jacobian(problem, fit_.params, free_)
        cand_.setup()
        cc_ = _candidate_columns(problem, fit_.params, cand_, _orth(J0_), r0_)
        if cc_.reason is not None:
            return False
        rr_ = _Rounds(J0_, r0_, sigma, fold_map, primary, problem.cv_max_leverage)
        ev_ = _evaluate(problem, cc_, rr_.get(cand_.folds), fit_term(r0_), types, n, floor)
        if ev_.k <= 0 or n - _gram_rank(J0_.T @ J0_) - ev_.k < MIN_DOF:
            return False
        return _cv_lower(ev_, rr_.cv0(cand_.folds)) and ev_.D_rob > decisive_margin(problem)

    def _groups_ok(ev_, fit_, free_) -> bool:
        """Whether generic term ``ev_`` leaves ``problem.min_groups`` degrees of freedom in independent groups
        (``independent_groups``) beside the model ``fit_`` it is named in, its own block taken out:
        the library effects it displaced are no part of that model."""
        if problem.shared_noise is None:
            return True
        fr = {k: v for k, v in free_.items() if k not in ev_.cc.params}
        Jm, _, _ = jacobian(problem, {k: v for k, v in fit_.params.items() if k not in ev_.cc.params}, fr)
        scanned = _scanned(ev_.desc)
        if independent_groups(problem, Jm, ev_.cc.J) - scanned >= problem.min_groups - GROUPS_TOL:
            return True
        # too few groups: the term tested within them, beside that model (its own block at zero)
        wo = {**fit_.params, **{k: np.zeros_like(np.asarray(v, float)) for k, v in ev_.cc.params.items()}}
        D_w = within_groups_deviance(problem, Jm, ev_.cc.J, _weighted(problem, wo))
        return D_w > _bound(problem, ev_, m_gen, n, _gram_rank(Jm.T @ Jm), problem.generic_scale)[0]

    generic_effect = None
    generic_tied: list[dict] = []  # library effects the generic one displaced by a margin that is not decisive
    if gens:
        # beside library effects it may displace, its groups are counted in the model it ends in;
        # when they are too few there, the best term that has them beside every library effect
        named = {oc.cand.name for oc, _ in picked}
        res = None
        for counted in [False, True] if picked and problem.shared_noise is not None else [True]:
            res = generic_round(state, free, named, groups=counted)
            if res is None:
                break
            before = (list(picked), cur_fit, state, free, {k: dict(v) for k, v in entries.items()})
            generic_effect = res
            cur_fit, state, free = with_generic(res[0], state, free)
            if picked:  # a library effect that only stood in for this structure is dropped now
                kept = (list(picked), cur_fit, state, free, {k: dict(v) for k, v in entries.items()})
                picked, cur_fit, state, free = prune(picked, cur_fit, extra=res[0].cc, min_items=1)
                if len(picked) < len(kept[0]) and model_bic(cur_fit, free) > model_bic(kept[1], kept[3]):
                    # dropping them fits worse than keeping them beside it: they explain their part
                    picked, cur_fit, state, free = kept[:4]
                    entries.clear()
                    entries.update(kept[4])
            if counted or _groups_ok(res[0], cur_fit, free):
                break
            # beside the library effects that stay it fits the group means, noise included
            picked, cur_fit, state, free = before[:4]
            entries.clear()
            entries.update(before[4])
            generic_effect = res = None
        if res is None and picked:
            # the library effects may have taken part of a structure none of them is (a bias step
            # seen as a drift): try the generic one against the baseline, then keep only the library
            # effects that still earn their place beside it, and it beside them
            # (each generic candidate that passes, best held-out RMS first, until one displaces them)
            flags = {k: dict(v) for k, v in entries.items()}
            # the library names given (picked or tied to a pick) may have stood in for it however
            # correlated: it may displace them on a clearly better fit
            held = {oc.cand.name for oc, _ in picked} | {c["name"] for _, e in picked for c in e["confused_with"]}
            tie = None  # a generic term that fits better than the library effects but not decisively
            for res0 in generic_round(dict(base_params), dict(problem.free), set(), ranked=True, allow=held):
                fit2, st2, fr2 = with_generic(res0[0], state, free)
                picked2, fit2, st2, fr2 = prune(list(picked), fit2, extra=res0[0].cc, min_items=1)
                # the generic term must pass against the library effects that remain
                st_wo = {k: v for k, v in st2.items() if k not in res0[0].cc.params}
                fr_wo = {k: v for k, v in fr2.items() if k not in res0[0].cc.params}
                wo = _refit(problem, st_wo, fr_wo, sigma) if picked2 else baseline_fit
                r0 = wo.weighted_residuals
                J0, _, _ = jacobian(problem, wo.params, fr_wo if picked2 else problem.free)
                Q0 = _orth(J0)
                res0[0].cc.cand.setup()
                cand = _candidate_columns(problem, wo.params, res0[0].cc.cand, Q0, r0)
                ok = False
                if cand.reason is None:
                    rr = _Rounds(J0, r0, sigma, fold_map, primary, problem.cv_max_leverage)
                    ev = _evaluate(problem, cand, rr.get(cand.cand.folds), fit_term(r0), types, n, floor)
                    ev.k += _scanned(res0[0].desc)
                    _count_groups(problem, ev, J0, _scanned(res0[0].desc), r0)
                    ok = _passes(
                        problem, ev, m_gen, rr.cv0(cand.cand.folds), _gram_rank(J0.T @ J0), n, problem.generic_scale
                    )
                # and the model it leaves must fit better than the library's (BIC): a drift is not
                # replaced by a step that only approximates it
                # (clearly better, by DISPLACE_MARGIN, where a library effect held most of its signature)
                margin = DISPLACE_MARGIN if any(res0[1].get(x, 0.0) > CONFUSION_CORR for x in held) else 0.0
                lib_cols: list = []
                if ok and len(picked2) < len(picked):
                    # the library effects it would displace are shapes of its own (an LDV offset, a
                    # constant per beam, inside a smooth function of each beam's input; a P1
                    # quadratic inside one of each axis' input): with them it is the same model, and
                    # what it adds beside them was tested in the round above and did not pass. A
                    # BIC gain here is its extra parameters fitting slow noise (a beam wander took
                    # a 10σ offset into `residual:input_axis`, gain 1639, seed 580500)
                    lib_cols = [
                        (oc, _candidate_columns(problem, wo.params, oc.cand, Q0, r0))
                        for oc, _ in _displaced(picked, picked2)
                    ]
                    nested = [_nested_share(lcc.J, cand.J, Q0) if lcc.reason is None else 0.0 for _, lcc in lib_cols]
                    ok = min(nested) <= ALIAS_CORR
                gain = model_bic(cur_fit, free) - model_bic(fit2, fr2)  # > 0: the generic model fits better
                if ok and margin > 0 and _single_basis(res0[0].desc):
                    # one fixed basis against the library effects it displaces: head to head, as two
                    # library candidates are (both deviances net of the larger serial-correlation
                    # inflation): the better fit is named, the other tied to it within the decisive margin
                    infl = ev.infl
                    for oc, lcc in lib_cols:  # the displaced effects' columns, built for the nested test
                        if lcc.reason is None and lcc.J.shape[1]:
                            lev = _evaluate(problem, lcc, rr.get(oc.cand.folds), fit_term(r0), types, n, floor)
                            infl = max(infl, lev.infl)
                    gain = (term_of(cur_fit) - term_of(fit2)) / infl - (
                        npar(fr2, fit2) - npar(free, cur_fit)
                    ) * math.log(n)
                    margin = 0.0
                displaces = len(picked2) < len(picked) and gain > margin
                if ok and margin > 0 and not _single_basis(res0[0].desc):
                    # and it explains what the library effects leave: it passes beside them (one test)
                    ok = _beyond(res0[0].cc.cand, cur_fit, free)
                    if (not ok or not displaces) and tie is None and len(picked2) < len(picked) and gain > -margin:
                        # it passes where the library effects are not fitted, and its model fits
                        # neither clearly worse than theirs nor clearly better while explaining
                        # something decisive beside them (DISPLACE_MARGIN either way; its names
                        # would replace theirs then): neither explanation is decisively better
                        tie = (res0, picked2)
                if ok and displaces:
                    # not decisively better (the scanned place or period counted as a parameter): the
                    # data cannot tell the two apart (a drift with slow wander against a step), and the
                    # library effects it displaced are named with it (head to head, as for two candidates)
                    scanned = _scanned(res0[0].desc)
                    kx = scanned * math.log(n)
                    # the margin of the larger of the two parts the models do not share (as for two
                    # candidates: each fits the noise along its own other directions)
                    n_wo = len(Packer.build(st_wo, fr_wo).names)
                    k_gen = len(Packer.build(fit2.params, fr2).names) - n_wo + scanned
                    k_lib = len(Packer.build(cur_fit.params, free).names) - n_wo
                    if gain - kx <= decisive_margin(problem, max(k_gen, k_lib)):
                        for _, e in _displaced(picked, picked2):
                            c = float(res0[1].get(e["name"], 0.0))
                            for t in [{"name": e["name"], "correlation": c}, *e["confused_with"]]:
                                if t["name"] not in {g["name"] for g in generic_tied}:
                                    generic_tied.append(t)
                    res0[0].cc.cand.setup()
                    picked, cur_fit, state, free = picked2, fit2, st2, fr2
                    generic_effect = (res0[0], res0[1], cv_rms(J0, r0, sigma, folds, primary))
                    break
                entries.clear()
                entries.update({k: dict(v) for k, v in flags.items()})
            if generic_effect is None and tie is not None:
                # the data cannot tell the two explanations apart: the library effects stay named
                # and the generic term is named with those it would displace (a bias step 0.97
                # correlated with a drift at 10σ leaves about 2.4σ beside it: no decisive margin
                # either way, while the step model fits better)
                (gen, corr_g, _), kept2 = tie
                for _, e in _displaced(picked, kept2):
                    e["confused_with"] = [
                        *e["confused_with"],
                        {"name": gen.cc.cand.name, "correlation": float(corr_g.get(e["name"], 0.0))},
                    ]

    gen = [(generic_effect[0].cc, None)] if generic_effect is not None else []
    picked, cur_fit, free = _refit_evidence_guard(
        problem, picked, gen, cur_fit, free, refit_with, types, floor, n, entries
    )
    picked, generic_effect, cur_fit, free = _held_out_guard(
        problem,
        picked,
        generic_effect,
        cur_fit,
        free,
        refit_with,
        baseline_fit,
        cv0,
        entries,
        (sigma, folds, primary, fold_map),
    )
    if generic_effect is None:
        generic_tied = []
    ext = cur_fit
    Je, _, _ = jacobian(problem, ext.params, free)
    cv_ext = cv_rms(Je, ext.weighted_residuals, sigma, folds, primary) if (picked or generic_effect) else cv0
    if not picked and not generic_effect:
        ext = baseline_fit
    _tie_intercepts(problem, [e for _, e in picked])
    _tie_could_be(problem, [e for _, e in picked], ext)
    effects: list[dict] = []
    for cc, e in picked:
        e = dict(e)
        # a block freed only in the refits (a temperature column's lag) is reported where it earned it
        earned = _free_in_model(cc)
        shown = [
            k
            for k in cc.params
            if k not in (cc.cand.refit_free or {}) or np.any(cc.free.get(k, False)) or np.any(earned.get(k, False))
        ]
        e["params"] = {k: ext.params[k] for k in shown}
        e["uncertainty"] = {k: ext.sigma[k] for k in shown}
        effects.append(e)
        verdict.append(e["name"])
        verdict += [c["name"] for c in e["confused_with"]]
    # gains in the order of selection, each against the model before it (refitted)
    cvs = [cv0]
    if effects:
        st, fr = dict(base_params), dict(problem.free)
        for k in base_params:
            st[k] = ext.params[k]
        for i, (cc, _) in enumerate(picked):
            st.update({k: ext.params[k] for k in cc.params})
            fr.update(_free_in_model(cc))
            if i == len(picked) - 1 and not generic_effect:
                cvs.append(cv_ext)
            else:
                Jt, _, _ = jacobian(problem, st, fr)
                cvs.append(cv_rms(Jt, _weighted(problem, st), sigma, folds, primary))
        for i, e in enumerate(effects):
            e["cv_rms_before"], e["cv_rms_after"] = cvs[i], cvs[i + 1]
            key = picked[i][0].cand.folds
            if key in problem.cv_rows:  # validated on some rows only (compass dip): its gain there
                st, fr = {k: ext.params[k] for k in base_params}, dict(problem.free)
                for oc, _ in picked[:i]:
                    st.update({k: ext.params[k] for k in oc.params})
                    fr.update(_free_in_model(oc))
                fs, rows = fold_map[key]
                Jb, _, _ = jacobian(problem, st, fr)
                before = cv_rms(Jb, _weighted(problem, st), sigma, fs, primary, rows)
                oc = picked[i][0]
                st.update({k: ext.params[k] for k in oc.params})
                fr.update(_free_in_model(oc))
                Ja, _, _ = jacobian(problem, st, fr)
                after = cv_rms(Ja, _weighted(problem, st), sigma, fs, primary, rows)
                e["cv_rms_before"], e["cv_rms_after"] = before, after
            b, a = e["cv_rms_before"], e["cv_rms_after"]
            e["gain"] = 1.0 - a / b if b > 0 else 0.0
    if generic_effect:
        best, corr, cv_g = generic_effect
        desc = dict(best.desc)
        drv = desc.pop("driver")
        name = f"residual:{drv}"
        effects.append(
            {
                "name": name,
                "params": {"bR": ext.params["bR"], **{k: v for k, v in desc.items() if k != "shape"}},
                "uncertainty": {"bR": ext.sigma["bR"]},
                "cv_rms_before": cv_g,
                "cv_rms_after": cv_ext,
                "gain": 1.0 - cv_ext / cv_g if cv_g > 0 else 0.0,
                "confused_with": generic_tied,
                "shape": desc.get("shape"),
                "driver": drv,
                "correlation": corr,
            }
        )
        verdict.append(name)
        verdict += [c["name"] for c in generic_tied]
    rw = ext.weighted_residuals
    scale = math.sqrt(ext.chi2 / ext.dof) if ext.dof > 0 else 1.0
    stud = rw / max(scale, 1e-300)
    test = _residual_test(problem, ext)
    test["drivers"] = _driver_correlations(problem, ext.residuals)
    wm = wander_model(problem)
    if wm is not None and test.get("white") is False:
        # what a slow wander (bias instability) fitted to the extended model's residual says of it
        test["wander"] = wm.evident(Je, ext.weighted_residuals, np.asarray(problem.sigma, float))
    cand_list = [entries[c.name] for c in problem.candidates]
    names = [e["name"] for e in effects]
    canon = [x for x in names if not x.startswith("residual:")]
    ext_model = problem.extended_model(canon) if (problem.extended_model and canon) else problem.model
    if generic_effect:
        ext_model += f" + f_{effects[-1]['shape']}({effects[-1]['driver']})"
    return Diagnosis(
        problem.procedure,
        baseline_fit,
        cv0,
        cand_list,
        effects,
        list(dict.fromkeys(verdict)),
        ext,
        cv_ext,
        names,
        test,
        stud,
        problem.model,
        ext_model,
        problem,
        deviance,
    )


def _residual_test(problem: Problem, fitres: FitResult) -> dict:
    """Ljung–Box per channel (Bonferroni) on time-ordered rows, else χ² of the weighted residuals."""
    rw = fitres.weighted_residuals
    if problem.time_ordered:
        ch = max(1, int(problem.channels))
        tests = [ljung_box(rw.reshape(-1, ch)[:, j]) for j in range(ch)]
        test = min(tests, key=lambda x: x["p_value"] if x["p_value"] is not None else 1.0)
        if test["p_value"] is not None:
            test = dict(test, p_value=min(1.0, test["p_value"] * ch), channels=ch)
            test["white"] = bool(test["p_value"] > WHITE_P)
        return test
    if problem.row_types is not None and problem.series is not None:
        # a time series of primary rows next to auxiliary ones (compass): Ljung–Box on the series
        sel = np.asarray(problem.series) == 0
        if sel.sum() >= 10:
            test = ljung_box(rw[sel])
            if problem.whiteness_lags and problem.whiteness_lags > test.get("lags", 0) and test["p_value"] is not None:
                slow = ljung_box(rw[sel], problem.whiteness_lags)
                if slow["lags"] > test["lags"]:
                    test = min((test, slow), key=lambda x: x["p_value"])
                    test = dict(test, p_value=min(1.0, 2.0 * test["p_value"]))
                    test["white"] = bool(test["p_value"] > WHITE_P)
            return test
    return chi2_test(rw, fitres.dof)


def _driver_correlations(problem: Problem, resid: np.ndarray) -> list[dict]:
    """|correlation| of the residual (primary rows) with each driver and with its smoothed
    trend (the residual averaged in 10 bins of the driver: structure, not only a slope), largest first."""
    keep = np.ones(len(resid), bool) if problem.row_types is None else np.asarray(problem.row_types) == 0
    out = []
    for name, x in (problem.drivers or {}).items():
        x = np.asarray(x, float)
        ok = keep & np.isfinite(x)
        if ok.sum() < 8 or np.ptp(x[ok]) <= 0:
            continue
        xr, rr = x[ok], resid[ok] - np.mean(resid[ok])
        lin = float(np.corrcoef(xr, rr)[0, 1]) if np.std(rr) > 0 else 0.0
        edges = np.quantile(xr, np.linspace(0, 1, 11))
        b = np.clip(np.searchsorted(edges, xr, side="right") - 1, 0, 9)
        means = np.array([rr[b == i].mean() if np.any(b == i) else 0.0 for i in range(10)])
        trend = means[b]
        explained = float(np.sum(trend**2) / max(np.sum(rr**2), 1e-300))
        out.append({"driver": name, "correlation": lin, "explained_by_trend": explained})
    out.sort(key=lambda d: -d["explained_by_trend"])
    return out

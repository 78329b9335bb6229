"""Where porous invasion meets fracturing on the Ca*–C diagram (Sec. 3.6): the separatrix Ca*_c = A exp(B C).

Two fits of the same logistic model of the labels: ``fit_exponential_separatrix`` (penalized maximum likelihood,
delta-method covariance of A and B) and ``separatrix_profile_interval`` (Jeffreys-penalized profile-likelihood
intervals, honest on separable labels); ``unlocated_reason`` says when the labels do not locate the line.
``separatrix_band`` gives the profile-likelihood band of ln Ca*_c over C (simultaneous: it covers the whole line),
``separatrix_significance`` the penalized likelihood-ratio test against a constant probability, and
``separatrix_summary`` what a campaign report states of them (sweep.regimes.probability re-exports the three).
``separatrix_test`` is the one rule of whether a fit is significant (that test at ``SEPARATRIX_P_MAX``): every
diagram (one run per point or replicates), the campaign report and the replicated sampler decide by it.
C in % (cement ratio), Ca* dimensionless.  Drawing lives in ``sweep.regimes.diagrams``.
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from .numbers import logistic_fit

__all__ = [
    "interval_text",
    "ExponentialSeparatrix",
    "fit_exponential_separatrix",
    "SeparatrixInterval",
    "separatrix_profile_interval",
    "unlocated_reason",
    "SEPARATRIX_P_MAX",
    "SeparatrixTest",
    "separatrix_test",
    "SeparatrixBand",
    "separatrix_band",
    "separatrix_significance",
    "separatrix_summary",
]


def interval_text(lo: float, hi: float, digits: int = 2) -> str:
    """A profile interval as text, a side the labels do not bound open: "[0.26, ∞)", "(−∞, ∞)"."""
    left = f"[{lo:.{digits}f}" if math.isfinite(lo) else "(−∞"
    right = f"{hi:.{digits}f}]" if math.isfinite(hi) else "∞)"
    return f"{left}, {right}"


class ExponentialSeparatrix(NamedTuple):
    """Ca*_c(C) = A exp(B C); cov: 2x2 covariance of (A, B) (delta method).

    Also: ``sigma_A``, ``sigma_B``, ``cov_lnA_B`` (covariance of (ln A, B), in which the
    fit is close to Gaussian), ``separable`` (labels perfectly separated: then cov
    reflects the ridge penalty, not a sampling uncertainty).
    """

    A: float
    B: float
    cov: np.ndarray
    cov_lnA_B: np.ndarray | None = None
    separable: bool = False

    @property
    def sigma_A(self) -> float:
        return float(math.sqrt(max(self.cov[0, 0], 0.0)))

    @property
    def sigma_B(self) -> float:
        return float(math.sqrt(max(self.cov[1, 1], 0.0)))

    def __call__(self, C: Any) -> Any:
        """Ca*_c at cement ratio C (%)."""
        return self.A * np.exp(self.B * np.asarray(C, dtype=float))


def fit_exponential_separatrix(C: Any, ca_star: Any, fracturing: Any,
                               ridge: float = 1e-3) -> ExponentialSeparatrix:
    """Fit Ca*_c = A exp(B C) separating porous invasion from fracturing.

    Logistic regression of ``fracturing`` on (C, ln Ca*) (scipy.optimize, no sklearn):
    logit P = b0 + b1 C + b2 ln Ca*; the 50 % boundary is ln Ca* = -(b0 + b1 C)/b2, so
    A = exp(-b0/b2), B = -b1/b2, with covariance by the delta method from the inverse
    Hessian. C in %, Ca* dimensionless (> 0), fracturing bools. Needs both outcomes and
    fracturing increasing with Ca* (b2 > 0).
    """
    Ca = np.asarray(C, dtype=float).ravel()
    cs = np.asarray(ca_star, dtype=float).ravel()
    fr = np.asarray(fracturing).astype(bool).ravel()
    if not (Ca.size == cs.size == fr.size) or Ca.size < 3:
        raise ValueError(f"C, ca_star, fracturing lengths=({Ca.size}, {cs.size}, {fr.size}): "
                         "must be equal and >= 3")
    if not np.all(np.isfinite(Ca)):
        raise ValueError("C: contains non-finite values; all must be finite (%)")
    if not np.all(np.isfinite(cs)) or np.any(cs <= 0):
        raise ValueError("ca_star: must be finite and > 0")
    fit = logistic_fit(np.c_[Ca, np.log(cs)], fr, ridge=ridge)
    b0, b1, b2 = fit.beta
    if b2 <= 0:
        raise ValueError("fracturing: does not increase with Ca* (fitted coefficient <= 0); "
                         "no separatrix Ca*_c(C)")
    lnA, B = -b0 / b2, -b1 / b2
    J = np.array([[-1.0 / b2, 0.0, b0 / b2**2],
                  [0.0, -1.0 / b2, b1 / b2**2]])
    cov_lnAB = J @ fit.cov @ J.T
    A = float(np.exp(lnA))
    D = np.diag([A, 1.0])
    return ExponentialSeparatrix(A=A, B=float(B), cov=D @ cov_lnAB @ D, cov_lnA_B=cov_lnAB,
                                 separable=fit.separable)


class SeparatrixInterval(NamedTuple):
    """Profile-likelihood intervals of the separatrix Ca*_c = A exp(B C) at ``level``.

    A (-) and B (1/%) are the penalized maximum-likelihood values; ``A_interval``, ``B_interval`` their
    intervals (each parameter profiled over the other and the transition's sharpness); ``sharpness`` the
    fitted logistic slope s per unit of ln Ca* (-); ``separable``: every label lies on its side of the
    fitted separatrix (the data alone then bound s from below only; the Jeffreys penalty keeps it finite).
    """

    A: float
    B: float
    A_interval: tuple[float, float]
    B_interval: tuple[float, float]
    level: float
    separable: bool
    sharpness: float = math.nan


def _sep_objective(phi, M, X, y):
    """Negative Jeffreys-penalized log-likelihood of the logistic model z = X theta at theta = M phi, and
    its gradient in phi. Penalty: 0.5 log det of the full model's Fisher information X' W X (Firth 1993);
    its gradient gives the modified score X' (y - p + h (1/2 - p)), h the hat values."""
    theta = M @ phi
    z = X @ theta
    p = 0.5 * (1.0 + np.tanh(0.5 * z))
    w = np.maximum(p * (1.0 - p), 1e-300)
    info = (X * w[:, None]).T @ X
    sign, logdet = np.linalg.slogdet(info)
    if sign <= 0:
        return math.inf, np.zeros_like(phi)
    h = w * np.einsum("ni,ij,nj->n", X, np.linalg.inv(info), X)
    nll = float(np.sum(np.logaddexp(0.0, z) - y * z)) - 0.5 * logdet
    return nll, -(M.T @ (X.T @ (y - p + h * (0.5 - p))))


def _sep_fisher(phi, M, X, y):
    """Fisher information of the likelihood part in phi: the trust region's model Hessian."""
    z = X @ (M @ phi)
    p = 0.5 * (1.0 + np.tanh(0.5 * z))
    XM = X @ M
    return (XM * (p * (1.0 - p))[:, None]).T @ XM


def _sep_min(X, y, M):
    """Minimum negative penalized log-likelihood over theta = M phi, and theta at the minimum (Newton trust
    region on the Fisher information, from a unit sharpness). The Jeffreys penalty keeps the minimum finite
    on separable labels."""
    from scipy.optimize import minimize

    phi0 = np.linalg.lstsq(M, np.r_[1.0, np.zeros(X.shape[1] - 1)], rcond=None)[0]
    res = minimize(_sep_objective, phi0, args=(M, X, y), jac=True, hess=_sep_fisher, method="trust-exact",
                   options={"gtol": 1e-8, "maxiter": 500})
    return float(res.fun), M @ res.x


def _profile_search(rise, v0: float, step: float) -> tuple[tuple[float, float], tuple[bool, bool]]:
    """Where rise(v) (< 0 at v0) crosses 0 on each side: doubling steps, then Brent.  Returns ((lower, upper),
    (lower found, upper found)): a side where the profile stays below the threshold over 1024 steps is not
    bounded by the labels, and its value is the search's reach, no bound."""
    from scipy.optimize import brentq

    out, found = [], []
    for sgn in (-1.0, 1.0):
        inner, d = v0, step
        while (r := rise(v0 + sgn * d)) < 0 and d < 1e3 * step:
            inner, d = v0 + sgn * d, 2.0 * d
        out.append(brentq(rise, inner, v0 + sgn * d, xtol=0.01 * step) if r >= 0 else v0 + sgn * d)
        found.append(bool(r >= 0))
    return (out[0], out[1]), (found[0], found[1])


def _profile_bounds(rise, v0: float, step: float) -> tuple[float, float]:
    """The profile interval of :func:`_profile_search`, a side the labels do not bound as -inf or +inf."""
    (lo, hi), (lo_ok, hi_ok) = _profile_search(rise, v0, step)
    return (lo if lo_ok else -math.inf), (hi if hi_ok else math.inf)


def separatrix_profile_interval(C: Any, ca_star: Any, fracturing: Any, level: float = 0.95) -> SeparatrixInterval:
    """Fit Ca*_c = A exp(B C) with profile-likelihood intervals of A and B (scipy only).

    Model: P(fracturing) = expit(s (ln Ca* - ln A - B C)), s > 0 the transition's sharpness per unit of
    ln Ca*; linear in theta = (s, s B, s ln A). The likelihood carries Jeffreys' prior (Firth's penalty
    0.5 log det I(theta)), the reference prior of the model, with no scale to choose: on labels that a
    separatrix separates, the unpenalized likelihood grows without bound as s grows and its profile
    shrinks to the separating separatrices, whatever the true transition width; the penalty keeps s
    finite and the profile honest (Heinze and Schemper 2002: profile penalized likelihood intervals).
    ln A fixed (theta_3 = v theta_1) or B fixed (theta_2 = v theta_1) is a linear constraint on theta,
    so each profile point is a fit in a plane of theta. The interval is where twice the penalized
    profile's rise stays below the chi-square(1) quantile of ``level``. C in %, Ca* > 0 (-),
    fracturing bools (both outcomes needed).
    """
    from scipy.stats import chi2

    Cc = np.asarray(C, float).ravel()
    L = np.log(np.asarray(ca_star, float).ravel())
    y = np.asarray(fracturing).astype(bool).astype(float).ravel()
    if not (Cc.size == L.size == y.size) or Cc.size < 3 or y.min() == y.max():
        raise ValueError("C, ca_star, fracturing: need equal lengths >= 3 and both outcomes")
    if not 0 < level < 1:
        raise ValueError(f"level={level!r}: must be in (0, 1)")
    X = np.c_[L, -Cc, -np.ones_like(L)]
    full, th = _sep_min(X, y, np.eye(3))
    if not th[0] > 0:
        raise ValueError("fracturing: does not increase with Ca* (fitted sharpness <= 0); no separatrix Ca*_c(C)")
    B_hat, lnA_hat = th[1] / th[0], th[2] / th[0]
    thr = chi2.ppf(level, 1) / 2.0

    def rise_lnA(v):
        return _sep_min(X, y, np.array([[1.0, 0.0], [0.0, 1.0], [v, 0.0]]))[0] - full - thr

    def rise_B(v):
        return _sep_min(X, y, np.array([[1.0, 0.0], [v, 0.0], [0.0, 1.0]]))[0] - full - thr

    span_L, span_C = max(np.ptp(L), 1e-6), max(np.ptp(Cc), 1e-6)
    lo_a, hi_a = _profile_bounds(rise_lnA, lnA_hat, 0.02 * span_L)
    b_iv = _profile_bounds(rise_B, B_hat, 0.02 * span_L / span_C)
    separable = bool(np.all((X @ th > 0) == (y > 0.5)))
    return SeparatrixInterval(float(np.exp(lnA_hat)), float(B_hat), (float(np.exp(lo_a)), float(np.exp(hi_a))),
                              b_iv, level, separable, float(th[0]))


SEPARATRIX_P_MAX = 0.05   # significance level of the separatrix test: p below it, the fit is significant


class SeparatrixTest(NamedTuple):
    """The separatrix test's outcome: ``lr`` the penalized likelihood-ratio statistic against a constant
    probability, ``p_value`` (chi2 with 2 degrees of freedom), ``alpha`` the level; ``significant`` = p < alpha."""

    lr: float
    p_value: float
    alpha: float

    @property
    def significant(self) -> bool:
        return bool(self.p_value < self.alpha)

    @property
    def reason(self) -> str | None:
        """Why the fit is not significant (None when it is), as a figure or report says it."""
        if self.significant:
            return None
        return (f"not significant: penalized likelihood ratio {self.lr:.2f} against a constant probability, "
                f"p = {self.p_value:.2g} >= {self.alpha:g}")


def separatrix_test(C: Any, ca_star: Any, fracturing: Any, alpha: float = SEPARATRIX_P_MAX) -> SeparatrixTest:
    """Whether the labels' separatrix Ca*_c = A exp(B C) is significant: the one rule of the single-run and the
    replicated Ca*-C diagrams, the campaign report and the replicated boundary sampler.  The Jeffreys-penalized
    likelihood-ratio test of the fit against a constant fracturing probability (:func:`separatrix_significance`,
    the likelihood of the band and the profile intervals), significant when p < ``alpha``.  C in %, Ca* (-) > 0,
    fracturing bools; ValueError when the design cannot identify the line or ``alpha`` is not in (0, 1)."""
    if not (isinstance(alpha, (int, float)) and 0 < alpha < 1):
        raise ValueError(f"alpha={alpha!r}: must be a number in (0, 1)")
    lr, p = separatrix_significance(C, ca_star, fracturing)
    return SeparatrixTest(lr, p, float(alpha))


def unlocated_reason(sep, C, cs, fr) -> str | None:
    """Why the labels do not locate the separatrix Ca*_c(C) (None when they do); the line is then not drawn.

    Two cases: the line stays above or below every sampled Ca* over the sampled C (an extrapolation), or it
    separates no better than the base rate, i.e. the runs it puts on the wrong side (fracturing below it,
    porous invasion above) are at least as many as the minority regime's runs, so calling every run the
    majority regime would do as well and the line carries no information about where the regimes meet."""
    line = sep(np.linspace(C.min(), C.max(), 50))
    head = f"the fitted line (A = {sep.A:.3g}, B = {sep.B:.3g} /%)"
    if np.all(line < cs.min()) or np.all(line > cs.max()):
        return f"{head} lies outside the sampled Ca* range [{cs.min():.3g}, {cs.max():.3g}] over C: the labels do not locate it"
    wrong = int(np.sum((cs >= sep(C)) != fr))
    minority = int(min(fr.sum(), (~fr).sum()))
    if wrong >= minority:
        major = "fracturing" if fr.sum() > (~fr).sum() else "porous invasion"
        return (f"{head} puts {wrong} of {fr.size} runs on the wrong side, no fewer than calling every run "
                f"{major} ({minority}): the labels do not locate it")
    try:
        test = separatrix_test(C, cs, fr)
    except ValueError as exc:     # a design that cannot identify the line
        return str(exc)
    return None if test.significant else f"{head} is {test.reason}; none found"


# --------------------------------------------------------------------------- the separatrix and its band
class SeparatrixBand(NamedTuple):
    """The separatrix Ca*_c(C) = A exp(B C) and its band.

    ``C`` (m,) the cement ratios (%) where the band is evaluated; ``center``, ``lo``, ``hi`` (m,) ln Ca*_c and its
    band (natural log); ``level``; ``simultaneous`` (band from the 2-parameter region: it covers the whole line at
    ``level``); A (-), B (1/%), ``sharpness`` s per unit of ln Ca*; ``lr`` the penalized likelihood-ratio statistic
    against a constant probability and ``p_value`` (chi2 with 2 degrees of freedom); ``significant`` = p_value <
    ``alpha``; ``n`` labels; ``lo_bounded``, ``hi_bounded`` (m,) whether the labels bound the band below and above
    at each C (where they do not, ``lo`` / ``hi`` hold the profile search's reach, no bound: see
    ``half_width_decades``)."""

    C: np.ndarray
    center: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level: float
    simultaneous: bool
    A: float
    B: float
    sharpness: float
    lr: float
    p_value: float
    significant: bool
    n: int
    lo_bounded: np.ndarray | None = None
    hi_bounded: np.ndarray | None = None

    @property
    def bounded(self) -> np.ndarray:
        """(m,) whether the labels bound the band on both sides at each C."""
        ok = np.ones(np.shape(self.C), bool)
        return ok & (True if self.lo_bounded is None else self.lo_bounded) & (True if self.hi_bounded is None else self.hi_bounded)

    @property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) edges of the band (ln Ca*_c), -inf / +inf where the labels do not bound it: what a
        figure draws (``lo`` / ``hi`` hold the search's reach there, which can lie inside the plotted range)."""
        lo = self.lo if self.lo_bounded is None else np.where(self.lo_bounded, self.lo, -np.inf)
        hi = self.hi if self.hi_bounded is None else np.where(self.hi_bounded, self.hi, np.inf)
        return lo, hi

    @property
    def half_width_decades(self) -> np.ndarray:
        """Half the band's width at each C, in decades of Ca*: inf where the labels do not bound it."""
        half = 0.5 * (self.hi - self.lo) / math.log(10.0)
        return np.where(self.bounded, half, np.inf)

    @property
    def reach_half_width_decades(self) -> np.ndarray:
        """Half the band's width at each C in decades, the search's reach where it is unbounded: a finite
        ranking scale for a sampler's straddle score, never a width to report."""
        return 0.5 * (self.hi - self.lo) / math.log(10.0)

    def covers(self, ln_ca_c: Any) -> bool:
        """Whether the band holds the line ln Ca*_c (values at ``C``) at every C."""
        v = np.asarray(ln_ca_c, float)
        above = (v >= self.lo) if self.lo_bounded is None else (v >= self.lo) | ~self.lo_bounded
        below = (v <= self.hi) if self.hi_bounded is None else (v <= self.hi) | ~self.hi_bounded
        return bool(np.all(above & below))


def _design(C, ca_star, fracturing):
    Cc = np.asarray(C, float).ravel()
    cs = np.asarray(ca_star, float).ravel()
    y = np.asarray(fracturing).astype(bool).astype(float).ravel()
    if not (Cc.size == cs.size == y.size) or Cc.size < 3:
        raise ValueError(f"C, ca_star, fracturing lengths=({Cc.size}, {cs.size}, {y.size}): must be equal and >= 3")
    if not (np.all(np.isfinite(Cc)) and np.all(np.isfinite(cs)) and np.all(cs > 0)):
        raise ValueError("C, ca_star: must be finite, Ca* > 0")
    X = np.c_[np.log(cs), -Cc, -np.ones_like(Cc)]
    if np.linalg.matrix_rank(X) < 3:   # the Fisher information is singular: no likelihood ratio, no band
        where = (f"every run at C = {Cc[0]:.4g} %" if np.ptp(Cc) == 0 else
                 f"every run at Ca* = {cs[0]:.4g}" if np.ptp(X[:, 0]) == 0 else "the runs lie on one line ln Ca* = a + b C")
        raise ValueError(f"C, ca_star: {where}: the separatrix Ca*_c = A exp(B C) is not identifiable (needs runs "
                         "spread over C and Ca*)")
    return X, y, _sep_min  # the Jeffreys-penalized optimizer


def separatrix_significance(C: Any, ca_star: Any, fracturing: Any) -> tuple[float, float]:
    """(LR, p-value) of the penalized likelihood-ratio test of P = expit(s (ln Ca* - ln A - B C)) against a
    constant P (Jeffreys' prior in both, as the fit; chi2 with 2 degrees of freedom). One outcome only: (0, 1)."""
    from scipy.stats import chi2

    X, y, sep_min = _design(C, ca_star, fracturing)
    if y.min() == y.max():
        return 0.0, 1.0
    full, _ = sep_min(X, y, np.eye(3))
    null, _ = sep_min(X, y, np.array([[0.0], [0.0], [1.0]]))
    lr = max(2.0 * (null - full), 0.0)
    return float(lr), float(chi2.sf(lr, 2))


def separatrix_band(C: Any, ca_star: Any, fracturing: Any, *, level: float = 0.95, simultaneous: bool = True,
                    at: Any = None, n_grid: int = 13, alpha: float = SEPARATRIX_P_MAX) -> SeparatrixBand:
    """Fit the separatrix and its profile-likelihood band of ln Ca*_c (see the module docstring).

    C (%), ca_star (-, > 0), fracturing (bools, both outcomes). ``at``: the C values of the band (default
    ``n_grid`` values over the sampled range). ``simultaneous``: threshold chi2_2(level)/2 (the whole line),
    else chi2_1(level)/2 (each C alone). ``significant``: :func:`separatrix_test` at ``alpha``. Raises ValueError
    when fracturing does not increase with Ca*.
    """
    from scipy.stats import chi2

    if not 0 < level < 1:
        raise ValueError(f"level={level!r}: must be in (0, 1)")
    X, y, sep_min = _design(C, ca_star, fracturing)
    if y.min() == y.max():
        raise ValueError("fracturing: needs both outcomes to locate a separatrix")
    full, th = sep_min(X, y, np.eye(3))
    if not th[0] > 0:
        raise ValueError("fracturing: does not increase with Ca* (fitted sharpness <= 0); no separatrix")
    test = separatrix_test(C, ca_star, fracturing, alpha)
    Cc = -X[:, 1]
    grid = np.linspace(Cc.min(), Cc.max(), n_grid) if at is None else np.atleast_1d(np.asarray(at, float))
    thr = chi2.ppf(level, 2 if simultaneous else 1) / 2.0
    lnA, B = th[2] / th[0], th[1] / th[0]
    center = lnA + B * grid
    wald = _wald_half(X, th, grid, math.sqrt(2.0 * thr))
    lo, hi = np.empty_like(grid), np.empty_like(grid)
    lo_ok, hi_ok = np.ones(grid.size, bool), np.ones(grid.size, bool)
    for i, c0 in enumerate(grid):
        step = max(0.5 * wald[i], 1e-3 * max(float(np.ptp(X[:, 0])), 1e-6))
        def rise(v, c0=c0):  # the line through (c0, v): theta_3 = v theta_1 - c0 theta_2
            return sep_min(X, y, np.array([[1.0, 0.0], [0.0, 1.0], [v, -c0]]))[0] - full - thr
        (lo[i], hi[i]), (lo_ok[i], hi_ok[i]) = _profile_search(rise, float(center[i]), step)
    with np.errstate(over="ignore"):   # a sharpness th[0] near 0 puts A beyond floats: A = inf, said as such
        A = float(np.exp(lnA))
    return SeparatrixBand(grid, center, lo, hi, level, simultaneous, A, float(B), float(th[0]),
                          test.lr, test.p_value, test.significant, int(y.size), lo_ok, hi_ok)


def separatrix_summary(C: Any, ca_star: Any, fracturing: Any, *, level: float = 0.95,
                       alpha: float = SEPARATRIX_P_MAX) -> dict:
    """What the labels say about the separatrix Ca*_c = A exp(B C), as a campaign report states it: the runs,
    the penalized likelihood-ratio test against a constant probability (``lr``, ``p_value``, ``significant`` at
    ``alpha``: :func:`separatrix_test`), and when it is significant A and B with their ``level`` profile-likelihood intervals
    (:func:`~.separatrix.separatrix_profile_interval`), ``B_positive`` (the interval of B above 0: the paper's
    increasing separatrix, Sec. 3.6) and the simultaneous band's half-width in decades at the two ends of the
    sampled C (:func:`separatrix_band`); ``reason`` says why there is no separatrix otherwise.  C in %, Ca* -."""
    Cc, cs = np.asarray(C, float).ravel(), np.asarray(ca_star, float).ravel()
    fr = np.asarray(fracturing).astype(bool).ravel()
    out: dict = {"runs": int(Cc.size), "fracturing": int(fr.sum()), "significant": False, "reason": None}
    if Cc.size < 3 or fr.all() or not fr.any():
        return {**out, "reason": "both regimes are needed to fit a separatrix"}
    try:
        test = separatrix_test(Cc, cs, fr, alpha)
    except ValueError as exc:     # a design that cannot identify the line
        return {**out, "reason": str(exc)}
    out.update({"lr": test.lr, "p_value": test.p_value, "significant": test.significant})
    if not test.significant:
        return {**out, "reason": test.reason}
    try:
        iv = separatrix_profile_interval(Cc, cs, fr, level=level)
        band = separatrix_band(Cc, cs, fr, level=level, at=[Cc.min(), Cc.max()])
    except ValueError as exc:
        return {**out, "significant": False, "reason": str(exc)}
    half = band.half_width_decades
    return {**out, "A": iv.A, "A_interval": list(iv.A_interval), "B": iv.B, "B_interval": list(iv.B_interval),
            "B_positive": bool(iv.B_interval[0] > 0), "separable": iv.separable, "level": level,
            "band_C": [float(c) for c in band.C], "band_half_width_decades": [float(h) for h in half],
            "band_log10": [[float(lo / math.log(10.0)) if lok else -math.inf, float(hi / math.log(10.0)) if hok else math.inf]
                           for lo, hi, lok, hok in zip(band.lo, band.hi, band.lo_bounded, band.hi_bounded)]}


def _wald_half(X, th, grid, z):
    """Delta-method half-widths z sd(ln Ca*_c(C)) at ``grid`` from the Fisher information at theta: the profile
    search's first step (its scale), not the band."""
    p = 0.5 * (1.0 + np.tanh(0.5 * (X @ th)))
    cov = np.linalg.pinv((X * (p * (1.0 - p))[:, None]).T @ X)
    # v = (theta_3 + C theta_2) / theta_1
    J = np.stack([-(th[2] + grid * th[1]) / th[0] ** 2, grid / th[0], np.full_like(grid, 1.0 / th[0])], axis=1)
    return z * np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", J, cov, J), 0.0))

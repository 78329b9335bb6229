"""Statistics of the discrepancy workflow (pure functions on standardized residuals).

Standardized residual r = (y − m)/σ (dimensionless).  Dense time curves give
serially correlated residuals; every criterion uses per-series weights
w = n_eff/n with n_eff = n (1 − ρ1)/(1 + ρ1) from the lag-1 autocorrelation ρ1
(clipped to [1/n, 1]), so 200 points of one smooth misfit count as ~1 piece of
evidence, not 200.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["lag1_autocorrelation", "profile_roughness", "series_weights", "effective_chi2", "bic", "systematic_test", "series_statistics",
           "project_out", "signature_table", "wald_interval", "PHASES", "phase_of_times", "symmetric_whitener",
           "moving_average", "pooled_lag1", "mean_ratio_lag1", "lag1_estimate", "LAG1_ESTIMATORS", "realization_level",
           "welch_dof", "THRESHOLDS"]

PHASES = ("before_initiation", "peak", "propagation", "late")


def lag1_autocorrelation(r) -> float:
    """Lag-1 autocorrelation of a residual series (about zero, not about its mean: a constant offset
    is systematic and must count as correlated).  0 for fewer than 3 points."""
    r = np.asarray(r, float)
    r = r[np.isfinite(r)]
    if r.size < 3:
        return 0.0
    den = float(np.dot(r, r))
    if den == 0.0:
        return 0.0
    return float(np.dot(r[1:], r[:-1]) / den)


def series_weights(r, series) -> np.ndarray:
    """Per-point weight w = n_eff/n of its series (``series``: integer label per point)."""
    r = np.asarray(r, float)
    series = np.asarray(series)
    w = np.ones_like(r)
    for s in np.unique(series):
        m = series == s
        n = int(m.sum())
        rho = max(lag1_autocorrelation(r[m]), 0.0)
        w[m] = min(1.0, max((1.0 - rho) / (1.0 + rho), 1.0 / n))
    return w


def effective_chi2(r, w) -> tuple[float, float]:
    """(χ²_eff = Σ w r², n_eff = Σ w)."""
    r = np.asarray(r, float)
    return float(np.sum(w * r * r)), float(np.sum(w))


def bic(r, w, k: int) -> float:
    """Bayesian information criterion with Gaussian standardized residuals: χ²_eff + k ln n_eff."""
    chi2, n = effective_chi2(r, w)
    return chi2 + k * math.log(max(n, 1.0))


def series_statistics(r) -> tuple:
    """(ρ1, χ² excess z, mean z) of residual series, vectorized over leading axes (last axis: time).

    ρ1 about zero (as :func:`lag1_autocorrelation`), z = (Σ r² − n)/√(2n), mean z = |mean r| √n_eff with
    n_eff = n (1 − ρ⁺)/(1 + ρ⁺) >= 1.  The statistics of :func:`systematic_test`."""
    r = np.asarray(r, float)
    n = r.shape[-1]
    ss = np.sum(r * r, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(ss > 0, np.sum(r[..., 1:] * r[..., :-1], axis=-1) / np.where(ss > 0, ss, 1.0), 0.0) \
            if n >= 3 else np.zeros_like(ss)
    z = (ss - n) / math.sqrt(2.0 * n)
    rp = np.maximum(rho, 0.0)
    n_eff = np.maximum(1.0, n * (1 - rp) / (1 + rp))
    zmean = np.abs(np.mean(r, axis=-1)) * np.sqrt(n_eff)
    return rho, z, zmean


def systematic_test(r, series, z_crit: float = 3.0, rho_crit: float = 0.3, null: dict | None = None) -> dict:
    """Are residuals above noise level?  Per series and overall.

    A series is systematic when its lag-1 autocorrelation exceeds ``rho_crit`` and its χ²
    excess z = (Σ r² − n)/√(2n) exceeds ``z_crit``, or when the mean residual is significant
    (|mean| √n > z_crit, with n reduced to n_eff).  Returns {"systematic": bool, "series": {label: {...}}}.

    ``null`` (optional): {label: object with ``adjust(z, mean_z) -> (z, mean_z)``} for series whose
    residuals were whitened with an *estimated* covariance (mesh realizations,
    :meth:`RealizationCovariance.null_calibration`): their statistics are mapped to the values with the
    same tail probability under a known covariance, so that z_crit keeps its false-alarm rate; the raw
    values are reported as ``chi2_excess_z_raw`` / ``mean_z_raw``.
    """
    r = np.asarray(r, float)
    series = np.asarray(series)
    out, any_sys = {}, False
    for s in np.unique(series):
        rs = r[series == s]
        n = rs.size
        rho = lag1_autocorrelation(rs)
        _, z, zmean = (float(v) for v in series_statistics(rs))
        row = {"n": n, "rho1": rho}
        adj = (null or {}).get(str(s))
        if adj is not None:
            row.update({"chi2_excess_z_raw": z, "mean_z_raw": zmean})
            z, zmean = adj.adjust(z, zmean)
        sys_ = bool((rho > rho_crit and z > z_crit) or zmean > z_crit and z > 0)
        any_sys |= sys_
        row.update({"chi2_excess_z": z, "mean_z": zmean, "systematic": sys_})
        out[str(s)] = row
    return {"systematic": any_sys, "series": out}


def symmetric_whitener(R) -> np.ndarray:
    """W = R^(−1/2), the symmetric inverse square root of a correlation-form covariance R (n × n, SPD).

    Symmetric, not Cholesky: W e stays attached to its points (W is close to the identity where R
    is), so whitened residuals keep their meaning per point and per series.  Wᵀ W = R⁻¹."""
    lam, V = np.linalg.eigh(np.asarray(R, float))
    lam = np.maximum(lam, 1e-12 * max(1.0, float(lam.max())))
    return (V / np.sqrt(lam)) @ V.T


def moving_average(v, window: int) -> np.ndarray:
    """Centred moving average over ``window`` points (the mean over the points available at the ends)."""
    v = np.asarray(v, float)
    h = window // 2
    c = np.concatenate([[0.0], np.cumsum(v)])
    i = np.arange(v.size)
    lo, hi = np.maximum(i - h, 0), np.minimum(i + h + 1, v.size)
    return (c[hi] - c[lo]) / (hi - lo)


def pooled_lag1(dev_series: list) -> float:
    """Lag-1 autocorrelation pooled over curves (rows of each (k, n) array, about zero; NaN: a missing point,
    left out), clipped to [0, 0.99]: the sum of the n − 1 lag products over the sum of the n squares of each
    curve.  For a stationary series of correlation ρ its expectation is ((n − 1)/n)·ρ (biased low: τ from it
    short; :func:`mean_ratio_lag1` removes the factor)."""
    num = sum(float(np.nansum(d[:, 1:] * d[:, :-1])) for d in dev_series)
    den = sum(float(np.nansum(d * d)) for d in dev_series)
    return float(np.clip(num / den, 0.0, 0.99)) if den > 0 else 0.0


def mean_ratio_lag1(dev_series: list) -> float:
    """Lag-1 autocorrelation over curves (rows of each (k, n) array, about zero; NaN: a missing point, left
    out), clipped to [0, 0.99]: the mean lag product over the mean square, each sum divided by its own count
    (the adjacent pairs with both points present, the points present).  For a stationary series of
    correlation ρ, E[d_i d_{i+1}] = ρ E[d_i²], so it tends to ρ as the curves grow in number (a ratio of
    means: bias O(1/(k n))), where :func:`pooled_lag1` tends to ((n − 1)/n)·ρ."""
    prods = [d[:, 1:] * d[:, :-1] for d in dev_series]
    n_prod = sum(int(np.isfinite(p).sum()) for p in prods)
    n_sq = sum(int(np.isfinite(d).sum()) for d in dev_series)
    if n_prod == 0 or n_sq == 0:
        return 0.0
    num = sum(float(np.nansum(p)) for p in prods) / n_prod
    den = sum(float(np.nansum(d * d)) for d in dev_series) / n_sq
    return float(np.clip(num / den, 0.0, 0.99)) if den > 0 else 0.0


# [noise] lag1: the estimator of the lag-1 autocorrelation giving the error model's correlation times τ
LAG1_ESTIMATORS = {"pooled": pooled_lag1, "mean_ratio": mean_ratio_lag1}


def lag1_estimate(dev_series: list, estimator: str = "pooled") -> float:
    """The lag-1 autocorrelation of ``dev_series`` by ``estimator`` (a key of :data:`LAG1_ESTIMATORS`)."""
    if estimator not in LAG1_ESTIMATORS:
        raise ValueError(f"lag1_estimate: estimator={estimator!r} is not allowed: one of {tuple(LAG1_ESTIMATORS)}")
    return LAG1_ESTIMATORS[estimator](dev_series)


# [profile] threshold: the profile interval's Δχ² threshold from χ²(1), or from F(1, ν) (realization_level) with
# ν = k − 1 or the Welch–Satterthwaite ν (NoiseModel.threshold_dof)
THRESHOLDS = ("chi2", "f_realizations", "f_welch")


def realization_level(level: float, nu: float) -> float:
    """The F(1, ν) quantile at the probability of the χ²(1) quantile ``level`` (3.841 at 95 % -> 6.61 at ν = 5,
    18.5 at ν = 2, 4.38 at ν = 19): Student's t²_ν, the Δχ² threshold of a one-parameter interval whose
    variance is known to ν degrees of freedom (:meth:`~.noise.NoiseModel.threshold_dof`); ``level`` itself for
    ν = ∞.  Dimensionless."""
    if not (level > 0 and math.isfinite(level)):
        raise ValueError(f"realization_level: level={level!r} is not allowed: a finite number > 0 (a χ²(1) quantile)")
    if not nu > 0:
        raise ValueError(f"realization_level: nu={nu!r} is not allowed: degrees of freedom > 0 (inf: χ²(1))")
    if math.isinf(nu):
        return float(level)
    from scipy.stats import chi2, f

    return float(f.ppf(chi2.cdf(level, 1), 1, nu))


def welch_dof(var_total: float, var_estimated: float, dof: float) -> float:
    """Welch–Satterthwaite degrees of freedom of a variance V = V_known + V_est whose part V_est is estimated
    with ``dof`` degrees of freedom and the rest known: ν = dof (V/V_est)² (Satterthwaite 1946, Biometrics
    Bulletin 2: 110; Welch 1947, Biometrika 34: 28); ``dof`` when V is all estimated, ∞ when none is."""
    if var_estimated <= 0.0:
        return math.inf
    return float(dof * (var_total / var_estimated) ** 2)


# a profile falling by more than this fraction of its threshold walking away from its lowest point is
# non-monotone (2 %, ~0.08 in Δχ² at 95 %: above the refits' convergence tolerance, below any jitter that
# moves a bound)
MONOTONE_TOL = 0.02


def profile_roughness(values, delta_chi2, center: float) -> float:
    """How far a profile likelihood falls when it should rise: the largest drop of Δχ² met walking away from
    ``center`` (the fit) on either side, i.e. max over points of (highest Δχ² nearer the fit on that side − Δχ²
    here), 0 for a profile monotone on each side.

    A true profile rises monotonically away from its minimum.  A coarse forward model whose outputs jitter with
    the parameter (the front radius of a fingering front jumps from node to node) gives a jagged profile whose
    threshold crossings are set by the jitter, not by the data: the interval can be far too narrow.  The drop measures that jitter in Δχ² units.
    """
    v = np.asarray(values, float)
    d = np.asarray(delta_chi2, float)
    worst = 0.0
    for side in (v > center, v < center):
        order = np.argsort(np.abs(v[side] - center))
        dd = d[side][order]
        if dd.size:
            worst = max(worst, float(np.max(np.maximum.accumulate(dd) - dd)))
    return worst


def quadratic_profile_interval(values, delta_chi2, threshold: float, level: float = 3.841,
                               cap: float = 4.0) -> dict | None:
    """Profile interval from a quadratic fitted to noisy profile points (MCAP, Ionides et al. 2017, J. R. Soc.
    Interface 14: 20170126, in its quadratic form).

    A forward model that jitters in its parameters makes every profile point a noisy evaluation, and the joint
    fit the luckiest of many (the minimum of a noisy function sits below the smooth one), so Δχ² measured from
    it is biased upward and the raw crossings give a falsely narrow interval.  Here y = Δχ²/s (s =
    threshold/level, the misfit scale) is fitted by least squares with y ≈ A (v − v0)² + c over the points with
    Δχ² ≤ ``cap``·threshold (the quadratic region); the statistical variance of the centre is 1/A (in the
    log-likelihood ℓ = −y/2 = −a v² + …, 1/(2a)), its Monte-Carlo variance se_mc² follows from the fit's
    coefficient covariance (σ̂² (XᵀX)⁻¹, σ̂² = RSS/(n − 3)) by the delta method, and the interval is
    v0 ± √(level (1/A + se_mc²)) (MCAP's cutoff level·(a se_mc² + 1/2) on ℓ).  ``values`` in the parameter's
    units.  None when fewer than 5 points are in the region; when A ≤ 0 or the centre lies outside the points
    (no minimum: the smoothed profile does not constrain the parameter there) the interval is the points'
    span and ``unbounded`` is set."""
    v = np.asarray(values, float)
    d = np.asarray(delta_chi2, float)
    keep = np.isfinite(v) & np.isfinite(d) & (d <= cap * threshold)
    v, d = v[keep], d[keep]
    if v.size < 5:
        return None
    sc = threshold / level
    vm, vs = float(v.mean()), float(np.ptp(v)) or 1.0
    u = (v - vm) / vs
    X = np.column_stack([np.ones_like(u), u, u * u])
    coef, *_ = np.linalg.lstsq(X, d / sc, rcond=None)
    c0, B, A = coef
    u0 = -B / (2 * A) if A > 0 else np.nan
    if not (u.min() < u0 < u.max()):
        # no minimum inside the points: the smoothed profile excludes none of them (at least their span)
        return {"center": None, "lower": float(v.min()), "upper": float(v.max()), "se_stat": None, "se_mc": None,
                "residual_sd": None, "n": int(v.size), "unbounded": True}
    res = d / sc - X @ coef
    s2 = float(res @ res) / (v.size - 3)
    cov = s2 * np.linalg.pinv(X.T @ X)
    g = np.array([0.0, -1.0 / (2 * A), B / (2 * A * A)])
    se_mc2 = float(g @ cov @ g)
    se_stat2 = 1.0 / A
    half = math.sqrt(level * (se_stat2 + se_mc2))
    return {"center": vm + vs * u0, "lower": vm + vs * (u0 - half), "upper": vm + vs * (u0 + half),
            "se_stat": vs * math.sqrt(se_stat2), "se_mc": vs * math.sqrt(se_mc2),
            "residual_sd": math.sqrt(s2) * sc, "n": int(v.size), "unbounded": False}


def project_out(J, s) -> np.ndarray:
    """Component of the signature vector ``s`` orthogonal to the columns of ``J`` (least squares)."""
    s = np.asarray(s, float)
    J = np.asarray(J, float)
    if J.size == 0:
        return s.copy()
    Q, R = np.linalg.qr(J)
    keep = np.abs(np.diag(R)) > 1e-12 * max(1.0, np.abs(R).max())
    Q = Q[:, keep]
    return s - Q @ (Q.T @ s)


def bounded_lstsq(M, s, lower=None, upper=None) -> np.ndarray:
    """The least-squares c of M c = s with lower <= c <= upper elementwise (None or ±inf: unbounded on that
    side; all unbounded: the minimum-norm solution of numpy's lstsq).  A parameter that can move only within its
    range moves a signature only that far: a direction reachable only by a move outside it does not count."""
    M, s = np.asarray(M, float), np.asarray(s, float)
    n = M.shape[1]
    lb = np.full(n, -np.inf) if lower is None else np.asarray(lower, float)
    ub = np.full(n, np.inf) if upper is None else np.asarray(upper, float)
    if lb.shape != (n,) or ub.shape != (n,) or np.any(lb > ub):
        raise ValueError(f"bounded_lstsq: bounds {lb}, {ub} are not allowed for {n} columns: lower <= upper, one each")
    c = np.linalg.lstsq(M, s, rcond=None)[0] if n else np.zeros(0)
    if n == 0 or np.all((c >= lb) & (c <= ub)):
        return c
    from scipy.optimize import lsq_linear

    return lsq_linear(M, s, bounds=(lb, ub), method="bvls", tol=1e-12).x


def signature_table(r, w, J, signatures: dict, *, min_ratio: float = 0.15, tie_cos: float = 0.95,
                    A=None, alternatives: tuple = (), bounds=None) -> dict:
    """Screen candidate effects from their signatures.

    r : standardized residuals of the calibrated baseline; w : series weights; J : Jacobian of the
    *model* (standardized, dm/σ) w.r.t. the calibrated parameters; signatures : {name: s} with
    s = (m(probe) − m(off))/σ.  For each candidate: its projected signature s⊥ (off J), the ratio
    ‖s⊥‖/‖s‖ (identifiable when >= ``min_ratio`` and s ≠ 0), the linearized best amplitude
    a = (w r·s⊥)/(w s⊥·s⊥) in units of the probe strength, and the score = linearized χ²_eff drop
    (0 when a <= 0: the data ask for the effect "below off").  ``tied_with`` lists identifiable
    candidates whose projected signatures have |cos| >= ``tie_cos`` with this one.

    ``A`` (columns: the model's standardized change for a step of each of the ``alternatives``, baseline
    parameters held fixed but uncertain): the signature is also projected off [J, A].  Its
    ``alternative_ratio`` below ``min_ratio`` makes the candidate not identifiable, and ``confounded_with``
    names the alternatives that bring it there (each alone, or all together when none does alone): what
    the candidate would explain, a change of those parameters would explain as well.  ``bounds`` (lower, upper:
    one per column of [J, A], in the columns' units) keeps those changes within the parameters' ranges
    (:func:`bounded_lstsq`), for the calibrated parameters' projection (``ratio``, the amplitude and the score)
    as for the alternatives': a signature the parameters reproduce only beyond their range is not confounded
    with them.  None: unbounded.
    """
    r = np.asarray(r, float)
    sw = np.sqrt(np.asarray(w, float))
    Jw = np.asarray(J, float) * sw[:, None] if np.size(J) else np.zeros((r.size, 0))
    Aw = np.asarray(A, float) * sw[:, None] if A is not None and np.size(A) else np.zeros((r.size, 0))
    if Aw.shape[1] != len(alternatives):
        raise ValueError(f"signature_table: {Aw.shape[1]} alternative columns for alternatives {alternatives}")
    out, perp = {}, {}
    for name, s in signatures.items():
        s = np.asarray(s, float)
        ok = np.all(np.isfinite(s))
        sw_s = np.where(np.isfinite(s), s, 0.0) * sw
        ns = float(np.linalg.norm(sw_s))
        sp = _off_calibrated(Jw, sw_s, bounds) if ns > 0 else sw_s
        nsp = float(np.linalg.norm(sp))
        ratio = nsp / ns if ns > 0 else 0.0
        alt_ratio, confounded = _alternative_ratio(Jw, Aw, alternatives, sw_s, ns, min_ratio, bounds)
        ident = bool(ok and ns > 1e-9 and ratio >= min_ratio and not confounded)
        rw = r * sw
        a = float(rw @ sp / nsp**2) if nsp > 0 else 0.0
        score = float((rw @ sp) ** 2 / nsp**2) if (nsp > 0 and a > 0) else 0.0
        out[name] = {"norm": ns, "projected_norm": nsp, "ratio": ratio, "identifiable": ident,
                     "amplitude": a, "score": score if ident else 0.0, "tied_with": [], "finite": bool(ok),
                     "alternative_ratio": alt_ratio, "confounded_with": confounded}
        perp[name] = sp
    names = [n for n in out if out[n]["identifiable"]]
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            c = abs(float(perp[a] @ perp[b])) / (out[a]["projected_norm"] * out[b]["projected_norm"])
            if c >= tie_cos:
                out[a]["tied_with"].append(b)
                out[b]["tied_with"].append(a)
    return out


def _off_calibrated(Jw, sw_s, bounds=None) -> np.ndarray:
    """The part of the (weighted) signature ``sw_s`` the calibrated parameters' columns ``Jw`` cannot reproduce:
    its least-squares residual on them, within their ranges when ``bounds`` (lower, upper per column of [J, A])
    are given (:func:`bounded_lstsq`, the same rule as :func:`_alternative_ratio`), else the orthogonal
    projection (:func:`project_out`)."""
    if bounds is None or Jw.shape[1] == 0:
        return project_out(Jw, sw_s)
    nJ = Jw.shape[1]
    lb, ub = (np.asarray(b, float)[:nJ] for b in bounds)
    return sw_s - Jw @ bounded_lstsq(Jw, sw_s, lb, ub)


def _alternative_ratio(Jw, Aw, alternatives, sw_s, ns, min_ratio, bounds=None) -> tuple:
    """(‖s off [J, A]‖/‖s‖, the alternatives that bring it below ``min_ratio``), or (None, []) without any;
    with ``bounds`` (lower, upper per column of [J, A]) the residual of the bounded least squares."""
    if not alternatives:
        return None, []
    if ns <= 0:
        return 0.0, []
    nJ = Jw.shape[1]

    def ratio(cols):
        M = np.column_stack([Jw, Aw[:, cols]])
        keep = list(range(nJ)) + [nJ + k for k in cols]
        lb, ub = (None, None) if bounds is None else (np.asarray(b, float)[keep] for b in bounds)
        return float(np.linalg.norm(M @ bounded_lstsq(M, sw_s, lb, ub) - sw_s)) / ns

    total = ratio(list(range(len(alternatives))))
    if total >= min_ratio:
        return total, []
    alone = [a for k, a in enumerate(alternatives) if ratio([k]) < min_ratio]
    return total, alone or list(alternatives)


def wald_interval(J, r, w, index: int, x_hat: float, level_z: float = 1.96,
                  min_ratio: float = 0.02) -> tuple[float, float, float]:
    """(lower, upper, sd) of parameter ``index`` from the Gauss–Newton covariance.

    When the parameter's column of J is (up to ``min_ratio`` of its norm) a combination of the others
    the fit sits on a ridge: the interval is (−inf, inf) rather than a falsely narrow one.
    cov = (Jᵀ W J)⁻¹ · max(1, χ²_eff/(n_eff − k)) with J = ∂r/∂x (standardized), W = diag(w):
    the weights widen the interval for correlated residuals, the factor for misfit beyond noise.
    """
    J = np.asarray(J, float)
    w = np.asarray(w, float)
    k = J.shape[1]
    sw = np.sqrt(w)[:, None]
    col = J[:, index] * sw[:, 0]
    others = np.delete(J * sw, index, axis=1)
    nc = float(np.linalg.norm(col))
    if nc == 0.0 or float(np.linalg.norm(project_out(others, col))) < min_ratio * nc:
        return -math.inf, math.inf, math.inf     # on a ridge: not separately determined
    A = J.T @ (J * w[:, None])
    chi2, n = effective_chi2(r, w)
    scale = max(1.0, chi2 / max(n - k, 1.0))
    try:
        cov = np.linalg.pinv(A) * scale
    except np.linalg.LinAlgError:
        return -math.inf, math.inf, math.inf
    sd = float(math.sqrt(max(cov[index, index], 0.0)))
    return x_hat - level_z * sd, x_hat + level_z * sd, sd


def phase_of_times(t, p_meas, crack_meas=None, crack_tol: float = 0.5) -> np.ndarray:
    """Phase label index (into PHASES) of each time (s) of one condition.

    t_init = first time the measured crack length exceeds ``crack_tol`` mm, else the time the measured
    pressure reaches 90 % of its maximum; t_peak = time of the pressure maximum (>= t_init);
    before_initiation: t < t_init; peak: t_init <= t <= t_peak + 0.1 T; propagation: up to
    t_peak + 0.5 (T − t_peak); late: after.  T = last time.
    """
    t = np.asarray(t, float)
    tp, pp = p_meas
    tp, pp = np.asarray(tp, float), np.asarray(pp, float)
    T = float(max(t.max(), tp.max()))
    t_peak = float(tp[int(np.argmax(pp))])
    t_init = float(tp[int(np.argmax(pp >= 0.9 * pp.max()))])
    if crack_meas is not None:
        tc, cc = (np.asarray(a, float) for a in crack_meas)
        if np.any(cc > crack_tol):
            t_init = float(tc[int(np.argmax(cc > crack_tol))])
    t_peak = max(t_peak, t_init)
    ph = np.full(t.shape, 3, int)
    ph[t <= t_peak + 0.5 * (T - t_peak)] = 2
    ph[t <= t_peak + 0.1 * T] = 1
    ph[t < t_init] = 0
    return ph

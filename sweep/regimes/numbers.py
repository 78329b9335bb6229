"""Dimensionless numbers of the paper (Secs. 2.10, 3.6, 3.8) and the critical pressure.

Units: mm, s, kPa (viscosity kPa*s, permeability mm^2, surface tension kPa*mm,
velocity mm/s).  All functions broadcast over numpy arrays.

Definitions (equation labels of the paper):

* Ca = eta_o w_i / gamma  (capillary number of Eq. dimensionless_groups with the
  characteristic viscosity eta_0 = eta_2 = eta_o and velocity v_0 = w_i).
* Ca* = Ca l0 delta / k0  (Eq. modified_capillary_number), l0 = r_o (the paper: "the
  characteristic length l0 is taken as the radius r_o of the Hele-Shaw cell"), delta =
  bead diameter.
* dp_vis = eta_o w_i l0 / k0  (Eq. viscous_pressure_drop), in kPa.  The paper states
  l0 = r_o in the Ca* paragraph that introduces this equation and does not restate it
  in Sec. 3.8, so ``l0`` is an argument with default r_o = 53 mm.
* N_b = eta_w l0^2 / (eta_o k0)  (Eq. Nb), l0 = r_i = 5 mm (Sec. 3.8).
* N_f = dp_vis / dp_cri  (Eq. Nf); dp_cri is common to all runs with the same
  fracture parameters. The paper gives no value: it is either given, or estimated from
  a campaign as the value of dp_vis where a logistic regression of the fracturing
  outcome on log(dp_vis) crosses 1/2 (``estimate_dp_cri``).
* k0: "the initial average permeability" (Sec. 3.8).  Choice made here: the mean of
  the Kozeny-Carman permeability k(phi0) = kbar phi0^3/(1 - phi0)^2 (Eq. permeability)
  over the domain, i.e. the area-weighted mean over the mesh of the initial field
  (``k0_mean``), or, without a mesh, its expectation for phi0 uniform in
  [phi_lo, phi_hi] (``k0_uniform_expectation``; 0.3264 kbar for [0.2, 0.6]).  The
  alternative k(mean phi0) = 0.1778 kbar (phi0 = 0.4) is 1.84 times smaller; it is
  used only when no porosity range is given (a uniform field).  ``phi_range`` follows
  solver.params.Parameters (half-width: 0.4 +- 0.2) or is a (lo, hi) pair.  Note that the
  paper's "initial average permeability ... 0.0015 mm^2" (Sec. 3.5) is entered as kbar
  in Table A / solver.params; with this k0 definition the reference run has
  k0 = 4.90e-4 mm^2.  The cap
  k <= k_max = h_cell^2/12 = 0.31 mm^2 (Sec. 2.8) is not reached by initial fields of the
  paper's ranges (kbar <= 0.1 mm^2, phi0 <= 0.6 gives k <= 0.135 mm^2) and is applied
  only when ``k_max`` is passed.
* M = eta_o / eta_w  (viscosity ratio M = eta_2/eta_1 of Eq. dimensionless_groups:
  fluid 1 is the invading water, fluid 2 the defending oil), so N_b = M^-1 Da^-1 with
  Da = k0 / l0^2 and l0 = r_i.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.optimize import minimize

__all__ = [
    "kozeny_carman",
    "k0_mean",
    "k0_uniform_expectation",
    "capillary_number",
    "modified_capillary_number",
    "viscous_pressure_drop",
    "branching_number",
    "fracturing_number",
    "dimensionless_numbers",
    "logistic_fit",
    "LogisticFit",
    "DpCriEstimate",
    "estimate_dp_cri",
]


# --------------------------------------------------------------------------- checks
def _positive(name: str, value: Any) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.size == 0 or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"{name}={value!r}: must be finite and > 0 (range (0, inf))")
    return a


def _out(a: np.ndarray) -> Any:
    return float(a) if np.ndim(a) == 0 else a


def _porosity(name: str, value: Any) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.size == 0 or not np.all(np.isfinite(a)) or np.any(a <= 0) or np.any(a >= 1):
        raise ValueError(f"{name}={value!r}: porosity must lie in (0, 1)")
    return a


# --------------------------------------------------------------------------- permeability
def kozeny_carman(phi: Any, kbar: Any, k_max: float | None = None) -> Any:
    """k(phi) = kbar phi^3 / (1 - phi)^2 (Eq. permeability), mm^2; capped at k_max if given."""
    ph = _porosity("phi", phi)
    kb = _positive("kbar", kbar)
    k = kb * ph**3 / (1.0 - ph) ** 2
    if k_max is not None:
        k = np.minimum(k, _positive("k_max", k_max))
    return _out(k)


def k0_mean(kbar: float, phi0: Any, areas: Any = None, k_max: float | None = None) -> float:
    """Initial mean permeability k0 (mm^2): area-weighted mean of k(phi0) over elements.

    kbar: Kozeny-Carman coefficient (mm^2); phi0 (M,) initial porosity per element;
    areas (M,) element areas (mm^2), default equal weights; k_max optional cap (mm^2).
    """
    ph = _porosity("phi0", phi0).ravel()
    if areas is None:
        w = np.ones_like(ph)
    else:
        w = _positive("areas", areas).ravel()
        if w.shape != ph.shape:
            raise ValueError(f"areas shape={w.shape}: must match phi0 shape={ph.shape}")
    k = np.asarray(kozeny_carman(ph, float(_positive("kbar", kbar)), k_max))
    return float(np.sum(w * k) / np.sum(w))


def _kc_antiderivative(phi: np.ndarray) -> np.ndarray:
    # phi^3/(1-phi)^2 = u^-2 - 3 u^-1 + 3 - u with u = 1 - phi, d(phi) = -du
    u = 1.0 - phi
    return -(-1.0 / u - 3.0 * np.log(u) + 3.0 * u - 0.5 * u * u)


def k0_uniform_expectation(kbar: Any, phi_lo: float = 0.2, phi_hi: float = 0.6) -> Any:
    """E[k(phi)] (mm^2) for phi uniform in [phi_lo, phi_hi] (the random field of Sec. 3.3).

    Closed form: with u = 1 - phi, phi^3/(1-phi)^2 = u^-2 - 3/u + 3 - u, whose
    antiderivative in phi is F(phi) = 1/u + 3 ln u - 3u + u^2/2, so
    E = kbar (F(phi_hi) - F(phi_lo)) / (phi_hi - phi_lo); for [0.2, 0.6] E = 0.326395 kbar.
    phi_lo == phi_hi gives k(phi_lo).
    """
    kb = _positive("kbar", kbar)
    lo = float(_porosity("phi_lo", phi_lo))
    hi = float(_porosity("phi_hi", phi_hi))
    if hi < lo:
        raise ValueError(f"phi_hi={phi_hi!r}: must be >= phi_lo={phi_lo!r}")
    if hi - lo < 1e-12:
        return _out(kb * lo**3 / (1 - lo) ** 2)
    mean = (_kc_antiderivative(np.array(hi)) - _kc_antiderivative(np.array(lo))) / (hi - lo)
    return _out(kb * float(mean))


# --------------------------------------------------------------------------- numbers
def capillary_number(eta_o: Any, w_i: Any, gamma: Any) -> Any:
    """Ca = eta_o w_i / gamma (Eq. dimensionless_groups, eta_0 = eta_o, v_0 = w_i).

    eta_o kPa*s, w_i mm/s, gamma kPa*mm -> dimensionless."""
    return _out(_positive("eta_o", eta_o) * _positive("w_i", w_i) / _positive("gamma", gamma))


def modified_capillary_number(eta_o: Any, w_i: Any, gamma: Any, k0: Any, *,
                              l0: Any = 53.0, delta: Any = 2.0) -> Any:
    """Ca* = Ca l0 delta / k0 (Eq. modified_capillary_number, Holtzman et al. 2012).

    l0 = r_o (mm, default 53), delta = bead diameter (mm, default 2), k0 mm^2."""
    ca = np.asarray(capillary_number(eta_o, w_i, gamma))
    return _out(ca * _positive("l0", l0) * _positive("delta", delta) / _positive("k0", k0))


def viscous_pressure_drop(eta_o: Any, w_i: Any, k0: Any, l0: Any = 53.0) -> Any:
    """dp_vis = eta_o w_i l0 / k0 (Eq. viscous_pressure_drop), kPa.

    eta_o kPa*s, w_i mm/s, k0 mm^2, l0 mm (default r_o = 53 mm, as in the paper's
    Ca* paragraph where the equation is introduced)."""
    return _out(_positive("eta_o", eta_o) * _positive("w_i", w_i) * _positive("l0", l0)
                / _positive("k0", k0))


def branching_number(eta_w: Any, eta_o: Any, k0: Any, l0: Any = 5.0) -> Any:
    """N_b = eta_w l0^2 / (eta_o k0) (Eq. Nb), l0 = r_i (mm, default 5), k0 mm^2."""
    return _out(_positive("eta_w", eta_w) * _positive("l0", l0) ** 2
                / (_positive("eta_o", eta_o) * _positive("k0", k0)))


def fracturing_number(dp_vis: Any, dp_cri: Any) -> Any:
    """N_f = dp_vis / dp_cri (Eq. Nf); both in kPa."""
    return _out(_positive("dp_vis", dp_vis) / _positive("dp_cri", dp_cri))


_ATTRS = ("eta_o", "eta_w", "kbar", "w_i", "gamma", "r_inner", "r_outer", "bead_diameter",
          "phi_mean", "phi_range", "k0", "porosity_field")
_ALIASES = {
    "r_inner": ("r_inner", "inner_radius", "r_i"),
    "r_outer": ("r_outer", "outer_radius", "r_o"),
    "bead_diameter": ("bead_diameter", "delta", "grain_size"),
    "phi_mean": ("phi_mean", "phi0", "porosity_mean"),
    "phi_range": ("phi_range", "porosity_range", "phi0_range"),
    "w_i": ("w_i", "inner_darcy_velocity"),
    "eta_o": ("eta_o", "oil_viscosity"),
    "eta_w": ("eta_w", "water_viscosity"),
    "kbar": ("kbar", "permeability_coeff", "k_bar"),
    "gamma": ("gamma", "surface_tension"),
    "k0": ("k0",),
    "porosity_field": ("porosity_field",),
}
_DEFAULTS = {"r_inner": 5.0, "r_outer": 53.0, "bead_diameter": 2.0, "phi_mean": 0.4,
             "phi_range": None, "k0": None, "porosity_field": "random"}


def _get(obj: Any, key: str) -> Any:
    for name in _ALIASES[key]:
        if isinstance(obj, Mapping):
            if name in obj:
                return obj[name]
        elif hasattr(obj, name):
            return getattr(obj, name)
    if key in _DEFAULTS:
        return _DEFAULTS[key]
    raise ValueError(f"params_like: missing {key!r} (accepted names {_ALIASES[key]})")


def _porosity_bounds(phi_mean: Any, phi_range: Any, porosity_field: Any) -> tuple[float, float]:
    """(lo, hi) of the uniform initial porosity.

    phi_range: None or 0 -> uniform phi_mean; a number -> half-width around phi_mean
    (solver.params.Parameters convention: 0.2 gives [0.2, 0.6]); a pair -> (lo, hi).
    porosity_field other than "random" ("constant", "pockets") -> phi_mean (the three
    small pockets of the convergence field are neglected)."""
    pm = float(_porosity("phi_mean", phi_mean))
    if phi_range is None or str(porosity_field) != "random":
        return pm, pm
    if np.ndim(phi_range) == 0:
        hw = float(phi_range)
        if not (math.isfinite(hw) and 0 <= hw < min(pm, 1 - pm) + 1e-12):
            raise ValueError(f"phi_range={phi_range!r}: half-width must be in [0, "
                             f"{min(pm, 1 - pm)}) for phi_mean={pm}")
        return max(pm - hw, 1e-9), min(pm + hw, 1 - 1e-9)
    lo, hi = (float(x) for x in phi_range)
    _porosity("phi_range[0]", lo)
    _porosity("phi_range[1]", hi)
    if hi < lo:
        raise ValueError(f"phi_range={phi_range!r}: needs lo <= hi")
    return lo, hi


def dimensionless_numbers(params_like: Any, dp_cri: float | None = None, *,
                          l0_vis: float | None = None, k_max: float | None = None) -> dict:
    """Dimensionless numbers of one run.

    params_like: Mapping or object with eta_o, eta_w (kPa*s), kbar (mm^2), w_i (mm/s),
    gamma (kPa*mm), r_inner, r_outer, bead_diameter (mm), phi_mean, phi_range (half-width
    as in solver.params.Parameters, or a (lo, hi) pair, or None), k0 (mm^2 or None),
    optionally porosity_field.  Missing geometry defaults to the paper (5, 53, 2 mm,
    phi_mean 0.4, no range).  k0: given, else the expectation of k(phi0) for phi0 uniform
    over the range (k0_uniform_expectation; 0.3264 kbar for 0.4 +- 0.2), else
    k(phi_mean).  dp_cri (kPa): gives N_f (else NaN).
    l0_vis: l0 of dp_vis (default r_outer).  k_max: optional permeability cap (mm^2).

    Returns {"k0", "Ca", "Ca_star", "dp_vis", "N_b", "N_f", "M", "Da"} where
    Ca_star uses l0 = r_outer, N_b and Da use l0 = r_inner, M = eta_o/eta_w.
    """
    v = {k: _get(params_like, k) for k in _ATTRS}
    for k in ("eta_o", "eta_w", "kbar", "w_i", "gamma", "r_inner", "r_outer", "bead_diameter"):
        _positive(k, v[k])
    if float(v["r_outer"]) <= float(v["r_inner"]):
        raise ValueError(f"r_outer={v['r_outer']!r}: must be > r_inner={v['r_inner']!r}")
    k0 = v["k0"]
    if k0 is None:
        lo, hi = _porosity_bounds(v["phi_mean"], v["phi_range"], v["porosity_field"])
        k0 = k0_uniform_expectation(v["kbar"], lo, hi)
        if k_max is not None:
            k0 = min(float(k0), float(_positive("k_max", k_max)))
    k0 = float(_positive("k0", k0))
    l0v = float(v["r_outer"]) if l0_vis is None else float(_positive("l0_vis", l0_vis))
    dp_vis = viscous_pressure_drop(v["eta_o"], v["w_i"], k0, l0v)
    return {
        "k0": k0,
        "Ca": capillary_number(v["eta_o"], v["w_i"], v["gamma"]),
        "Ca_star": modified_capillary_number(v["eta_o"], v["w_i"], v["gamma"], k0,
                                             l0=v["r_outer"], delta=v["bead_diameter"]),
        "dp_vis": dp_vis,
        "N_b": branching_number(v["eta_w"], v["eta_o"], k0, v["r_inner"]),
        "N_f": fracturing_number(dp_vis, dp_cri) if dp_cri is not None else math.nan,
        "M": float(v["eta_o"]) / float(v["eta_w"]),
        "Da": k0 / float(v["r_inner"]) ** 2,
    }


# --------------------------------------------------------------------------- logistic
@dataclass(frozen=True)
class LogisticFit:
    """P(y = 1 | x) = 1 / (1 + exp(-(beta[0] + x . beta[1:]))); cov = inverse Hessian."""

    beta: np.ndarray
    cov: np.ndarray
    n: int
    converged: bool
    separable: bool


def logistic_fit(X: Any, y: Any, ridge: float = 1e-3) -> LogisticFit:
    """Maximum-likelihood logistic regression (scipy.optimize, Newton-CG).

    X (n, p) features, y (n,) booleans. Features are standardised internally; ``ridge``
    is an L2 penalty 0.5*ridge*|b|^2 on the standardised slopes (not the intercept),
    which keeps the estimate finite for separable data (then the boundary is the
    penalised, margin-like solution and ``cov`` is not a sampling uncertainty:
    ``separable`` flags this case). Returns coefficients in the original units and
    their covariance (inverse Hessian of the penalised negative log-likelihood).
    """
    Xa = np.asarray(X, dtype=float)
    if Xa.ndim == 1:
        Xa = Xa[:, None]
    ya = np.asarray(y).astype(bool).astype(float).ravel()
    if Xa.ndim != 2 or len(Xa) != len(ya) or len(ya) < 2:
        raise ValueError(f"X shape={Xa.shape}, y length={len(ya)}: need X (n, p), y (n,), n >= 2")
    if not np.all(np.isfinite(Xa)):
        raise ValueError("X: contains non-finite values; all must be finite")
    if ya.min() == ya.max():
        raise ValueError("y: needs both classes (True and False) to locate a boundary")
    if not (ridge >= 0 and math.isfinite(ridge)):
        raise ValueError(f"ridge={ridge!r}: must be in [0, inf)")
    mu = Xa.mean(axis=0)
    sd = Xa.std(axis=0)
    sd[sd == 0] = 1.0
    Z = np.c_[np.ones(len(ya)), (Xa - mu) / sd]
    pen = np.full(Z.shape[1], ridge)
    pen[0] = 0.0

    def nll(b):
        s = Z @ b
        return float(np.sum(np.logaddexp(0.0, s) - ya * s) + 0.5 * np.sum(pen * b * b))

    def grad(b):
        pr = 0.5 * (1 + np.tanh(0.5 * (Z @ b)))
        return Z.T @ (pr - ya) + pen * b

    def hess(b):
        pr = 0.5 * (1 + np.tanh(0.5 * (Z @ b)))
        return (Z * (pr * (1 - pr))[:, None]).T @ Z + np.diag(pen)

    res = minimize(nll, np.zeros(Z.shape[1]), jac=grad, hess=hess, method="trust-exact",
                   options={"gtol": 1e-9, "maxiter": 500})
    bz = res.x
    H = hess(bz)
    cov_z = np.linalg.pinv(H)
    # back to original units: beta0 = b0 - sum(b_j mu_j / sd_j), beta_j = b_j / sd_j
    T = np.zeros_like(H)
    T[0, 0] = 1.0
    T[0, 1:] = -mu / sd
    T[1:, 1:] = np.diag(1.0 / sd)
    beta = T @ bz
    cov = T @ cov_z @ T.T
    pred = (Z @ bz) > 0
    separable = bool(np.all(pred == (ya > 0.5)))
    return LogisticFit(beta=beta, cov=cov, n=len(ya), converged=bool(res.success),
                       separable=separable)


@dataclass(frozen=True)
class DpCriEstimate:
    """Critical viscous pressure drop (kPa) from a campaign.

    dp_cri: where P(fracturing) = 1/2 on the fitted logistic curve in ln(dp_vis);
    interval: ~95% interval (delta method, +-1.96 sigma of ln dp_cri);
    bracket: (largest dp_vis of a non-fracturing run, smallest dp_vis of a fracturing
    run); slope: logistic slope per unit ln(dp_vis); separable: the data are perfectly
    separated (then the interval reflects the ridge, not sampling).
    """

    dp_cri: float
    interval: tuple[float, float]
    bracket: tuple[float, float]
    slope: float
    n: int
    separable: bool


def estimate_dp_cri(dp_vis: Any, fracturing: Any, ridge: float = 1e-3) -> DpCriEstimate:
    """Estimate dp_cri (kPa) as the transition of a logistic fit of fracturing on ln(dp_vis).

    dp_vis (n,) kPa; fracturing (n,) bools; needs both outcomes.  N_f = 1 is then the
    50 % fracturing line of the campaign (the paper's delimiter N_f = 1, Sec. 3.8).
    """
    dp = _positive("dp_vis", dp_vis).ravel()
    fr = np.asarray(fracturing).astype(bool).ravel()
    if fr.shape != dp.shape:
        raise ValueError(f"fracturing length={fr.size}: must match dp_vis length={dp.size}")
    x = np.log(dp)
    fit = logistic_fit(x, fr, ridge=ridge)
    b0, b1 = fit.beta
    if b1 <= 0:
        raise ValueError("fracturing: does not increase with dp_vis (fitted slope <= 0); "
                         "cannot define a critical pressure")
    lx = -b0 / b1
    g = np.array([-1.0 / b1, b0 / b1**2])
    s = float(np.sqrt(max(g @ fit.cov @ g, 0.0)))
    nonfr = dp[~fr]
    yes = dp[fr]
    return DpCriEstimate(
        dp_cri=float(np.exp(lx)),
        interval=(float(np.exp(lx - 1.96 * s)), float(np.exp(lx + 1.96 * s))),
        bracket=(float(nonfr.max()) if nonfr.size else math.nan,
                 float(yes.min()) if yes.size else math.nan),
        slope=float(b1),
        n=fit.n,
        separable=fit.separable,
    )

"""The profile interval's threshold at few mesh realizations k ([profile] threshold = "f_realizations" or
"f_welch"): the F(1, ν) quantile of the χ²(1) level's probability (stats.realization_level), ν = k − 1 or the
Welch–Satterthwaite degrees of freedom of the strength's variance whose realization part is known to k − 1
(NoiseModel.threshold_dof, strength_dof).
Known answers: the closed-form Student quantiles at ν = 1 (Cauchy) and ν = 2, the χ²(1) level at ν = ∞; ν =
k − 1 when the realization term is all of the variance, the Welch formula with a known noise share, ∞ without
realizations; the exact coverage of one more realization's prediction interval (Student 1908) through the
workflow's own noise model; the threshold of a linear model's profile scaled by exactly that ratio."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, t

from sweep.discrepancy.layout import CurveLayout
from sweep.discrepancy.noise import NoiseModel
from sweep.discrepancy.options import ProfileOptions, parse_options
from sweep.discrepancy.stats import realization_level, welch_dof

LEVEL = float(chi2.ppf(0.95, 1))          # 3.841


def test_the_f_level_is_students_t_squared_in_closed_form_and_chi2_in_the_limit():
    """F(1, ν) = t²_ν: ν = 1 the Cauchy quantile tan(π (p − ½)), ν = 2 the closed form (2p − 1)/√(2p(1 − p))
    (p = 0.975 for 95 %); ν → ∞ the χ²(1) level, ν = ∞ exactly it; decreasing in ν."""
    p = 0.975
    assert realization_level(LEVEL, 1) == pytest.approx(math.tan(math.pi * (p - 0.5)) ** 2, rel=1e-9)
    assert realization_level(LEVEL, 2) == pytest.approx(((2 * p - 1) / math.sqrt(2 * p * (1 - p))) ** 2, rel=1e-9)
    assert realization_level(LEVEL, 1e8) == pytest.approx(LEVEL, rel=1e-6)
    assert realization_level(LEVEL, math.inf) == LEVEL
    lv = [realization_level(LEVEL, nu) for nu in (2, 5, 19, 99)]
    assert all(a > b for a, b in zip(lv, lv[1:])) and lv[-1] > LEVEL


def _one_point(sig: float, fines: np.ndarray) -> NoiseModel:
    """A NoiseModel of one observation (σ = ``sig`` kPa) with the realizations ``fines`` (k,) as its covariance."""
    lay = CurveLayout(np.zeros(1, int), np.array(["p_inj"]), np.array([0.1]))
    nm = NoiseModel(np.zeros(1), np.full(1, sig), lay)
    nm.set_discretization(np.zeros(1), np.asarray(fines, float)[:, None], 0.0)
    return nm


def test_the_strength_dof_is_welch_satterthwaite_with_the_realizations_known_to_k_minus_one():
    """One observation y = θ + error: V = σ² + (1 + 1/k) s² and ν = (k − 1)(V/((1 + 1/k) s²))² (Welch), k − 1
    when σ → 0, ∞ without realizations (k < 2); the Jacobian's scale does not matter."""
    fines = np.array([0.3, -1.1, 0.9, 0.2])
    k, vr = fines.size, (1 + 1 / fines.size) * np.var(fines, ddof=1)
    mask = np.ones(1, bool)
    for sig in (0.5, 2.0):
        nm = _one_point(sig, fines)
        J = nm.standardize(np.ones(1), mask, 50.0)[:, None] * 3.0
        assert nm.strength_dof(J, 0, mask) == pytest.approx((k - 1) * ((sig**2 + vr) / vr) ** 2, rel=1e-9)
    nm = _one_point(1e-6, fines)
    assert nm.strength_dof(np.ones((1, 1)), 0, mask) == pytest.approx(k - 1, rel=1e-9)
    assert _one_point(0.5, fines[:1]).strength_dof(np.ones((1, 1)), 0, mask) == math.inf
    assert welch_dof(2.0, 1.0, 3) == 12.0 and welch_dof(1.0, 0.0, 3) == math.inf
    nm = _one_point(0.5, fines)                 # the option's ν: ∞, k − 1, Welch
    J = np.ones((1, 1))
    assert nm.threshold_dof("chi2", J, 0, mask) == math.inf and nm.threshold_dof("f_realizations", J, 0, mask) == 3.0
    assert nm.threshold_dof("f_welch", J, 0, mask) == nm.strength_dof(J, 0, mask) > 3.0
    assert _one_point(0.5, fines[:1]).threshold_dof("f_realizations", J, 0, mask) == math.inf


def test_the_f_level_gives_one_more_realizations_prediction_interval_its_exact_coverage():
    """One observation y = θ + d_new − d̄ (σ = 10⁻⁶ kPa beside it), d the realization deviation of sd 1, d̄ the
    mean of k = 3 realizations that also give the covariance: the workflow's NoiseModel whitens y − θ to
    (y − θ)/√((1 + 1/k) s² + σ²) (checked on 20 data sets), so the profile's Δχ² at the truth is F(1, k − 1).
    Over 20000 data sets the F-level interval covers at 0.95 and the χ²-level one at P(|t₂| < 1.96) = 0.811
    (analytic), each within 3 binomial sds (0.0046 and 0.0083)."""
    k, n_sets = 3, 20000
    dev = np.random.default_rng(11).standard_normal((n_sets, k + 1))
    y = 1.0 + dev[:, k] - dev[:, :k].mean(axis=1)
    d2 = (y - 1.0) ** 2 / ((1 + 1 / k) * np.var(dev[:, :k], axis=1, ddof=1) + 1e-12)
    mask = np.ones(1, bool)
    for i in range(20):                                   # the workflow's whitening and ν give this Δχ², k − 1
        nm = _one_point(1e-6, dev[i, :k])
        assert float(nm.standardize(y[i : i + 1] - 1.0, mask, 50.0)[0] ** 2) == pytest.approx(d2[i], rel=1e-9)
        assert nm.strength_dof(np.ones((1, 1)), 0, mask) == pytest.approx(k - 1, rel=1e-6)
    cover_f = np.mean(d2 <= realization_level(LEVEL, k - 1))
    cover_chi2 = np.mean(d2 <= LEVEL)
    want_chi2 = 2 * t.cdf(math.sqrt(LEVEL), k - 1) - 1
    assert abs(cover_f - 0.95) <= 3 * math.sqrt(0.95 * 0.05 / n_sets), cover_f
    assert abs(cover_chi2 - want_chi2) <= 3 * math.sqrt(want_chi2 * (1 - want_chi2) / n_sets), cover_chi2


@pytest.mark.parametrize("kind", ["f_realizations", "f_welch"])
def test_the_profile_threshold_of_a_linear_model_scales_by_the_f_over_chi2_ratio(tmp_path, kind):
    """The linear-Gaussian problem of test_discrepancy_coverage (Δχ² exactly quadratic in the strength) with
    a realization covariance from k = 4 curves: under ``kind`` the threshold is the "chi2" one times
    F(1, ν)/χ²(1), ν = k − 1 = 3 ("f_realizations") or strength_dof (> 3: σ is part of the variance;
    "f_welch"), and the interval the same centre with its half-widths √ of that ratio wider."""
    from dataclasses import replace

    from sweep.discrepancy.profile import profile_interval
    from test_discrepancy_coverage import _linear_problem

    prob, fit, train = _linear_problem(tmp_path, "gaussian")
    n = prob.y.size
    fines = np.random.default_rng(2).normal(0.0, 0.5, (4, n))             # kPa: realizations about zero
    prob.noise.set_discretization(np.zeros(n), fines, 0.0)
    fit = prob.fit(fit.params, [fit.x], train)
    pr = profile_interval(prob, fit, 1, train)
    prob.spec = replace(prob.spec, profile=replace(prob.spec.profile, threshold=kind))
    pf = profile_interval(prob, fit, 1, train)
    nu = 3.0 if kind == "f_realizations" else prob.noise.strength_dof(fit.J, 1, prob.mask(train))
    assert pr["threshold_dof"] is None and pf["threshold_dof"] == nu and nu >= 3.0
    ratio = realization_level(3.841, nu) / 3.841                          # profile_interval's level
    assert pf["threshold"] == pytest.approx(pr["threshold"] * ratio, rel=1e-9)
    centre = fit.params[1].from_x(fit.x[1])
    tol = 2e-3 * (pr["upper"] - pr["lower"])                              # the optimizer's precision
    for side in ("lower", "upper"):
        assert pf[side] - centre == pytest.approx((pr[side] - centre) * math.sqrt(ratio), abs=tol)


def test_an_unknown_threshold_is_refused_in_one_line():
    assert ProfileOptions().threshold == "chi2"
    with pytest.raises(ValueError, match=r"profile\.threshold='t'.*\"chi2\" or \"f_realizations\" or \"f_welch\""):
        parse_options({"profile": {"threshold": "t"}})
    with pytest.raises(ValueError, match=r"kind='F'.*one of"):
        _one_point(0.5, np.array([0.1, 0.2, 0.4])).threshold_dof("F", np.ones((1, 1)), 0, np.ones(1, bool))
    with pytest.raises(ValueError, match=r"level=-1.*> 0"):
        realization_level(-1.0, 6)
    with pytest.raises(ValueError, match=r"nu=0.*> 0"):
        realization_level(LEVEL, 0)

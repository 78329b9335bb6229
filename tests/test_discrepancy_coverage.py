"""The named strength's interval against known answers: the exact interval of a linear-Gaussian model, the
likelihood with an estimated realization-covariance scale in its two limits, and the coverage of the 95 %
interval on toy twins with mesh realizations (sweep.discrepancy.coverage).  Units mm, s, kPa."""
import numpy as np
import pytest

from sweep.discrepancy import load_measured, make_twin, spec_from_dict
from sweep.discrepancy.toy import MeshToy

TIMES = np.linspace(0.02, 0.3, 15)
RATES = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}
OFF = ["damage_viscosity", "volumetric_coupling"]


def _linear_problem(tmp_path, likelihood):
    """p_inj of MeshToy without discretization error or realizations is linear in (η_o, β): the calibrated
    η_o (linear scale) and the strength β, over three training rates, σ = 2 kPa."""
    from sweep.discrepancy.problem import Problem

    fwd = MeshToy(4.0, spread=0.0, bias=0.0)
    hidden = {"beta": 50.0, "volumetric_coupling": 0.0, "eta_o": 0.33}
    data = load_measured(make_twin(tmp_path / "d", fwd, RATES, TIMES, hidden, noise={"p_inj": 2.0}, seed=3,
                                   observables=("p_inj",), regime=False))
    spec = spec_from_dict({"baseline": {"effects_off": OFF},
                           "calibrate": [{"name": "eta_o", "lower": 0.1, "upper": 0.6, "scale": "linear"}],
                           "candidates": {"effects": ["damage_viscosity"]}, "holdout": {"ids": ["d"]},
                           "options": {"h": 4.0, "t_end": 0.3}, "fit": {"loss": "linear", "max_nfev": 50},
                           "profile": {"likelihood": likelihood}})
    prob = Problem(data, spec, fwd)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    train = ["a", "b", "c"]
    return prob, prob.fit(params, [np.array([0.29, 30.0])], train), train


def _exact_interval(prob, train, level=3.841):
    """Least squares by linear algebra: the columns of the linear model from its values at three points."""
    m = prob.mask(train)

    def model(eta, beta):
        return prob.model_vector(prob.predict([{"eta_o": eta, "effect:damage_viscosity": beta}], train)[0], m)

    a = model(0.2, 0.0)
    X = np.column_stack([(model(0.4, 0.0) - a) / 0.2, model(0.2, 1.0) - a])
    m0 = a - 0.2 * X[:, 0]                      # the model at η_o = β = 0 (outside η_o's range, extrapolated)
    X = X / prob.sig[m][:, None]
    y = (prob.y[m] - m0) / prob.sig[m]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    chi2 = float(np.sum((y - X @ coef) ** 2))
    thr = level * max(1.0, chi2 / (y.size - 2))
    half = np.sqrt(thr * np.linalg.inv(X.T @ X)[1, 1])
    return coef[1] - half, coef[1] + half, thr


def test_gaussian_profile_is_the_exact_interval_of_a_linear_gaussian_model(tmp_path):
    """With the calibrated parameter profiled out, Δχ² of a linear model is exactly (β − β̂)²/Var(β̂): the
    interval is β̂ ± √(thr Var(β̂)), Var from (XᵀX)⁻¹ with the correlation of β and η_o in it."""
    from sweep.discrepancy.profile import profile_interval

    prob, fit, train = _linear_problem(tmp_path, "gaussian")
    lo, hi, thr = _exact_interval(prob, train)
    pr = profile_interval(prob, fit, 1, train)
    tol = 2e-3 * (hi - lo) / 2           # the optimizer's precision (least_squares tolerances 1e-8)
    assert pr["threshold"] == pytest.approx(thr, rel=1e-6)
    assert pr["lower"] == pytest.approx(lo, abs=tol) and pr["upper"] == pytest.approx(hi, abs=tol)
    # the same model under the lag-1 series weights gives another interval (its Δχ² is Σ w r², w <= 1)
    prw, fitw, _ = _linear_problem(tmp_path / "w", "weighted")
    w = profile_interval(prw, fitw, 1, train)
    assert w["lower"] <= pr["lower"] + tol and w["upper"] >= pr["upper"] - tol


def _noise_with_block(n, alpha, k):
    """A NoiseModel of one series of ``n`` points, σ = 1, whose realization covariance is α I from ``k``
    realizations (no correlation in time)."""
    from sweep.discrepancy.layout import CurveLayout
    from sweep.discrepancy.noise import NoiseModel
    from sweep.discrepancy.realizations import RealizationCovariance

    lay = CurveLayout(np.zeros(n, int), np.array(["p_inj"] * n), np.linspace(0.02, 0.3, n))
    nm = NoiseModel(np.zeros(n), np.ones(n), lay)
    rows = np.arange(n)
    nm.real_cov = RealizationCovariance({0: (rows, alpha * np.eye(n))}, {"p_inj": 0.0}, {"p_inj": 0.0}, k, lay)
    nm._attach()
    return nm, nm.real_cov.scale_dof(rows)


def test_marginal_likelihood_is_gaussian_for_many_realizations_and_student_t_for_few():
    """Known answers of the likelihood with the realization scale integrated over λ ~ ν/χ²_ν: for ν → ∞ the
    Gaussian (differences of −2 ln p equal differences of r·r); when the realization term dominates the
    measured noise (α → ∞) the multivariate Student t, −2 ln p = (ν + n) ln(1 + |r|²/ν) + const."""
    n = 15
    mask = np.ones(n, bool)
    rng = np.random.default_rng(0)
    r1, r2 = rng.normal(size=n), 2.0 * rng.normal(size=n)
    nm, nu = _noise_with_block(n, 1.0, 100_000)
    d_gauss = nm.marginal_deviance(r2, mask) - nm.marginal_deviance(r1, mask)
    assert d_gauss == pytest.approx(r2 @ r2 - r1 @ r1, rel=1e-4)          # λ within ~√(2/ν) ≈ 0.1 % of 1
    nm, nu = _noise_with_block(n, 1e6, 3)
    assert 2.0 <= nu <= 2.0 * n                                            # k − 1 to (k − 1) n (scale_dof)

    def t_dev(r):
        return (nu + n) * np.log1p(r @ r / nu)

    d_t = nm.marginal_deviance(r2, mask) - nm.marginal_deviance(r1, mask)
    # 32 equal-probability nodes of λ: against 4000 nodes the quadrature's error is 3e-4 here
    assert d_t == pytest.approx(t_dev(r2) - t_dev(r1), rel=2e-3)
    assert d_t < r2 @ r2 - r1 @ r1                                          # heavier tails than the Gaussian


def test_interval_covers_the_truth_on_toy_twins_outside_the_twinned_set_up():
    """kbar calibrated, cement as the condition axis, hidden β of random strength, three check realizations
    whose deviations wander with the exponential correlation the covariance model assumes
    (sweep.discrepancy.coverage, variant wander_remedy_marginal), with the likelihood's settings:
    [noise] disc_error_fraction = 0 (the correction's uncertainty is its k-realization covariance) and
    [profile] likelihood = "marginal" (that covariance's scale estimated from three realizations).

    40 twins: if the interval is a 95 % interval, the number covered is Binomial(40, 0.95) (mean 38, sd 1.4),
    fewer than 34 with probability 0.3 %.  The likelihood-ratio statistic at the truth is χ²₁: below its median
    0.455 in Binomial(40, 0.5) twins (sd 3.2), outside 10..30 with probability 0.07 %: an interval too wide
    (the statistic piling up near 0) fails here before its coverage shows it."""
    from sweep.discrepancy.coverage import SETUPS, VARIANTS, one_draw

    su = {s.name: s for s in SETUPS}["kbar_cement_beta"]
    rows = [one_draw(su, d, VARIANTS["wander_remedy_marginal"], seed=5) for d in range(40)]
    named = [r for r in rows if r["named"] and "covered" in r]
    assert len(named) >= 36
    assert sum(r["covered"] for r in named) >= 34 * len(named) / 40
    below = sum(r["dchi2_truth"] < 0.455 for r in named)
    assert 10 * len(named) / 40 <= below <= 30 * len(named) / 40


def test_wilson_interval_known_values():
    from sweep.discrepancy.coverage import wilson

    lo, hi = wilson(95, 100)                       # the textbook Wilson score interval of 95/100
    assert lo == pytest.approx(0.8883, abs=1e-4) and hi == pytest.approx(0.9785, abs=1e-4)
    assert wilson(0, 20)[0] == pytest.approx(0.0, abs=1e-12) and wilson(20, 20)[1] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("kw,msg", [({"h": 0.0}, "h=0.0"), ({"spread": -1.0}, "spread=-1.0"),
                                    ({"realization": -2}, "realization=-2"), ({"shape": "jagged"}, "shape='jagged'")])
def test_mesh_toy_refuses_bad_settings(kw, msg):
    with pytest.raises(ValueError, match=msg):
        MeshToy(**kw)


def test_spec_refuses_an_unknown_profile_likelihood():
    with pytest.raises(ValueError, match=r"profile.likelihood='exact' is not allowed: \"weighted\" or \"gaussian\""):
        spec_from_dict({"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
                        "candidates": {"effects": OFF}, "holdout": {"ids": ["d"]}, "options": {"h": 4.0},
                        "profile": {"likelihood": "exact"}})


def test_wander_deviation_is_a_unit_process_with_exponential_correlation():
    """The "wander" realizations' paths: unit variance and correlation exp(−Δt/τ) (τ = 0.1 s).  From 2000
    paths the sample correlation has sd ≈ (1 − ρ²)/√2000 ≈ 0.02 and the variance ≈ √(2/2000) ≈ 0.03."""
    from sweep.discrepancy.toy import _ou

    rng = np.random.default_rng(4)
    t = np.array([0.1, 0.15, 0.2, 0.3])
    x = np.array([_ou(rng, t, 0.1) for _ in range(2000)])
    assert x.var(axis=0) == pytest.approx(np.ones(4), abs=0.12)
    c = np.corrcoef(x.T)
    for (i, j) in ((0, 1), (0, 2), (0, 3)):
        assert c[i, j] == pytest.approx(np.exp(-(t[j] - t[i]) / 0.1), abs=0.08)

"""Dimensionless numbers (Eqs. modified_capillary_number, viscous_pressure_drop, Nb, Nf)."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from sweep.regimes.numbers import (
    branching_number,
    capillary_number,
    dimensionless_numbers,
    estimate_dp_cri,
    fracturing_number,
    k0_mean,
    k0_uniform_expectation,
    kozeny_carman,
    logistic_fit,
    modified_capillary_number,
    viscous_pressure_drop,
)

REF = dict(eta_o=0.29, eta_w=1e-6, kbar=0.0015, w_i=50.0, gamma=0.03, r_inner=5.0,
           r_outer=53.0, bead_diameter=2.0, phi_mean=0.4, phi_range=0.2)


def kc(phi):
    return phi**3 / (1 - phi) ** 2


def test_k0_uniform_expectation_closed_form():
    # independent: numerical quadrature of phi^3/(1-phi)^2 over [0.2, 0.6]
    ref = quad(kc, 0.2, 0.6, epsabs=1e-14)[0] / 0.4
    assert k0_uniform_expectation(1.0) == pytest.approx(ref, rel=1e-12)
    # hand value: (F(0.6) - F(0.2)) / 0.4, F = 1/u + 3 ln u - 3u + u^2/2, u = 1 - phi
    F = lambda u: 1 / u + 3 * math.log(u) - 3 * u + u * u / 2  # noqa: E731
    assert k0_uniform_expectation(0.0015) == pytest.approx(0.0015 * (F(0.4) - F(0.8)) / 0.4, rel=1e-12)
    assert k0_uniform_expectation(1.0) == pytest.approx(0.326396, abs=1e-6)
    for lo, hi in ((0.1, 0.3), (0.35, 0.45), (0.5, 0.9)):
        assert k0_uniform_expectation(2.0, lo, hi) == pytest.approx(2 * quad(kc, lo, hi)[0] / (hi - lo), rel=1e-10)
    # degenerate range: k(phi)
    assert k0_uniform_expectation(1.0, 0.4, 0.4) == pytest.approx(0.064 / 0.36, rel=1e-12)


def test_k0_mean_of_random_field():
    """Area-weighted mean over a random field converges to the expectation (4 standard errors)."""
    rng = np.random.default_rng(0)
    M = 20000
    phi0 = rng.uniform(0.2, 0.6, M)
    areas = rng.uniform(0.3, 0.6, M)
    mean = quad(kc, 0.2, 0.6)[0] / 0.4
    var = quad(lambda p: (kc(p) - mean) ** 2, 0.2, 0.6)[0] / 0.4
    n_eff = areas.sum() ** 2 / (areas**2).sum()
    assert abs(k0_mean(1.0, phi0, areas) - mean) < 4 * math.sqrt(var / n_eff)
    # exact on a two-element example: weights 1 and 3
    assert k0_mean(2.0, [0.2, 0.5], [1.0, 3.0]) == pytest.approx(2 * (kc(0.2) + 3 * kc(0.5)) / 4, rel=1e-14)
    assert k0_mean(1.0, [0.5], k_max=0.1) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="areas shape"):
        k0_mean(1.0, [0.2, 0.3], [1.0])
    with pytest.raises(ValueError, match="phi0"):
        k0_mean(1.0, [0.2, 1.3])


def test_primitive_numbers_reference_run():
    k0 = 0.326396 * 0.0015
    ca = 0.29 * 50.0 / 0.03
    assert capillary_number(0.29, 50.0, 0.03) == pytest.approx(483.3333333, rel=1e-9)
    assert modified_capillary_number(0.29, 50.0, 0.03, k0) == pytest.approx(ca * 53.0 * 2.0 / k0, rel=1e-12)
    assert viscous_pressure_drop(0.29, 50.0, k0) == pytest.approx(0.29 * 50 * 53 / k0, rel=1e-12)
    assert viscous_pressure_drop(0.29, 50.0, k0, l0=5.0) == pytest.approx(0.29 * 50 * 5 / k0, rel=1e-12)
    assert branching_number(1e-6, 0.29, k0) == pytest.approx(1e-6 * 25 / (0.29 * k0), rel=1e-12)
    assert fracturing_number(300.0, 150.0) == 2.0
    assert kozeny_carman(0.4, 1.0) == pytest.approx(0.064 / 0.36)
    assert kozeny_carman(0.9, 1.0, k_max=0.31) == 0.31
    # broadcasting
    nb = branching_number(np.array([1e-6, 1e-3]), 1.0, 1e-3)
    assert np.allclose(nb, [1e-6 * 25 / 1e-3, 25.0])
    # paper's field estimate (Sec. 3.8): water/oil, k = 1e-9 mm^2, l0 = 100 mm -> N_b ~ 1e10
    assert 1e9 < branching_number(1e-6, 1e-3, 1e-9, l0=100.0) < 1e11


def test_dimensionless_numbers():
    d = dimensionless_numbers(REF, dp_cri=1e6)
    k0 = 0.0015 * quad(kc, 0.2, 0.6)[0] / 0.4
    assert d["k0"] == pytest.approx(k0, rel=1e-10)
    assert d["Ca"] == pytest.approx(0.29 * 50 / 0.03)
    assert d["Ca_star"] == pytest.approx(d["Ca"] * 53 * 2 / k0, rel=1e-10)
    assert d["dp_vis"] == pytest.approx(0.29 * 50 * 53 / k0, rel=1e-10)
    assert d["N_b"] == pytest.approx(1e-6 * 25 / (0.29 * k0), rel=1e-10)
    assert d["N_f"] == pytest.approx(d["dp_vis"] / 1e6, rel=1e-12)
    assert d["M"] == pytest.approx(0.29 / 1e-6)
    assert d["N_b"] == pytest.approx(1 / (d["M"] * d["Da"]), rel=1e-12)  # N_b = M^-1 Da^-1
    # (lo, hi) pair == half-width; object with attributes == mapping; explicit k0 wins
    assert dimensionless_numbers({**REF, "phi_range": (0.2, 0.6)})["k0"] == pytest.approx(k0, rel=1e-12)

    class P:
        pass

    obj = P()
    obj.__dict__.update(REF)
    assert dimensionless_numbers(obj)["N_b"] == pytest.approx(d["N_b"], rel=1e-12)
    assert dimensionless_numbers({**REF, "k0": 1e-3})["k0"] == 1e-3
    assert math.isnan(dimensionless_numbers(REF)["N_f"])
    # no range: k(phi_mean)
    assert dimensionless_numbers({**REF, "phi_range": 0.0})["k0"] == pytest.approx(0.0015 * 0.064 / 0.36)
    assert dimensionless_numbers({**REF, "porosity_field": "constant"})["k0"] == pytest.approx(0.0015 * 0.064 / 0.36)
    # l0 of dp_vis is an argument
    assert dimensionless_numbers(REF, l0_vis=5.0)["dp_vis"] == pytest.approx(d["dp_vis"] * 5 / 53)


def test_dimensionless_numbers_from_solver_parameters():
    params = pytest.importorskip("solver.params", reason="solver.params not importable yet")
    d = dimensionless_numbers(params.Parameters())
    assert d["k0"] == pytest.approx(0.0015 * 0.326396, rel=1e-5)  # phi 0.4 +- 0.2
    assert d["N_b"] == pytest.approx(dimensionless_numbers(REF)["N_b"], rel=1e-12)


def test_bad_input():
    with pytest.raises(ValueError, match="eta_o"):
        capillary_number(-1.0, 50.0, 0.03)
    with pytest.raises(ValueError, match="k0"):
        viscous_pressure_drop(0.29, 50.0, 0.0)
    with pytest.raises(ValueError, match="missing 'eta_w'"):
        dimensionless_numbers({k: v for k, v in REF.items() if k != "eta_w"})
    with pytest.raises(ValueError, match="phi_range"):
        dimensionless_numbers({**REF, "phi_range": 0.5})
    with pytest.raises(ValueError, match="r_outer"):
        dimensionless_numbers({**REF, "r_outer": 4.0})
    with pytest.raises(ValueError, match="phi_hi"):
        k0_uniform_expectation(1.0, 0.5, 0.3)
    with pytest.raises(ValueError, match="both classes"):
        logistic_fit(np.arange(5.0), np.ones(5, bool))


def test_estimate_dp_cri_noisy():
    """Labels drawn from P = 1/(1 + exp(-3 ln(dp/300))): estimate within 3 sigma, sigma small."""
    rng = np.random.default_rng(2)
    dp = np.exp(rng.uniform(np.log(10.0), np.log(1e4), 400))
    fr = rng.random(400) < 1 / (1 + np.exp(-3.0 * np.log(dp / 300.0)))
    e = estimate_dp_cri(dp, fr)
    sigma = (math.log(e.interval[1]) - math.log(e.interval[0])) / (2 * 1.96)
    assert abs(math.log(e.dp_cri / 300.0)) <= 3 * sigma
    assert sigma < 0.15
    assert e.slope == pytest.approx(3.0, rel=0.3)
    assert not e.separable


def test_estimate_dp_cri_separable():
    dp = np.logspace(1, 4, 61)
    fr = dp > 300.0
    e = estimate_dp_cri(dp, fr)
    assert e.separable
    assert e.bracket[0] < 300.0 < e.bracket[1]
    assert e.bracket[0] <= e.dp_cri <= e.bracket[1]
    with pytest.raises(ValueError, match="slope"):
        estimate_dp_cri(dp, dp < 300.0)

"""Verification of the point-wise constitutive laws (solver/physics.py) against closed forms.

Finite-difference tolerances: a central difference of step δ on a smooth
function has truncation error ~ f''' δ²/6 and round-off ~ eps |f| / δ; with
δ = 1e-6 (on O(1) arguments) both are ~1e-10 relative, so 1e-7 is safe.
Dual-number derivatives are exact to round-off.
"""
import numpy as np
import pytest

from solver import Parameters, physics
from solver.ad import Dual

P = Parameters()
LAM, MU = P.lame_lambda, P.lame_mu


# ---------------------------------------------------------------- degradation
@pytest.mark.parametrize("m", [1.0, 3.7, P.m])
def test_degradation_end_values_and_initial_slope(m):
    assert physics.degradation(0.0, m) == 1.0
    assert physics.degradation(1.0, m) == 0.0
    assert physics.degradation_prime(0.0, m) == pytest.approx(-m, rel=1e-15)
    assert physics.degradation_prime(1.0, m) == 0.0  # no driving force at full damage
    d = np.linspace(0, 1, 201)
    g = physics.degradation(d, m)
    assert np.all(np.diff(g) < 0) and np.all((g >= 0) & (g <= 1))


@pytest.mark.parametrize("m", [1.0, 3.7, P.m])
def test_degradation_derivatives_match_finite_differences(m):
    d = np.linspace(0.01, 0.99, 99)
    dl = 1e-6
    fd1 = (physics.degradation(d + dl, m) - physics.degradation(d - dl, m)) / (2 * dl)
    fd2 = (physics.degradation_prime(d + dl, m) - physics.degradation_prime(d - dl, m)) / (2 * dl)
    g1 = physics.degradation_prime(d, m)
    g2 = physics.degradation_second(d, m)
    assert np.max(np.abs(fd1 - g1)) < 1e-7 * max(1.0, np.abs(g1).max())
    assert np.max(np.abs(fd2 - g2)) < 1e-7 * max(1.0, np.abs(g2).max())
    # Dual numbers give g' exactly too
    (x,) = Dual.variables(d[:, None])
    gd = physics.degradation(x, m)
    np.testing.assert_allclose(gd.d[:, 0], g1, rtol=1e-12, atol=1e-14)


# ---------------------------------------------------------------- spectral split
def _strains(rng, n=200):
    e = 1e-2 * rng.standard_normal((n, 3))
    # add special cases: pure compression, pure tension, equal principal strains (both signs), zero
    special = np.array([
        [-1e-2, -2e-2, 3e-3],  # both principal strains negative
        [2e-2, 1e-2, -4e-3],  # both positive
        [5e-3, 5e-3, 0.0],  # equal principal strains, tension
        [-5e-3, -5e-3, 0.0],  # equal principal strains, compression
        [0.0, 0.0, 0.0],
        [1e-2, -1e-2, 0.0],  # pure shear, volumetric part zero
    ])
    return np.concatenate([e, special])


def test_split_sums_to_linear_elasticity():
    e = _strains(np.random.default_rng(0))
    (ax, ay, axy), (sx, sy, sxy), psi_a = physics.spectral_split(e[:, 0], e[:, 1], e[:, 2], LAM, MU)
    ev = e[:, 0] + e[:, 1]
    # C:ε in plane strain
    np.testing.assert_allclose(sx, LAM * ev + 2 * MU * e[:, 0], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(sy, LAM * ev + 2 * MU * e[:, 1], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(sxy, 2 * MU * e[:, 2], rtol=1e-14, atol=1e-14)
    # ψ_A + ψ_I = ψ = λ/2 ε_v² + μ ε:ε with ψ_I from the principal strains (Eq. spectral_decomposition)
    r = np.hypot(0.5 * (e[:, 0] - e[:, 1]), e[:, 2])
    e1, e2 = 0.5 * ev + r, 0.5 * ev - r
    neg = lambda x: np.minimum(x, 0.0)
    psi_i = 0.5 * LAM * neg(ev) ** 2 + MU * (neg(e1) ** 2 + neg(e2) ** 2)
    psi = 0.5 * LAM * ev**2 + MU * (e[:, 0] ** 2 + e[:, 1] ** 2 + 2 * e[:, 2] ** 2)
    np.testing.assert_allclose(psi_a + psi_i, psi, rtol=1e-12, atol=1e-16)
    assert np.all(psi_a >= 0)


def test_active_part_vanishes_under_compression():
    e = np.array([[-1e-2, -2e-2, 3e-3], [-5e-3, -5e-3, 0.0], [-1e-3, -4e-3, -1e-3]])
    (ax, ay, axy), _, psi_a = physics.spectral_split(e[:, 0], e[:, 1], e[:, 2], LAM, MU)
    for a in (ax, ay, axy, psi_a):
        np.testing.assert_array_equal(a, 0.0)
    # pure tension: everything is active
    e = np.array([[2e-2, 1e-2, -4e-3], [5e-3, 5e-3, 0.0]])
    (ax, ay, axy), (sx, sy, sxy), _ = physics.spectral_split(e[:, 0], e[:, 1], e[:, 2], LAM, MU)
    np.testing.assert_allclose(np.stack([ax, ay, axy]), np.stack([sx, sy, sxy]), rtol=1e-13)


def test_active_stress_is_derivative_of_active_energy():
    """σ_A = ∂ψ_A/∂ε: by Dual numbers and by central differences (shear: ∂ψ/∂ε_xy = 2σ_xy)."""
    e = _strains(np.random.default_rng(1))
    sa, _, psi = physics.spectral_split(e[:, 0], e[:, 1], e[:, 2], LAM, MU)
    X = Dual.variables(e)
    _, _, psi_d = physics.spectral_split(*X, LAM, MU)
    np.testing.assert_allclose(psi_d.v, psi, rtol=1e-14)
    scale = LAM * 1e-2 + 2 * MU * 1e-2  # stress scale of 1e-2 strains
    np.testing.assert_allclose(psi_d.d[:, 0], sa[0], atol=1e-12 * scale)
    np.testing.assert_allclose(psi_d.d[:, 1], sa[1], atol=1e-12 * scale)
    np.testing.assert_allclose(0.5 * psi_d.d[:, 2], sa[2], atol=1e-12 * scale)
    # central differences.  Where ψ_A is smooth, step δ = 1e-7 on 1e-2 strains gives an error
    # ~ ψ''' δ² + eps ψ/δ ~ 1e-9 of the stress scale.  At the kinks of <·> (ε_v = 0 or a principal
    # strain = 0: the pure-shear and zero-strain samples) ψ_A is only C¹ and the central difference
    # error is bounded by δ times the jump of ψ'' instead, <= 2 (λ + 2μ) δ.
    dl = 1e-7
    kink_tol = 2 * (LAM + 2 * MU) * dl
    for k in range(3):
        ep, em = e.copy(), e.copy()
        ep[:, k] += dl
        em[:, k] -= dl
        fd = (physics.spectral_split(*ep.T, LAM, MU)[2] - physics.spectral_split(*em.T, LAM, MU)[2]) / (2 * dl)
        target = sa[k] * (2.0 if k == 2 else 1.0)
        assert np.max(np.abs(fd - target)) < kink_tol + 1e-9 * scale, k
        smooth = np.abs(e[:, 0] + e[:, 1]) > 1e-4  # away from the ε_v kink (and from zero strain)
        assert np.max(np.abs(fd - target)[smooth]) < 1e-7 * scale, k


def test_split_at_equal_principal_strains_is_smooth():
    """At ε_xx = ε_yy, ε_xy = 0 the split must be finite and equal its limit from nearby strains."""
    for m in (4e-3, -4e-3):
        exact = physics.spectral_split(np.array([m]), np.array([m]), np.array([0.0]), LAM, MU)
        near = physics.spectral_split(np.array([m + 1e-9]), np.array([m - 1e-9]), np.array([1e-9]), LAM, MU)
        for a, b in zip(exact[0], near[0]):
            assert np.isfinite(a).all()
            assert abs(a[0] - b[0]) < 1e-6 * (LAM + 2 * MU) * abs(m)
        assert exact[2][0] == pytest.approx(near[2][0], rel=1e-6, abs=1e-18)
        # closed form: equibiaxial tension is fully active, compression fully inactive
        if m > 0:
            assert exact[0][0][0] == pytest.approx((2 * LAM + 2 * MU) * m, rel=1e-14)
            assert exact[2][0] == pytest.approx(0.5 * LAM * (2 * m) ** 2 + 2 * MU * m * m, rel=1e-14)
        else:
            assert exact[0][0][0] == 0.0 and exact[2][0] == 0.0
    # Dual derivative at the exactly equal strains: the tangent of ψ_A
    X = Dual.variables(np.array([[4e-3, 4e-3, 0.0]]))
    _, _, psi = physics.spectral_split(*X, LAM, MU)
    np.testing.assert_allclose(psi.d[0], [(2 * LAM + 2 * MU) * 4e-3] * 2 + [0.0], rtol=1e-13)


# ---------------------------------------------------------------- permeability
def test_kozeny_carman_values_cap_and_continuity():
    kbar, kmax = P.kbar, P.k_max
    phi = np.array([0.2, 0.4, 0.6])
    np.testing.assert_allclose(physics.kozeny_carman(phi, kbar, kmax), phi**3 / (1 - phi) ** 2 * kbar, rtol=1e-14)
    ps = physics.cap_porosity(kbar, kmax)
    assert 0 < ps < 1
    assert ps**3 / (1 - ps) ** 2 * kbar == pytest.approx(kmax, rel=1e-12)
    # continuity at φ*: the law's slope is finite there, so k(φ* − δ) = k_max − O(δ)
    below = physics.kozeny_carman(np.array([ps - 1e-9]), kbar, kmax)[0]
    above = physics.kozeny_carman(np.array([ps + 1e-9]), kbar, kmax)[0]
    slope = (3 * ps**2 / (1 - ps) ** 2 + 2 * ps**3 / (1 - ps) ** 3) * kbar
    assert abs(below - kmax) < 2e-9 * slope and above == kmax
    big = np.array([ps, 0.999, 1.0, 1.5, 3.0])
    np.testing.assert_array_equal(physics.kozeny_carman(big, kbar, kmax), kmax)
    # monotone non-decreasing over the whole range, and its Dual derivative vanishes on the cap
    grid = np.linspace(0.01, 2.0, 4001)
    assert np.all(np.diff(physics.kozeny_carman(grid, kbar, kmax)) >= 0)
    (x,) = Dual.variables(np.array([[0.4], [1.2]]))
    k = physics.kozeny_carman(x, kbar, kmax)
    assert k.d[0, 0] == pytest.approx((3 * 0.4**2 / 0.36 + 2 * 0.4**3 / 0.216) * kbar, rel=1e-12)
    assert k.d[1, 0] == 0.0


def test_permeability_blend():
    phi0 = np.array([0.3, 0.3])
    phi = np.array([0.5, 1.2])
    k0 = physics.kozeny_carman(phi0, P.kbar, P.k_max)
    k = physics.kozeny_carman(phi, P.kbar, P.k_max)
    np.testing.assert_array_equal(physics.permeability(phi, phi0, P.kbar, P.k_max, 1.0), k)
    np.testing.assert_allclose(physics.permeability(phi, phi0, P.kbar, P.k_max, 0.0), k0, rtol=1e-15)
    np.testing.assert_allclose(physics.permeability(phi, phi0, P.kbar, P.k_max, 0.25), k0 + 0.25 * (k - k0), rtol=1e-15)


@pytest.mark.parametrize("M", [1.0, 0.5, P.viscosity_ratio])
def test_relative_permeabilities(M):
    kr1, kr2 = physics.relative_permeabilities(np.array([0.0, 1.0]), M)
    assert kr1[0] == 0.0 and kr1[1] == 1.0  # k_r1(S1=0) = 0, k_r1(S1=1) = 1
    assert kr2[0] == 1.0 and kr2[1] == 0.0  # k_r2(S2=1) = 1, k_r2(S2=0) = 0
    S = np.linspace(0, 1, 1001)
    kr1, kr2 = physics.relative_permeabilities(S, M)
    # closed forms (Fourar–Lenormand)
    np.testing.assert_allclose(kr1, S**3 + 1.5 / M * S * (1 - S) * (1 + S), rtol=1e-14)
    np.testing.assert_allclose(kr2, 0.5 * (1 - S) ** 2 * (2 + S), rtol=1e-14, atol=1e-16)
    if M >= 1.0:  # k_r1 is monotone for M >= 3/4 (its derivative 3S²(1 − 1/(2M)) + 3/(2M) > 0)
        assert np.all(np.diff(kr1) > 0)
    assert np.all(np.diff(kr2) < 0)
    # clipped outside [0, 1]: overshoots of the phase field give the bound values, never negative mobility
    kr1o, kr2o = physics.relative_permeabilities(np.array([-0.05, 1.05]), M)
    np.testing.assert_array_equal(kr1o, [0.0, 1.0])
    np.testing.assert_array_equal(kr2o, [1.0, 0.0])


# ---------------------------------------------------------------- porosity, double well
@pytest.mark.parametrize("M", [5.0, 2.9e5])
def test_invading_permeability_slope_is_the_derivative_of_k_r1(M):
    """The SUPG transport speed's factor: dk_r1/dS on (0, 1) (central differences, O(ε²) = 1e-12), its value
    at the bound outside [0, 1], and the same values and derivative through Duals."""
    S = np.linspace(0.01, 0.99, 50)
    eps = 1e-6
    fd = (physics.relative_permeabilities(S + eps, M)[0] - physics.relative_permeabilities(S - eps, M)[0]) / (2 * eps)
    assert np.allclose(physics.invading_permeability_slope(S, M), fd, rtol=0, atol=1e-8)
    out = physics.invading_permeability_slope(np.array([-0.2, 0.0, 1.0, 1.3]), M)
    assert np.allclose(out, [1.5 / M, 1.5 / M, 3.0 - 3.0 / M, 3.0 - 3.0 / M], rtol=1e-14)
    d = physics.invading_permeability_slope(Dual.variables([S])[0], M)
    assert np.allclose(d.v, physics.invading_permeability_slope(S, M), rtol=1e-14)
    assert np.allclose(d.dd[..., 0], 6.0 * S * (1.0 - 1.5 / M), rtol=1e-12)


def test_porosity_law():
    phi0, ev, p, Ks = 0.4, 0.01, 50.0, 1600.0
    assert physics.porosity(phi0, ev, p, Ks) == pytest.approx(0.4 + 0.6 * 0.01 + 0.6 * 50 / 1600, rel=1e-15)
    assert physics.porosity(phi0, 0.0, 0.0, Ks) == phi0
    # a fully opened element (ε_v = 1, p = 0) reaches φ = 1: the permeability cap applies there
    assert physics.porosity(np.array([0.2, 0.6]), 1.0, 0.0, Ks) == pytest.approx(1.0)
    # linear in (ε_v, p): Dual derivatives are the coefficients (1 − φ0) and (1 − φ0)/K_s
    X = Dual.variables(np.array([[0.01, 50.0]]))
    phi = physics.porosity(0.4, X[0], X[1], Ks)
    np.testing.assert_allclose(phi.d[0], [0.6, 0.6 / Ks], rtol=1e-15)


def test_double_well():
    S = np.linspace(-0.2, 1.2, 141)
    np.testing.assert_allclose(physics.double_well(S), S**2 * (1 - S) ** 2, rtol=1e-14, atol=1e-18)
    dl = 1e-6
    fd = (physics.double_well(S + dl) - physics.double_well(S - dl)) / (2 * dl)
    assert np.max(np.abs(fd - physics.double_well_prime(S))) < 1e-9
    assert physics.double_well_prime(0.0) == 0.0 and physics.double_well_prime(1.0) == 0.0
    assert physics.double_well_prime(0.5) == 0.0


def test_cohesive_strength_1d():
    # σ_c = sqrt(2 E ψ_c): the stress at which ½ σ²/E = ψ_c
    E, psic = 367.8, 0.00216
    s = physics.cohesive_strength_1d(E, psic)
    assert 0.5 * s * s / E == pytest.approx(psic, rel=1e-14)


def test_permeability_is_zero_for_closed_pores_and_continuous_at_zero():
    """Linear poroelasticity can push φ below 0 under strong compression: k must be 0 there, not negative."""
    from solver import physics

    kbar, kmax = 0.0015, 1.96**2 / 12
    phi = np.array([-0.1, -1e-12, 0.0, 1e-4])
    k = physics.kozeny_carman(phi, kbar, kmax)
    assert np.all(k[:3] == 0.0)
    assert 0.0 < k[3] < 1e-11  # φ³ kbar / (1 − φ)² ~ 1.5e-15 mm²


def test_sparse_duals_carry_only_the_inputs_they_depend_on_and_match_finite_differences():
    """Duals store derivatives on the slots they depend on; unions, where() and constants stay exact."""
    from solver import ad

    rng = np.random.default_rng(3)
    vals = rng.uniform(0.5, 2.0, size=(4, 5, 6))
    X = Dual.variables(vals)

    def f(X):
        a = X[0] * X[1] + X[4] / X[2]          # slots {0, 1, 2, 4}
        b = ad.where(X[3].v > 1.0, X[3] ** 3, 2.0 - X[5])  # slots {3, 5}
        c = ad.sqrt(a) - 1.0 / b + 3.0 * X[1]
        return ad.positive_part(c - 1.5) + ad.clip(X[0], 0.7, 1.8) * b

    y = f(X)
    assert set(X[0].idx) == {0} and (X[0] * X[1]).idx == (0, 1)
    assert y.idx == (0, 1, 2, 3, 4, 5) and ad.as_dual_like(1.0, X[0]).idx == ()
    eps = 1e-6
    for k in range(6):
        vp, vm = vals.copy(), vals.copy()
        vp[..., k] += eps
        vm[..., k] -= eps
        yp = f(Dual.variables(vp)).v
        ym = f(Dual.variables(vm)).v
        np.testing.assert_allclose(y.d[..., k], (yp - ym) / (2 * eps), rtol=1e-6, atol=1e-8)
    # a quantity that does not depend on an input has an exactly zero dense derivative there
    z = X[2] * X[2]
    assert np.all(z.d[..., [0, 1, 3, 4, 5]] == 0.0) and np.allclose(z.d[..., 2], 2 * vals[..., 2])

"""Verification of the critical saturation of the invading water (parameter ``critical_saturation``, effect
"critical_saturation" of solver/effects.py; law in solver.physics.relative_permeabilities).

1. The law: S_c = 0 is the paper's Fourar–Lenormand law exactly; with S_c > 0 the water is immobile up to S_c,
   k_r1 is the paper's law of (S − S_c)/(1 − S_c) above it (so k_r1(1) = 1), k_r2 is unchanged, and the SUPG
   transport factor is dk_r1/dS (central differences).
2. Buckley–Leverett on the strip of tests/test_outlet.py with S_c = 0.2: the water that has left follows Welge's
   answer for the fractional flow with S_c within the scheme's smearing, and breaks through later than with the
   paper's law (the shock saturation rises above S_c).
3. The Jacobian stays exact with S_c > 0 in the Darcy mobilities and the outlet's fractional flow (Taylor test:
   the remainder falls as ε² on the S and p rows).
Units mm, s, kPa.
"""
import math

import numpy as np
import pytest

from solver import Parameters, RunOptions, physics, simulate
from solver.ad import Dual
from solver.effects import EFFECTS, is_off
from test_outlet import BL, DT, H, PHI, ROWS, _f_prime, _strip, _welge_outflow, taylor_remainders, taylor_state

M_EXP = Parameters().viscosity_ratio  # 2.9e5


@pytest.mark.parametrize("M", [5.0, M_EXP])
def test_zero_critical_saturation_is_the_papers_law(M):
    S = np.linspace(-0.05, 1.05, 111)
    for a, b in zip(physics.relative_permeabilities(S, M, 0.0), physics.relative_permeabilities(S, M)):
        np.testing.assert_array_equal(a, b)
    Sc = np.clip(S, 0, 1)
    np.testing.assert_array_equal(physics.relative_permeabilities(S, M, 0.0)[0],
                                  Sc**3 + (1.5 / M) * Sc * (1 - Sc) * (1 + Sc))


@pytest.mark.parametrize("M", [5.0, M_EXP])
@pytest.mark.parametrize("S_c", [0.1, 0.3])
def test_the_water_is_immobile_below_the_critical_saturation(M, S_c):
    S = np.linspace(0.0, 1.0, 1001)
    kr1, kr2 = physics.relative_permeabilities(S, M, S_c)
    assert np.all(kr1[S <= S_c] == 0.0) and kr1[-1] == 1.0
    Se = (S - S_c) / (1 - S_c)
    up = S > S_c
    np.testing.assert_allclose(kr1[up], Se[up]**3 + 1.5 / M * Se[up] * (1 - Se[up]) * (1 + Se[up]), rtol=1e-13)
    np.testing.assert_array_equal(kr2, physics.relative_permeabilities(S, M)[1])   # the oil's law unchanged
    f = physics.fractional_flow(S, M, S_c)
    assert np.all(f[S <= S_c] == 0.0) and f[-1] == 1.0 and np.all(np.diff(f) >= 0.0)
    # the SUPG factor is dk_r1/dS in the mobile range (central differences, O(eps^2))
    Sm = np.linspace(S_c + 0.01, 0.99, 40)
    eps = 1e-6
    fd = (physics.relative_permeabilities(Sm + eps, M, S_c)[0] - physics.relative_permeabilities(Sm - eps, M, S_c)[0]) / (2 * eps)
    np.testing.assert_allclose(physics.invading_permeability_slope(Sm, M, S_c), fd, rtol=0, atol=1e-8)
    # Duals carry the same derivative
    d = physics.relative_permeabilities(Dual.variables([Sm])[0], M, S_c)[0]
    np.testing.assert_allclose(d.dd[..., 0], fd, rtol=0, atol=1e-8)


def test_critical_saturation_is_an_effect_off_in_the_paper():
    e = EFFECTS["critical_saturation"]
    assert e.parameter == "critical_saturation" and e.off == 0.0 and e.paper == 0.0
    assert is_off(Parameters(), "critical_saturation") and not is_off(Parameters(critical_saturation=0.1),
                                                                      "critical_saturation")
    assert "critical_saturation" not in Parameters().to_dict()          # run keys of older runs unchanged
    for bad in (-0.1, 0.6, float("nan")):
        with pytest.raises(ValueError, match="critical_saturation"):
            Parameters(critical_saturation=bad)


def test_buckley_leverett_outflow_with_a_critical_saturation():
    par = Parameters(**{**BL, "critical_saturation": 0.2})
    mesh = _strip()
    res = simulate(par, RunOptions(h=H, t_end=8.0, dt0=1e-3, dt_max=DT, snapshot_times=[], write_xdmf=False,
                                   newton_rtol=1e-10), mesh=mesh, phi0=np.full(len(mesh.triangles), PHI))
    assert res.status == "ok", res.reason
    ts = res.timeseries
    _, s_star, t_b = _welge_outflow(par, 1.0)
    assert s_star > 0.2
    v = par.w_i / PHI * _f_prime(s_star, par.viscosity_ratio, S_c=0.2)
    for t_check in (0.5 * t_b, 6.0, 8.0):
        row = ts.iloc[int(np.argmin(np.abs(ts["t"] - t_check)))]
        exact, _, _ = _welge_outflow(par, row["t"])
        tol = PHI * ROWS * H * 2 * math.sqrt(v * v * DT / 2 * row["t"]) * s_star
        assert abs(row["water_outflow_volume"] - exact) < tol, (row["t"], row["water_outflow_volume"], exact, tol)
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9
    # the shock saturation rises above S_c, so the water breaks through later than the paper's law lets it
    # (its Welge breakthrough time, tests/test_outlet.py checks the run against it); the run's first water out
    # lies within the smearing's reach before t_b
    _, _, t_b0 = _welge_outflow(Parameters(**BL), 1.0)
    first = ts["t"][ts["water_outflow_volume"] > 1e-3 * ts["injected_volume"]].min()
    assert t_b > t_b0 and first > t_b0, (t_b, t_b0, first)


def test_critical_saturation_jacobian_is_exact():
    """Taylor test on the annulus with S ≈ 0.5 (S_e ≈ 0.375: the water mobile, the reduced law active) and the
    outlet letting fluid out: |R(U + εV) − R(U) − ε J V| falls as ε² on the S and p rows."""
    from solver.mesh import annulus_mesh
    from solver.model import build_discretization, step_data
    from solver.porosity import random_porosity

    p = Parameters(outer_saturation_bc="outflow", mu_outer_bc="zero_flux", critical_saturation=0.2)
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3))
    rng = np.random.default_rng(1)
    U = taylor_state(disc, rng)
    data = step_data(disc, p, 0.9 * U, np.zeros(disc.n_nodes), 1e-3)
    nf = disc.n_fields
    V = rng.standard_normal(U.shape) * np.array([0.01, 0.01, 1, 0.05, 0.01, 0.05, 0.05])[:nf]
    eps = np.array([1e-2, 1e-3, 1e-4])
    for field in (2, 3):   # the total (p) and water (S) balances, where the mobilities live
        rows = np.arange(disc.n_nodes) * nf + field
        rem = taylor_remainders(disc, p, U, data, V, eps, rows)
        assert np.all(np.diff(np.log(rem)) / np.diff(np.log(eps)) > 1.9), (field, rem)

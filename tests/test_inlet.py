"""Verification of the inlet condition ``inner_saturation_bc = "injection"``: the pumped fluid is all water and
the only inflow through r_i.

1. Buckley–Leverett on a strip (Cahn–Hilliard and Korteweg off, rigid skeleton, constant φ, the outlet of
   tests/test_outlet.py): with no Cahn–Hilliard flux the injection inlet and the paper's S = 1 inlet admit the
   same water, w per unit area, so the water that has left the strip follows Welge's answer within the scheme's
   smearing, as the paper's inlet does there.
2. With the Cahn–Hilliard flux on (γ > 0) and μ_i > 0 the paper's inlet draws water in beyond the pumped volume
   and lets oil out through r_i (Sec. 3.4: μ_i "facilitates the incoming flow"); the injection inlet admits
   exactly the pumped water, no oil crosses r_i, and both balances close to 1e-9 of the injected volume.
3. The Jacobian stays exact with the inlet's line storage on the S rows (Taylor test).
"""
import math

import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from test_outlet import BL, DT, H, PHI, ROWS, _f_prime, _strip, _welge_outflow, taylor_remainders, taylor_state


def _strip_run(**changes):
    par = Parameters(**{**BL, **changes})
    mesh = _strip()
    res = simulate(par, RunOptions(h=H, t_end=8.0, dt0=1e-3, dt_max=DT, snapshot_times=[], write_xdmf=False,
                                   newton_rtol=1e-10), mesh=mesh, phi0=np.full(len(mesh.triangles), PHI))
    assert res.status == "ok", res.reason
    return par, res.timeseries


def test_injection_inlet_gives_the_buckley_leverett_outflow():
    par, ts = _strip_run(inner_saturation_bc="injection")
    _, s_star, t_b = _welge_outflow(par, 1.0)
    v = par.w_i / PHI * _f_prime(s_star, par.viscosity_ratio)
    for t_check in (0.5 * t_b, 6.0, 8.0):
        row = ts.iloc[int(np.argmin(np.abs(ts["t"] - t_check)))]
        exact, _, _ = _welge_outflow(par, row["t"])
        tol = PHI * ROWS * H * 2 * math.sqrt(v * v * DT / 2 * row["t"]) * s_star
        assert abs(row["water_outflow_volume"] - exact) < tol, (row["t"], row["water_outflow_volume"], exact, tol)
    assert np.allclose(ts["water_inflow_volume"], ts["injected_volume"], rtol=1e-12, atol=0.0)
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9


@pytest.fixture(scope="module")
def annulus_runs():
    """The experiment's rate on the annulus, h = 4 mm, to 0.2 s, with the paper's inlet and the injection inlet
    (Cahn–Hilliard flux on: γ = 0.03 kPa mm, μ_i = 0.006 kPa)."""
    out = {}
    for bc in ("dirichlet", "injection"):
        p = Parameters(w_i=27.07, outer_saturation_bc="outflow", mu_outer_bc="zero_flux", inner_saturation_bc=bc)
        res = simulate(p, RunOptions(h=4.0, t_end=0.2, snapshot_times=[], write_xdmf=False, newton_rtol=1e-10))
        assert res.status == "ok", res.reason
        out[bc] = res.timeseries
    return out


def test_injection_inlet_admits_exactly_the_pumped_water_and_no_oil(annulus_runs):
    ts = annulus_runs["injection"]
    inj = ts["injected_volume"]
    # water in = pumped: the total inflow through r_i is w_i L t (the p rows' load), so the oil through r_i is 0
    assert np.allclose(ts["water_inflow_volume"], inj, rtol=1e-12, atol=0.0)
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9


def test_the_papers_inlet_draws_water_in_beyond_the_pumped_volume(annulus_runs):
    """μ_i = 0.006 kPa > 0 with S = 1 on r_i: the Cahn–Hilliard flux carries water in and oil out at r_i, so the
    water inflow exceeds the pumped volume (by several percent at 0.2 s) while the total inflow equals it."""
    ts = annulus_runs["dirichlet"]
    excess = ts["water_inflow_volume"].iloc[-1] / ts["injected_volume"].iloc[-1] - 1.0
    assert excess > 0.01, excess
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9


def test_injection_inlet_jacobian_with_the_line_storage_is_exact():
    """|R(U + εV) − R(U) − ε J V| falls as ε² with the line's storage on the inlet's p and S rows."""
    from solver.mesh import annulus_mesh
    from solver.model import build_discretization, step_data
    from solver.porosity import random_porosity

    p = Parameters(inner_saturation_bc="injection", line_compliance=3.0)
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3))
    rng = np.random.default_rng(2)
    U = taylor_state(disc, rng)
    data = step_data(disc, p, 0.9 * U, np.zeros(disc.n_nodes), 1e-3)
    V = rng.standard_normal(U.shape) * np.array([0.01, 0.01, 1, 0.05, 0.01, 0.05, 0.05])[:disc.n_fields]
    eps = np.array([1e-2, 1e-3, 1e-4])
    rem = taylor_remainders(disc, p, U, data, V, eps)
    assert np.all(np.diff(np.log(rem)) / np.diff(np.log(eps)) > 1.8), rem

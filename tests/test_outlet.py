"""Verification of the outlet condition ``outer_saturation_bc = "outflow"`` (issue #47, item 1).

1. Buckley–Leverett on a strip (the model's own residual, the Cahn–Hilliard and Korteweg terms off, a rigid
   skeleton and constant φ, as in tests/test_transport.py) ending in the outlet: before the shock reaches the
   outlet (t_b = L φ S*/(w f(S*))) no water leaves; after it the outlet's saturation S_L follows
   L = (w t/φ) f'(S_L) and Welge's mean saturation S̄ = S_L + (1 − f(S_L))/f'(S_L) gives the water that has
   left, H (w t − φ L S̄) for a strip of height H.  The tolerance is the water the scheme's smearing of the
   shock over δ = 2 √(D t) (D = v²Δt/2, backward Euler) can misplace, φ H δ S*.
2. On the paper's annulus (coarse mesh, front far from r_o): no water through r_o, no water layer at r_o,
   and both phases' volumes balance to 1e-9 of the injected volume.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from solver import Parameters, RunOptions, physics, simulate
from solver.mesh import Mesh, rectangle_mesh

BL = dict(eta_w=1e-3, eta_o=5e-3, kbar=0.05, E=1e8, K_s=1e12, gamma=0.0, mu_i=0.0, mu_o=0.0, korteweg_factor=0.0,
          volumetric_coupling=0.0, w_i=1.0, porosity_field="constant", outer_saturation_bc="outflow",
          mu_outer_bc="zero_flux")
PHI, LENGTH, H, ROWS, DT = 0.4, 20.0, 1.0, 2, 0.1


def _strip():
    m = rectangle_mesh(LENGTH, ROWS * H, int(round(LENGTH / H)), ROWS, x0=0.0, y0=-H / 2, diagonal="alternate")
    e = dict(m.boundary_edges)
    e["inner"], e["outer"] = e["left"], e["right"]
    return Mesh(m.points, m.triangles, e)


def _f_prime(s, M, e=1e-7, S_c=0.0):
    return (physics.fractional_flow(s + e, M, S_c) - physics.fractional_flow(s - e, M, S_c)) / (2 * e)


def _welge_outflow(par, t):
    """Water (mm² per unit cell height) that has left a strip of length L and height H by time t (Welge), with
    the fractional flow of ``par`` (its viscosity ratio and critical saturation S_c: the shock lies above S_c)."""
    M, S_c = par.viscosity_ratio, par.critical_saturation
    f = lambda s: physics.fractional_flow(s, M, S_c)
    fp = lambda s: _f_prime(s, M, S_c=S_c)
    s_star = brentq(lambda s: fp(s) - f(s) / s, S_c + 0.01, 0.99)
    t_b = LENGTH * PHI * s_star / (par.w_i * f(s_star))
    if t <= t_b:
        return 0.0, s_star, t_b
    s_L = brentq(lambda s: par.w_i * t / PHI * fp(s) - LENGTH, s_star, 1.0 - 1e-9)
    s_bar = s_L + (1.0 - f(s_L)) / fp(s_L)
    return ROWS * H * (par.w_i * t - PHI * LENGTH * s_bar), s_star, t_b


@pytest.fixture(scope="module")
def strip_run():
    par = Parameters(**BL)
    mesh = _strip()
    res = simulate(par, RunOptions(h=H, t_end=8.0, dt0=1e-3, dt_max=DT, snapshot_times=[], write_xdmf=False,
                                   newton_rtol=1e-10), mesh=mesh, phi0=np.full(len(mesh.triangles), PHI))
    assert res.status == "ok", res.reason
    return par, res.timeseries


def test_outlet_lets_water_out_only_after_breakthrough_as_buckley_leverett(strip_run):
    par, ts = strip_run
    _, s_star, t_b = _welge_outflow(par, 1.0)
    v = par.w_i / PHI * _f_prime(s_star, par.viscosity_ratio)
    for t_check in (0.5 * t_b, 6.0, 8.0):
        row = ts.iloc[int(np.argmin(np.abs(ts["t"] - t_check)))]
        exact, _, _ = _welge_outflow(par, row["t"])
        width = 2 * math.sqrt(v * v * DT / 2 * row["t"])
        tol = PHI * ROWS * H * width * s_star
        assert abs(row["water_outflow_volume"] - exact) < tol, (row["t"], row["water_outflow_volume"], exact, tol)
    # after breakthrough the outflow's water share is f(S_L) > f(S*) (0.58 at this M)
    last = ts.iloc[-10:]
    share = np.ptp(last["water_outflow_volume"]) / np.ptp(last["outflow_volume"])
    assert share > physics.fractional_flow(s_star, par.viscosity_ratio), share
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9


def test_outlet_on_the_annulus_keeps_water_in_before_breakthrough():
    """The paper's annulus at the measured rate, h = 4 mm, 0.1 s: the front is within 10 mm of r_i, 43 mm from
    r_o, where the tanh tail of the phase field is e^(-4·43/l_S) ~ 1e-19: the water through r_o is zero to the
    solver's tolerance, no layer forms at r_o, oil leaves, and the total and water volumes balance to 1e-9."""
    p = Parameters(outer_saturation_bc="outflow", mu_outer_bc="zero_flux", w_i=27.07)
    res = simulate(p, RunOptions(h=4.0, t_end=0.1, snapshot_times=[], write_xdmf=False, newton_rtol=1e-10))
    assert res.status == "ok", res.reason
    ts = res.timeseries
    inj = ts["injected_volume"].iloc[-1]
    assert ts["front_radius_max"].iloc[-1] < 15.0
    assert ts["water_outflow_volume"].abs().max() < 1e-6 * inj
    assert ts["outer_layer_area"].max() == 0.0
    assert ts["outflow_volume"].iloc[-1] > 0.0
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9


def taylor_state(disc, rng):
    """A state for a Taylor test on the annulus: p falling from about 100 kPa at r_i to 0 at r_o, S ≈ 0.5 (both
    fluids mobile), small random displacements, μ and gradient fields (nodes x fields)."""
    r = np.hypot(*disc.points.T)
    U = np.zeros((disc.n_nodes, disc.n_fields))
    U[:, 0:2] = 0.02 * rng.standard_normal((disc.n_nodes, 2))
    U[:, 2] = 100 * (53 - r) / 48 + rng.standard_normal(disc.n_nodes)
    U[:, 3] = 0.5 + 0.1 * rng.standard_normal(disc.n_nodes)
    U[:, 4] = 0.01 * rng.standard_normal(disc.n_nodes)
    if disc.n_fields == 7:
        U[:, 5:] = 0.1 * rng.standard_normal((disc.n_nodes, 2))
    return U


def taylor_remainders(disc, p, U, data, V, eps, rows=slice(None)):
    """|R(U + εV) − R(U) − ε J V| on ``rows`` for each ε of ``eps`` (the unconstrained residual and Jacobian)."""
    from solver.model import residual_and_jacobian

    R, J = residual_and_jacobian(disc, p, U, data)
    return [np.linalg.norm((residual_and_jacobian(disc, p, U + e * V, data, need_jacobian=False)[0] - R
                            - e * (J @ V.ravel()))[rows]) for e in eps]


def test_outlet_jacobian_is_exact():
    """Taylor test of the residual with the outlet term: |R(U + εV) − R(U) − ε J V| falls as ε², with water at
    r_o (S ≈ 0.5 there, so f(S) and f'(S) are both active) and outflow at most outer nodes."""
    from solver.mesh import annulus_mesh
    from solver.model import build_discretization, residual_and_jacobian, step_data
    from solver.porosity import random_porosity

    p = Parameters(outer_saturation_bc="outflow", mu_outer_bc="zero_flux")
    mesh = annulus_mesh(h=4.0)
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=3))
    rng = np.random.default_rng(1)
    U = taylor_state(disc, rng)
    data = step_data(disc, p, 0.9 * U, np.zeros(disc.n_nodes), 1e-3)
    R, J = residual_and_jacobian(disc, p, U, data)
    nf = disc.n_fields
    assert np.mean(-R[nf * disc.outer_nodes + 2] > 0) > 0.5  # most outer nodes let fluid out
    V = rng.standard_normal(U.shape) * np.array([0.01, 0.01, 1, 0.05, 0.01, 0.05, 0.05])[:nf]
    eps = np.array([1e-2, 1e-3, 1e-4])
    rows = nf * disc.outer_nodes + 3  # the outlet's S rows, where its term lives (a global norm would hide it)
    rem = taylor_remainders(disc, p, U, data, V, eps, rows)
    assert np.all(np.diff(np.log(rem)) / np.diff(np.log(eps)) > 1.9), rem

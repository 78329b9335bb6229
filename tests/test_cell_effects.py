"""Verification of the elastic cell and the injection line's compliance (solver.effects, issue #47 item 4).

Both on the paper's annulus with a rigid, incompressible skeleton (E = 1e8 kPa, K_s = 1e12 kPa), constant
porosity 0.4, equal viscosities η_w = η_o (then k_r1 + k_r2 = 1: the total mobility k/η does not depend on S,
so the pressure does not see the front), no Cahn–Hilliard or Korteweg terms and the outlet reservoir on r_o.

1. Elastic cell, steady radial flow: with the gap's transmissivity δ³/(12h), δ = c p, in parallel with k, the
   Kirchhoff transform of Q = 2π r (k + c³p³/(12h))/η (−dp/dr) gives k p_i + c³ p_i⁴/(48 h) = Q η ln(r_o/r_i)/(2π)
   for the inlet pressure p_i.  The gap's storage c/h delays the steady state by about r_o²/D, D = (k/η)/(c/h)
   (0.35 s here); the runs go to 2 s.  Tolerance: the P1 error of the same mesh on the linear problem (c = 0),
   2.5 % at h = 4; the gap lowers p_i by 13 %, so a missing or wrong gap term fails.
2. Line compliance: the pack is a resistance R (p_inj = R × its inflow, exact on this mesh: the c = 0 run's
   p_inj / Q, Q = w_i × the polygonal inlet's length), the line a capacity C_line, so p_inj follows C_line dp/dt = Q − p/R, here in backward Euler over
   the run's own steps: p_{n+1} = (p_n + Δt Q/C_line)/(1 + Δt/(R C_line)).  Tolerance 1e-6 relative (the
   Newton tolerance; the inlet nodes' p differ by round-off only).
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from solver import Parameters, RunOptions, simulate

RIGID = dict(E=1e8, K_s=1e12, gamma=0.0, mu_i=0.0, mu_o=0.0, korteweg_factor=0.0, volumetric_coupling=0.0,
             eta_w=1e-3, eta_o=1e-3, kbar=0.01, w_i=50.0, porosity_field="constant",
             outer_saturation_bc="outflow", mu_outer_bc="zero_flux")


def _run(**changes):
    res = simulate(Parameters(**RIGID, **changes), RunOptions(h=4.0, t_end=2.0, dt_max=0.2, snapshot_times=[],
                                                              write_xdmf=False, newton_rtol=1e-10))
    assert res.status == "ok", res.reason
    ts = res.timeseries
    assert ts["mass_error"].max() < 1e-9 and ts["water_mass_error"].max() < 1e-9
    return ts


def _steady_inlet_pressure(par: Parameters) -> float:
    k = par.k_of_phi(0.4)
    rhs = 2 * math.pi * par.r_inner * par.w_i * par.eta_w * math.log(par.r_outer / par.r_inner) / (2 * math.pi)
    c, h = par.cell_compliance, par.cell_height
    return brentq(lambda p: k * p + c**3 * p**4 / (48 * h) - rhs, 0.0, 1e5)


@pytest.fixture(scope="module")
def rigid_run():
    return _run()


def test_elastic_cell_gives_the_steady_radial_flow_of_the_opened_gap(rigid_run):
    e0 = rigid_run["p_inj"].iloc[-1] / _steady_inlet_pressure(Parameters(**RIGID)) - 1
    par = Parameters(**RIGID, cell_compliance=1e-3)
    ts = _run(cell_compliance=1e-3)
    p_ex = _steady_inlet_pressure(par)
    assert p_ex < 0.9 * _steady_inlet_pressure(Parameters(**RIGID))  # the gap matters here
    assert abs(np.diff(ts["p_inj"].iloc[-3:])).max() < 1e-4 * p_ex  # steady
    assert abs(ts["p_inj"].iloc[-1] / p_ex - 1) <= abs(e0), (ts["p_inj"].iloc[-1], p_ex, e0)


def test_line_compliance_charges_the_line_as_a_capacity_behind_the_pack(rigid_run):
    C = 3.0  # mm²/kPa
    Q = rigid_run["injected_volume"].iloc[-1] / rigid_run["t"].iloc[-1]  # w_i × the polygonal inlet's length
    R = rigid_run["p_inj"].iloc[-1] / Q  # kPa s/mm²: the pack's resistance on this mesh
    ts = _run(line_compliance=C)
    p, expect = 0.0, []
    for dt in ts["dt"]:
        p = (p + dt * Q / C) / (1 + dt / (R * C))
        expect.append(p)
    np.testing.assert_allclose(ts["p_inj"], expect, rtol=1e-6)
    assert ts["p_inj"].iloc[0] < 0.5 * rigid_run["p_inj"].iloc[-1]  # the line delays the rise
    # what the line holds is C_line p_inj
    np.testing.assert_allclose(ts["line_stored_volume"], C * ts["p_inj"], rtol=1e-6)


def test_effects_are_off_exactly_and_leave_the_run_keys_alone():
    from solver.effects import EFFECTS, is_off, plate_bending_compliance, tube_compliance

    p = Parameters()
    assert is_off(p, "elastic_cell") and is_off(p, "line_compliance")
    assert "cell_compliance" not in p.to_dict() and "line_compliance" not in p.to_dict()
    assert Parameters(cell_compliance=1e-3).to_dict()["cell_compliance"] == 1e-3
    # the independent estimates quoted with the effects: w = p a⁴/(64 D), D = E t³/(12 (1 − ν²)), two plates
    D = 3e6 * 10.0**3 / (12 * (1 - 0.35**2))
    assert plate_bending_compliance() == pytest.approx(2 * 53.0**4 / (64 * D), rel=1e-12)
    assert "8.7e-4" in EFFECTS["elastic_cell"].estimate and round(plate_bending_compliance(), 5) == 0.00087
    assert round(tube_compliance(), 1) == 2.6 and "2.6 mm^2/kPa" in EFFECTS["line_compliance"].estimate

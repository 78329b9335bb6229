"""Verification of the saturation transport and of the fidelity options (issue: model behaviour).

1. Buckley–Leverett (1D, the model's own residual on a strip): with the Cahn–Hilliard and Korteweg terms off
   (γ = 0, μ_i = μ_o = 0, κ factor 0), a rigid skeleton (E = 1e8 kPa, K_s = 1e12 kPa) and constant porosity φ,
   the invading mass balance is φ ∂S/∂t + w ∂f(S)/∂x = 0 with f = λ_1/(λ_1 + λ_2) (Fourar–Lenormand k_r).
   Welge: the shock saturation S* solves f'(S*) = f(S*)/S*, the front sits at x_f = (w t/φ) f(S*)/S*.
   The front is measured as the S = S*/2 crossing.  The method smears the shock over a width
   δ ≈ 2 √(D t) with the numerical diffusivity D = v²Δt/2 of backward Euler plus v h/2 for the upwind
   option (v = f'(S*) w/φ, the shock speed): the tolerance on x_f is δ.
2. Mass balance: every option keeps the discrete volume balance (``mass_error`` of the time series)
   to 1e-9 relative.
3. Cahn–Hilliard relaxation under each mobility law: a too-wide planar interface relaxes to the
   equilibrium profile ½(1 + tanh(2x/l_S)) with interface energy γ; the free energy never increases
   (the Cahn–Hilliard flux is a gradient flow for any M >= 0), up to the quadrature of the energy.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from solver import Parameters, RunOptions, simulate
from solver.mesh import Mesh, rectangle_mesh
from solver.model import MU, S
from solver.simulate import Simulation

# ----------------------------------------------------------------- Buckley–Leverett
BL = dict(eta_w=1e-3, eta_o=5e-3, kbar=0.05, E=1e8, K_s=1e12, gamma=0.0, mu_i=0.0, mu_o=0.0,
          korteweg_factor=0.0, volumetric_coupling=0.0, w_i=1.0, porosity_field="constant")
PHI, LENGTH, T_BL, H_BL, DT_BL = 0.4, 60.0, 12.0, 1.0, 0.05


def strip(length, h, rows, diagonal="alternate"):
    """Structured strip [0, length] x [-h/2, (rows - 1/2) h] (mm) with tags inner = left, outer = right."""
    m = rectangle_mesh(length, rows * h, int(round(length / h)), rows, x0=-0.0, y0=-h / 2, diagonal=diagonal)
    e = dict(m.boundary_edges)
    e["inner"], e["outer"] = e["left"], e["right"]
    return Mesh(m.points, m.triangles, e)


def fractional_flow(S, p: Parameters):
    M = p.eta_o / p.eta_w
    kr1 = S**3 + 1.5 / M * S * (1 - S) * (1 + S)
    kr2 = 0.5 * (1 - S) ** 2 * (2 + S)
    l1, l2 = kr1 / p.eta_w, kr2 / p.eta_o
    return l1 / (l1 + l2)


def welge(p: Parameters):
    """Shock saturation S* and shock speed factor f(S*)/S* (-)."""
    f = lambda s: fractional_flow(s, p)
    fp = lambda s, e=1e-7: (f(s + e) - f(s - e)) / (2 * e)
    s_star = brentq(lambda s: fp(s) - f(s) / s, 0.01, 0.99)
    return s_star, f(s_star) / s_star


def bl_front(transport):
    par = Parameters(**BL)
    mesh = strip(LENGTH, H_BL, 4)
    res = simulate(par, RunOptions(h=H_BL, t_end=T_BL, dt0=1e-3, dt_max=DT_BL, snapshot_times=[T_BL],
                                   write_xdmf=False, transport=transport),
                   mesh=mesh, phi0=np.full(len(mesh.triangles), PHI))
    assert res.status == "ok", res.reason
    x = np.round(mesh.points[:, 0], 9)
    xs = np.unique(x)
    Sn = res.snapshots[-1][1]["S"]
    Ss = np.array([Sn[x == v].mean() for v in xs])
    return par, xs, Ss, res.timeseries


def shock_width(xs, Ss, s_star):
    """Distance (mm) between the last crossing of 0.9 S* and the first crossing below 0.1 S* of the profile."""
    i_lo = int(np.flatnonzero(Ss < 0.1 * s_star)[0])
    i_hi = int(np.flatnonzero(Ss >= 0.9 * s_star)[-1])
    x_lo = xs[i_lo - 1] + (Ss[i_lo - 1] - 0.1 * s_star) / (Ss[i_lo - 1] - Ss[i_lo]) * (xs[i_lo] - xs[i_lo - 1])
    x_hi = xs[i_hi] + (Ss[i_hi] - 0.9 * s_star) / (Ss[i_hi] - Ss[i_hi + 1]) * (xs[i_hi + 1] - xs[i_hi])
    return x_lo - x_hi


# SUPG adds diffusion only where the strong residual is not zero (consistent): its front is held to the plain
# Galerkin smearing width (upwind = 0), and its shock must be narrower than first-order upwinding's own
# diffusion width 2 √(v h/2 t)
@pytest.mark.parametrize("transport,upwind", [("galerkin", 0.0), ("upwind", 1.0), ("supg", 0.0)])
def test_buckley_leverett_front_matches_welge(transport, upwind):
    par, xs, Ss, ts = bl_front(transport)
    s_star, speed = welge(par)
    x_front = par.w_i * T_BL / PHI * speed
    i = int(np.flatnonzero(Ss < s_star / 2)[0])
    x_num = xs[i - 1] + (Ss[i - 1] - s_star / 2) / (Ss[i - 1] - Ss[i]) * (xs[i] - xs[i - 1])
    v = par.w_i / PHI * speed
    width = 2 * math.sqrt((v * v * DT_BL / 2 + upwind * v * H_BL / 2) * T_BL)
    assert abs(x_num - x_front) < width, (x_num, x_front, width)
    if transport == "supg":
        assert shock_width(xs, Ss, s_star) < 2 * math.sqrt(v * H_BL / 2 * T_BL)
    # behind the shock the rarefaction x = (w t/φ) f'(S) is followed: the numerical saturation at the
    # rarefaction's mid point is within the smearing of its exact value
    s_mid = 0.5 * (1 + s_star)
    fp = (fractional_flow(s_mid + 1e-7, par) - fractional_flow(s_mid - 1e-7, par)) / 2e-7
    x_mid = par.w_i * T_BL / PHI * fp
    assert abs(np.interp(x_mid, xs, Ss) - s_mid) < 0.05
    assert ts["mass_error"].max() < 1e-9
    # the water stays in the strip: at most the smeared tail reaches the outlet (upwind: front 6 mm from the
    # outlet, smearing width 11 mm; measured 0.4 % of the inflow)
    assert abs(ts["water_outflow_volume"].iloc[-1]) < 1e-2 * ts["water_inflow_volume"].iloc[-1]


# ----------------------------------------------------------------- mass balance of every option
OPTION_CASES = [
    ({"ch_mobility": "oil"}, {"transport": "upwind"}),
    ({"ch_mobility": "degenerate"}, {}),
    ({"outer_saturation_bc": "defending_outflow", "mu_outer_bc": "zero_flux"}, {}),
    ({}, {"transport": "upwind"}),
    ({}, {"transport": "supg"}),
    ({"ch_mobility": "oil"}, {"transport": "supg"}),
]


@pytest.mark.parametrize("changes,opts", OPTION_CASES)
def test_every_option_keeps_the_volume_balance(changes, opts):
    # the balance is exact up to the Newton residual: solve tightly so that the check measures the scheme
    res = simulate(Parameters(**changes), RunOptions(h=4.0, t_end=0.05, snapshot_times=[], write_xdmf=False,
                                                     newton_rtol=1e-10, **opts))
    assert res.status == "ok", res.reason
    ts = res.timeseries
    assert ts["mass_error"].max() < 1e-9
    if changes.get("outer_saturation_bc") == "defending_outflow":
        # no invading flux through r_o: what leaves is the defending fluid only
        assert abs(ts["water_outflow_volume"].iloc[-1]) < 1e-9 * ts["injected_volume"].iloc[-1]
        assert ts["outflow_volume"].iloc[-1] > 0


# ----------------------------------------------------------------- Cahn–Hilliard relaxation
CH = dict(eta_w=1e-3, eta_o=2e-3, kbar=1.0, w_i=0.0, mu_i=0.0, mu_o=0.0, korteweg_factor=0.0, E=1e8, K_s=1e12)


def interface_energy(sim):
    """Free energy ∫ 12γ/l_S (f(S) + l_S²/16 |∇S|²) per unit interface length (kPa·mm), vertex + exact rule."""
    p, disc, Sn = sim.params, sim.disc, sim.U[:, S]
    tri = disc.triangles
    f = ((Sn * (1 - Sn)) ** 2)[tri].mean(axis=1)  # vertex rule (the relaxed profile is smooth)
    gS = np.einsum("ma,mai->mi", Sn[tri], disc.geom.grads)
    dens = f + p.l_S**2 / 16 * (gS**2).sum(axis=1)
    return 12 * p.gamma / p.l_S * float(np.sum(disc.geom.areas * dens)) / np.ptp(disc.points[:, 1])


@pytest.mark.parametrize("law", ["harmonic", "oil", "degenerate"])
def test_cahn_hilliard_relaxes_to_the_planar_profile(law):
    par = Parameters(ch_mobility=law, **CH)
    ls, h = par.l_S, par.l_S / 8
    half = 3 * ls
    m = rectangle_mesh(2 * half, h, int(round(2 * half / h)), 1, x0=-half, y0=-h / 2, diagonal="right")
    e = dict(m.boundary_edges)
    e["inner"], e["outer"] = e["right"], e["left"]  # S = 1 on the right (inner tag), 0 on the left
    mesh = Mesh(m.points, m.triangles, e)
    sim = Simulation(par, RunOptions(h=h, write_xdmf=False), mesh, np.full(len(mesh.triangles), 0.4))
    x = sim.disc.points[:, 0]
    exact = 0.5 * (1 + np.tanh(2 * x / ls))
    sim.U[:, S] = 0.5 * (1 + np.tanh(2 * x / (2 * ls)))  # twice too wide
    energies = [interface_energy(sim)]
    dt = 0.05 if law != "oil" else 0.1
    for _ in range(60):
        U, d, _info = sim.step(dt)
        sim.U, sim.d, sim.t = U, d, sim.t + dt
        energies.append(interface_energy(sim))
    # non-increasing up to the mismatch between this vertex-rule energy and the scheme's Strang-rule
    # f'(S) near equilibrium (measured 1e-10 kPa·mm against steps of 1e-3 at the start)
    assert np.all(np.diff(energies) <= 1e-6 * energies[0]), energies
    assert np.abs(sim.U[:, S] - exact).max() < 0.02
    assert energies[-1] == pytest.approx(par.gamma, rel=0.03)
    if law != "degenerate":
        # the chemical potential equilibrates to its coexistence value 0; with the degenerate law M -> 0 in
        # the pure phases, so there μ relaxes only through the interface and is not checked
        assert np.abs(sim.U[:, MU]).max() < 1e-3 * 12 * par.gamma / ls


def test_the_reference_experiment_is_valid_measured_data():
    """results/fidelity/experiment (the paper's Sec. 3.5 figures) loads with the workflow's validating loader."""
    from pathlib import Path

    from solver.presets import measured_injection_velocity
    from sweep.discrepancy.data import load_measured

    m = load_measured(Path(__file__).resolve().parents[1] / "results" / "fidelity" / "experiment")
    assert set(m.curves["observable"]) == {"p_inj", "front_radius_branches", "crack_length", "crack_count"}
    assert m.regimes == {"reference": (2.0, "invasive_fracturing")}
    # one experiment at the measured rate (issue #47)
    assert m.conditions.loc["reference", "w_i"] == pytest.approx(measured_injection_velocity(), rel=1e-12)


def test_the_reference_experiment_starts_a_spec_and_its_spec_checks_against_it(tmp_path):
    """`dchfrac discrepancy init` accepts results/fidelity/experiment (issue #52) and holds out the shape (the
    observables other than p_inj of its one condition); the real experiment's SPEC
    (results/experiment_model/discrepancy/spec.toml) loads and passes the data-model checks on the held-out data,
    and the condition and its held-out twin map to one forward run (one experiment, issue #47)."""
    from pathlib import Path

    from sweep.cli import main
    from sweep.discrepancy.checks import check_data_against_model
    from sweep.discrepancy.data import load_measured
    from sweep.discrepancy.forward import SolverForward, fine_forwards
    from sweep.discrepancy.spec import load_spec

    root = Path(__file__).resolve().parents[1]
    folder = root / "results" / "fidelity" / "experiment"
    assert main(["discrepancy", "init", "--measured", str(folder), "--out", str(tmp_path / "s.toml")]) in (0, None)
    from sweep.discrepancy.heldout import heldout_data

    assert ('observables = ["crack_count", "crack_length", "front_radius_branches", "regime"]'
            in (tmp_path / "s.toml").read_text())
    spec = load_spec(root / "results" / "experiment_model" / "discrepancy" / "spec.toml")
    data = heldout_data(load_measured(folder), spec)
    fw = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), tmp_path / "cache")
    check_data_against_model(data, spec, [fw, *fine_forwards(spec, tmp_path / "cache")])
    runs = {fw.run_dir(data.conditions.loc[c].to_dict()) for c in data.ids}
    assert len(runs) == 1


def test_every_fidelity_variant_is_a_valid_model():
    """Each screening variant (sweep.studies.fidelity.VARIANTS) passes the parameter and run-option validation, so a
    misspelt option fails here and not after a campaign has started."""
    from sweep.studies.fidelity import VARIANTS

    for name, (changes, opts) in VARIANTS.items():
        Parameters(**changes)
        RunOptions(h=2.0, **opts)
    assert {"c_supg", "ac_oil_supg", "fc_supg_graded"} <= set(VARIANTS)


def test_water_placement_against_analytic_volumes():
    """sweep.studies.fidelity.water_placement on an annulus (r_i = 5, r_o = 53 mm, h = 1 mm) with uniform φ = 0.3:
    a disk of water S = 1 for r <= 20 mm and a separate ring S = 1 for 45 <= r <= 50 mm.  Analytic: the
    volume φ π ((20² − 5²) + (50² − 45²)), the connected fraction (20² − 5²)/((20² − 5²) + (50² − 45²)), the
    outer-band fraction (r > 43 mm) the ring's share, and r50 from the cumulative volume.  A P1 step is
    smeared over one element row at each edge of the water, so volumes hold to 2 h × circumference and radii
    to h."""
    from solver.mesh import annulus_mesh
    from sweep.studies.fidelity import water_placement

    h, phi = 1.0, 0.3
    m = annulus_mesh(5.0, 53.0, h)
    r = np.hypot(m.points[:, 0], m.points[:, 1])
    Snod = ((r <= 20.0) | ((r >= 45.0) & (r <= 50.0))).astype(float)
    snap = {"S": Snod, "phi": np.full(len(m.triangles), phi)}
    out = water_placement(snap, m.points, m.triangles, 5.0, 53.0)
    disk, ring = 20.0 ** 2 - 5.0 ** 2, 50.0 ** 2 - 45.0 ** 2
    vol = phi * math.pi * (disk + ring)
    smear = phi * 2 * h * 2 * math.pi * (20.0 + 45.0 + 50.0)
    assert abs(out["invading_volume"] - vol) < smear
    assert abs(out["connected_frac"] - disk / (disk + ring)) < smear / vol
    assert abs(out["outer_band_frac"] - ring / (disk + ring)) < smear / vol
    # r50: half the water, (disk + ring)/2 = 2,600 mm²/π, lies past the disk (375): inside the ring at
    # r² = 45² + (disk + ring)/2 − disk
    r50 = math.sqrt(45.0 ** 2 + (disk + ring) / 2 - disk)
    assert abs(out["r50"] - r50) < h
    # with the ring gone every drop is connected to the inlet and none is in the outer band
    snap["S"] = (r <= 20.0).astype(float)
    out = water_placement(snap, m.points, m.triangles, 5.0, 53.0)
    # (the elements of the edge row hold part of the water and are not wholly invaded: one row, h 2π 20 mm²)
    assert out["connected_frac"] > 1.0 - h * 2 * math.pi * 20.0 / (math.pi * disk)
    assert out["outer_band_frac"] == 0.0
    assert abs(out["r90"] - math.sqrt(5.0 ** 2 + 0.9 * disk)) < h

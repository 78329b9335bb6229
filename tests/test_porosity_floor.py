"""The porosity floor (``Parameters.porosity_floor``, ``solver.physics.porosity_floor``).

1. The law: the linear porosity above φ_f; below, φ_f²/(2φ_f − φ), positive, increasing in the linear value,
   and C¹ at φ_f (value and slope 1 match), with the exact derivative of the Dual path.
2. The residual's Jacobian stays exact where the floor is active (Taylor remainder of second order).
3. Off by default, and then absent from the parameter dict (the run keys of older runs do not change);
   validated against the smallest initial porosity.
4. A run in which the floor acts (the compacted wall rows) keeps its volume balance.
"""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.ad import Dual
from solver.mesh import annulus_mesh
from solver.physics import porosity, porosity_floor
from solver.porosity import random_porosity

from compaction import taylor_slopes_under_compaction

FLOOR = 0.1


def test_floor_is_identity_above_and_positive_increasing_below():
    lin = np.linspace(-5.0, 0.9, 2001)
    phi = porosity_floor(lin, FLOOR)
    above = lin >= FLOOR
    assert np.array_equal(phi[above], lin[above])
    assert np.all(phi > 0) and np.all(phi[~above] < FLOOR)
    assert np.all(np.diff(phi) > 0)
    # as the linear value goes to −∞ the floored porosity goes to 0 like φ_f²/|φ|
    assert porosity_floor(np.array([-1e6]), FLOOR)[0] == pytest.approx(FLOOR**2 / (2 * FLOOR + 1e6))


def test_floor_is_c1_at_the_bound_and_its_dual_derivative_is_exact():
    x = np.array([FLOOR - 1e-9, FLOOR + 1e-9, FLOOR - 0.3, 0.5])
    d = porosity_floor(Dual.variables([x])[0], FLOOR)
    slope = d.d[..., 0]
    assert slope[0] == pytest.approx(1.0, abs=1e-7) and slope[1] == 1.0  # slope 1 on both sides of φ_f
    assert slope[2] == pytest.approx(FLOOR**2 / (2 * FLOOR - x[2]) ** 2, rel=1e-12)
    eps = 1e-7
    fd = (porosity_floor(x + eps, FLOOR) - porosity_floor(x - eps, FLOOR)) / (2 * eps)
    assert np.allclose(slope, fd, rtol=1e-6)


def test_porosity_law_applies_the_floor_only_when_given():
    phi0, ev, p = np.array([0.4, 0.4]), np.array([-0.9, 0.0]), np.array([0.0, 100.0])
    lin = porosity(phi0, ev, p, 1600.0)
    assert lin[0] < 0  # the paper's law leaves [0, 1] under strong compaction
    assert np.array_equal(porosity(phi0, ev, p, 1600.0, FLOOR), porosity_floor(lin, FLOOR))


def test_jacobian_stays_exact_where_the_floor_is_active():
    slopes, paper = taylor_slopes_under_compaction(Parameters(porosity_floor=FLOOR), "phi")
    assert np.all(slopes > 1.9), slopes
    assert (paper < FLOOR).mean() > 0.2  # the test exercises the floor


def test_floor_is_off_by_default_absent_from_old_dicts_and_validated():
    assert Parameters().porosity_floor is None and "porosity_floor" not in Parameters().to_dict()
    assert Parameters(porosity_floor=np.float32(0.05)).to_dict()["porosity_floor"] == pytest.approx(0.05)
    for bad in (0.0, -0.1, 0.2, 0.5):  # the default initial porosity spans [0.2, 0.6]
        with pytest.raises(ValueError, match=f"porosity_floor={bad!r}"):
            Parameters(porosity_floor=bad)
    assert Parameters.from_dict(Parameters(porosity_floor=0.05).to_dict()) == Parameters(porosity_floor=0.05)


def test_run_with_the_floor_keeps_its_volume_balance():
    """φ_f = 0.19, just below the smallest initial porosity: by 0.05 s the compacted wall rows fall below it."""
    par = Parameters(porosity_floor=0.19)
    res = simulate(par, RunOptions(h=4.0, h_outer=0.5, t_end=0.05, snapshot_times=(), write_xdmf=False))
    assert res.status == "ok", res.reason
    assert res.timeseries.mass_error.max() < 1e-9
    f = res.snapshots[-1][1]
    mesh = annulus_mesh(h=4.0, h_outer=0.5)
    lin = porosity(random_porosity(mesh, par.phi_mean, par.phi_range, par.seed), f["eps_v"],
                   f["p"][mesh.triangles].mean(axis=1), par.K_s)
    active = lin < par.porosity_floor
    assert active.sum() >= 10  # the floor acts (measured: 49 elements)
    assert np.all(f["phi"][active] < par.porosity_floor) and np.all(f["phi"] > 0)

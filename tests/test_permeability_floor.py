"""The permeability floor (``Parameters.permeability_floor``, ``solver.physics.permeability_floor``).

1. The law: the Kozeny–Carman permeability above k_f; below, k_f²/(2k_f − k), in [k_f/2, k_f) for k in
   [0, k_f), increasing in k and C¹ at k_f, with the exact derivative of the Dual path; the porosity floor is
   the same form (one function, ``smooth_floor``).
2. The residual's Jacobian stays exact where the floor is active (Taylor remainder of second order).
3. Off by default, and then absent from the parameter dict (run keys of older runs do not change);
   validated against the smallest initial permeability.
4. A run in which the floor acts (the compacted wall row) keeps its volume balance to 1e-9, and the floor is
   what the run's permeability field shows there.
"""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.ad import Dual
from solver.physics import kozeny_carman, permeability, permeability_floor, porosity_floor, smooth_floor

from compaction import taylor_slopes_under_compaction

K_F = 1e-5  # mm², below k(0.2) = 1.875e-5 mm² of the default k̄


def test_floor_is_identity_above_and_bounded_below():
    k = np.linspace(0.0, 4e-5, 4001)
    kf = permeability_floor(k, K_F)
    above = k >= K_F
    assert np.array_equal(kf[above], k[above])
    assert np.all(kf[~above] < K_F) and np.all(kf >= K_F / 2)
    assert kf[0] == K_F / 2  # closed pores (k = 0) keep half the floor
    assert np.all(np.diff(kf) > 0)
    # one form for both floors
    x = np.linspace(-3.0, 1.0, 101)
    assert np.array_equal(porosity_floor(x, 0.1), smooth_floor(x, 0.1))


def test_floor_is_c1_at_the_bound_and_its_dual_derivative_is_exact():
    x = np.array([K_F * (1 - 1e-9), K_F * (1 + 1e-9), 0.3 * K_F, 0.0, 3 * K_F])
    d = permeability_floor(Dual.variables([x])[0], K_F)
    slope = d.d[..., 0]
    assert slope[0] == pytest.approx(1.0, abs=1e-7) and slope[1] == 1.0
    assert slope[2] == pytest.approx(K_F**2 / (2 * K_F - x[2]) ** 2, rel=1e-12)
    assert slope[3] == pytest.approx(0.25, rel=1e-12)  # k_f²/(2k_f)² at k = 0
    eps = 1e-12
    fd = (permeability_floor(x + eps, K_F) - permeability_floor(np.maximum(x - eps, 0.0), K_F)) / \
        (x + eps - np.maximum(x - eps, 0.0))
    assert np.allclose(slope, fd, rtol=1e-5)


def test_permeability_law_applies_the_floor_only_when_given():
    par = Parameters()
    phi = np.array([-0.2, 0.0, 0.05, 0.2, 0.4, 1.2])
    phi0 = np.full_like(phi, 0.4)
    k = permeability(phi, phi0, par.kbar, par.k_max)
    assert np.array_equal(k, kozeny_carman(phi, par.kbar, par.k_max))
    assert k[0] == 0.0 and k[1] == 0.0  # the paper's law: closed pores, no flow
    kf = permeability(phi, phi0, par.kbar, par.k_max, floor=K_F)
    assert np.array_equal(kf, permeability_floor(k, K_F))
    assert np.array_equal(kf[3:], k[3:])  # every initial porosity (>= 0.2) is above the floor
    # with the crack-permeability blend the floor bounds the blended value
    ks = permeability(phi, phi0, par.kbar, par.k_max, 0.5, floor=K_F)
    k0 = kozeny_carman(phi0, par.kbar, par.k_max)
    assert np.array_equal(ks, permeability_floor(k0 + 0.5 * (k - k0), K_F))


def test_jacobian_stays_exact_where_the_floor_is_active():
    slopes, paper = taylor_slopes_under_compaction(Parameters(permeability_floor=K_F), "k")
    assert np.all(slopes > 1.9), slopes
    assert (paper < K_F).mean() > 0.2  # the test exercises the floor


def test_floor_is_off_by_default_absent_from_old_dicts_and_validated():
    assert Parameters().permeability_floor is None and "permeability_floor" not in Parameters().to_dict()
    assert Parameters(permeability_floor=np.float32(1e-6)).to_dict()["permeability_floor"] == pytest.approx(1e-6)
    for bad in (0.0, -1e-6, 1.9e-5, 1e-4):  # k at the smallest initial porosity 0.2 is 1.875e-5 mm²
        with pytest.raises(ValueError, match=f"permeability_floor={bad!r}"):
            Parameters(permeability_floor=bad)
    assert Parameters.from_dict(Parameters(permeability_floor=1e-6).to_dict()) == Parameters(permeability_floor=1e-6)


def test_run_with_the_floor_keeps_its_volume_balance():
    """The floor just below the smallest initial permeability: by 0.05 s the compacted wall row falls below it."""
    par = Parameters(permeability_floor=1.8e-5)
    res = simulate(par, RunOptions(h=4.0, h_outer=0.5, t_end=0.05, snapshot_times=(), write_xdmf=False))
    assert res.status == "ok", res.reason
    assert res.timeseries.mass_error.max() < 1e-9
    f = res.snapshots[-1][1]
    k_paper = kozeny_carman(f["phi"], par.kbar, par.k_max)
    active = k_paper < par.permeability_floor
    assert active.sum() >= 10, active.sum()
    assert np.allclose(f["k"][active], permeability_floor(k_paper[active], par.permeability_floor), rtol=1e-12)
    assert np.all(f["k"] >= par.permeability_floor / 2)

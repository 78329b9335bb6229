"""The porosity ceiling (``Parameters.porosity_ceiling``, ``solver.physics.porosity_ceiling``).

1. The law: the linear porosity up to the onset φ_c; above, 1 − (1 − φ_c)²/(2(1 − φ_c) − (1 − φ)), increasing,
   below 1 and tending to 1, C¹ at φ_c, with the exact derivative of the Dual path; it is the porosity floor's
   form mirrored about 1.
2. The residual's Jacobian stays exact where the ceiling is active (Taylor remainder of second order).
3. Off by default, and then absent from the parameter dict (run keys of older runs do not change); validated
   against the largest initial porosity.
4. A run in which the ceiling acts keeps its volume balance to 1e-9, and the ceiling is what its porosity
   field shows there.
"""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.ad import Dual
from solver.physics import porosity, porosity_ceiling, smooth_floor

from compaction import taylor_slopes_under_compaction

ONSET = 0.98


def test_ceiling_is_identity_below_and_bounded_by_one():
    phi = np.linspace(0.0, 5.0, 5001)
    pc = porosity_ceiling(phi, ONSET)
    below = phi <= ONSET
    assert np.array_equal(pc[below], phi[below])
    assert np.all(pc[~below] > ONSET) and np.all(pc < 1.0)
    assert np.all(np.diff(pc) > 0)
    assert porosity_ceiling(np.array(1e6), ONSET) == pytest.approx(1.0, abs=1e-7)
    # at φ_lin = 1 the ceiling is halfway between the onset and 1 in 1 − φ: 1 − (1 − φ_c)/2
    assert porosity_ceiling(np.array(1.0), ONSET) == pytest.approx(1.0 - (1.0 - ONSET) / 2, rel=1e-14)
    # the floor's form mirrored about 1
    assert np.allclose(pc, 1.0 - smooth_floor(1.0 - phi, 1.0 - ONSET), rtol=0, atol=1e-15)


def test_ceiling_is_c1_at_the_onset_and_its_dual_derivative_is_exact():
    x = np.array([ONSET * (1 - 1e-9), ONSET * (1 + 1e-9), 1.0, 1.5, 0.5])
    d = porosity_ceiling(Dual.variables([x])[0], ONSET)
    slope = d.d[..., 0]
    assert slope[0] == 1.0 and slope[1] == pytest.approx(1.0, abs=1e-7)
    delta = 1.0 - ONSET
    assert slope[2] == pytest.approx(delta**2 / (2 * delta - (1 - x[2])) ** 2, rel=1e-12)  # 1/4 at φ_lin = 1
    eps = 1e-9
    fd = (porosity_ceiling(x + eps, ONSET) - porosity_ceiling(x - eps, ONSET)) / (2 * eps)
    assert np.allclose(slope, fd, rtol=1e-5)


def test_porosity_law_applies_the_ceiling_only_when_given_and_after_the_floor():
    phi0, ev, p = np.full(5, 0.4), np.array([-1.0, 0.0, 0.5, 1.0, 2.0]), np.zeros(5)
    lin = porosity(phi0, ev, p, 1600.0)
    assert np.array_equal(lin, 0.4 + 0.6 * ev)
    assert lin.max() > 1.0  # the paper's law: above 1 in strong dilation
    both = porosity(phi0, ev, p, 1600.0, floor=0.1, ceiling=ONSET)
    assert both[1] == lin[1] and both[2] == lin[2]
    assert both[0] == pytest.approx(0.1**2 / (0.2 - lin[0]), rel=1e-14) and np.all(both[3:] < 1.0)


def test_jacobian_stays_exact_where_the_ceiling_is_active():
    slopes, paper = taylor_slopes_under_compaction(Parameters(porosity_ceiling=ONSET), "phi", dilation=True)
    assert np.all(slopes > 1.9), slopes
    assert (paper > ONSET).mean() > 0.2  # the test exercises the ceiling


def test_ceiling_is_off_by_default_absent_from_old_dicts_and_validated():
    assert Parameters().porosity_ceiling is None and "porosity_ceiling" not in Parameters().to_dict()
    assert Parameters(porosity_ceiling=np.float32(0.99)).to_dict()["porosity_ceiling"] == pytest.approx(0.99)
    for bad in (0.5, 0.6, 1.0, 1.2):  # the largest initial porosity is phi_mean + phi_range = 0.6
        with pytest.raises(ValueError, match=f"porosity_ceiling={bad!r}"):
            Parameters(porosity_ceiling=bad)
    assert Parameters.from_dict(Parameters(porosity_ceiling=0.95).to_dict()) == Parameters(porosity_ceiling=0.95)


def test_run_with_the_ceiling_keeps_its_volume_balance():
    """An onset just above the largest initial porosity (0.6): the dilated zone at the cavity passes it early."""
    par = Parameters(porosity_ceiling=0.62)
    res = simulate(par, RunOptions(h=4.0, t_end=0.05, snapshot_times=(), write_xdmf=False))
    assert res.status == "ok", res.reason
    assert res.timeseries.mass_error.max() < 1e-9
    f = res.snapshots[-1][1]
    assert f["phi"].max() < 1.0
    active = f["phi"] > par.porosity_ceiling
    assert active.sum() >= 3, active.sum()

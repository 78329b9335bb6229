"""The state-change step controller (``RunOptions.dt_change_target``, ``solver.simulate._next_dt``) against known
properties: its formula; the step sequence depends on the accepted states only, so Anderson acceleration (which
changes the Newton iteration counts) leaves the run unchanged to the Newton tolerance; and backward Euler with
steps proportional to the target converges at first order in the target."""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate
from solver.simulate import _next_dt

SHORT = dict(h=6.0, t_end=0.1, dt0=1e-3, snapshot_times=[], write_xdmf=False)


def _info(change, newton_its=5, stagger_its=2):
    return {"step_change": change, "newton_its": newton_its, "stagger_its": stagger_its}


def test_the_formula_and_its_limits():
    o = RunOptions(dt_change_target=0.1, dt_grow=1.5)
    assert _next_dt(o, 1e-3, _info(0.1)) == pytest.approx(1e-3)          # the target reached: dt kept
    assert _next_dt(o, 1e-3, _info(0.3)) == pytest.approx(0.5e-3)        # 2c / (3c + c)
    assert _next_dt(o, 1e-3, _info(0.0)) == pytest.approx(1.5e-3)        # 2c / c = 2, capped by dt_grow
    # the iteration counts do not enter
    assert _next_dt(o, 1e-3, _info(0.05, newton_its=1)) == _next_dt(o, 1e-3, _info(0.05, newton_its=200, stagger_its=9))
    # the controller of earlier runs counts them
    o = RunOptions(step_control="iterations")
    assert _next_dt(o, 1e-3, _info(0.05, newton_its=1)) == pytest.approx(1.5e-3)
    assert _next_dt(o, 1e-3, _info(0.05, newton_its=200)) == pytest.approx(1e-3)


def test_the_options_are_validated_and_round_trip():
    for bad in (0.0, -0.1, 1.5, float("nan"), "0.1", None):
        with pytest.raises(ValueError, match="dt_change_target"):
            RunOptions(dt_change_target=bad)
    with pytest.raises(ValueError, match="step_control"):
        RunOptions(step_control="error")
    o = RunOptions(step_control="iterations", dt_change_target=0.05)
    assert RunOptions.from_dict(o.to_dict()) == o


def test_the_step_sequence_does_not_depend_on_the_nonlinear_iterations():
    """h = 6 mm to 0.1 s from the adaptive start: with the state-change controller, the run with Anderson
    acceleration takes the same steps (to the Newton tolerance, 1e-6 relative per update) and gives the same
    p_inj, with fewer Newton iterations."""
    plain = simulate(Parameters(), RunOptions(**SHORT, dt_change_target=0.1, anderson_depth=0))
    accel = simulate(Parameters(), RunOptions(**SHORT, dt_change_target=0.1, anderson_depth=3))
    assert plain.status == accel.status == "ok"
    assert len(plain.timeseries) == len(accel.timeseries)
    np.testing.assert_allclose(accel.timeseries["t"], plain.timeseries["t"], rtol=1e-5)
    np.testing.assert_allclose(accel.timeseries["p_inj"], plain.timeseries["p_inj"], rtol=1e-5)
    assert accel.timeseries["newton_its"].sum() < plain.timeseries["newton_its"].sum()
    # the measure the controller reads is the one the time series reports
    assert np.all(plain.timeseries["step_change"].between(0.0, 1.0))


def test_backward_euler_converges_at_first_order_in_the_target():
    """Steps scale with the target c (dt ≈ c / |∂S/∂t|), so backward Euler's error in p_inj at t = 0.1 s is
    O(c): halving c twice, the second difference of p_inj is half the first (ratio 0.5; the band allows the
    pre-asymptotic range and the last step cut to t_end)."""
    p = [simulate(Parameters(), RunOptions(**SHORT, dt_change_target=c)).timeseries["p_inj"].iloc[-1]
         for c in (0.1, 0.05, 0.025)]
    ratio = (p[2] - p[1]) / (p[1] - p[0])
    assert 0.35 < ratio < 0.7


@pytest.mark.parametrize("tol", [1e-8, 1e-11])
def test_the_balance_test_bounds_the_reported_volume_balance(tol):
    """Newton's balance test (``newton_mass_tol``, ``Simulation.balanced``) bounds each step's global defect by
    tol x the injection rate, so the cumulative relative error of the volume balance that ``timeseries.csv``
    reports (injected = stored change + source + outflow, each measured independently) is at most tol, on the
    graded mesh and porosity floor of tests/test_porosity_floor.py."""
    res = simulate(Parameters(porosity_floor=0.19),
                   RunOptions(h=4.0, h_outer=0.5, t_end=0.05, snapshot_times=(), write_xdmf=False, newton_mass_tol=tol))
    assert res.status == "ok", res.reason
    assert res.timeseries["mass_error"].max() <= tol * (1 + 1e-6) + 1e-14


def test_outputs_are_smooth_in_a_parameter():
    """The step sequence is a continuous function of the parameters, so p_inj is smooth in them and finite
    differences see its derivative: the two one-sided difference quotients of p_inj(0.3 s) in E (steps of 1 %,
    h = 6 mm) agree to 2 % (their difference is the curvature times the step; a controller whose steps jump with
    the iteration counts makes it as large as the slope's own jumps)."""
    E0 = Parameters().E
    p = [simulate(Parameters(E=E0 * f), RunOptions(h=6.0, t_end=0.3, snapshot_times=[], write_xdmf=False))
         .timeseries["p_inj"].iloc[-1] for f in (0.99, 1.0, 1.01)]
    left, right = p[1] - p[0], p[2] - p[1]
    assert abs(right - left) < 0.02 * abs(left)

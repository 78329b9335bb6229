"""The first stagger iteration solved to a looser Newton tolerance (RunOptions.first_stagger_rtol).

Known answers: on a fixed sequence of steps the run matches the one with every stagger iteration at
``newton_rtol`` to a few Newton tolerances (with a stagger tolerance tight enough not to mask them); the first
iteration never ends a step."""
import numpy as np
import pytest

from solver import Parameters, RunOptions, simulate

FIXED = dict(h=6.0, t_end=0.05, dt0=2e-3, dt_max=2e-3, dt_grow=1.0, step_control="iterations", snapshot_times=[],
             write_xdmf=False)


def test_loose_first_iteration_gives_the_same_run():
    """Both runs with stagger_tol = 1e-6, so that the stagger's own tolerance (which lets two schemes that meet it
    differ by up to 1e-3 in p_inj at the first step with the default 1e-4) does not mask the Newton tolerance."""
    tight = dict(FIXED, stagger_tol=1e-6)
    full = simulate(Parameters(), RunOptions(**tight))
    loose = simulate(Parameters(), RunOptions(**tight, first_stagger_rtol=1e-3))
    assert full.status == loose.status == "ok" and not full.rejected_steps and not loose.rejected_steps
    np.testing.assert_allclose(loose.timeseries["t"], full.timeseries["t"], rtol=1e-12)
    p0, p1 = full.timeseries["p_inj"].to_numpy(), loose.timeseries["p_inj"].to_numpy()
    assert np.max(np.abs(p1 / p0 - 1.0)) < 1e-6  # a few newton_rtol
    assert (loose.timeseries["stagger_its"] >= 2).all()  # the loose first iteration never ends a step
    assert loose.timeseries["newton_its"].sum() < full.timeseries["newton_its"].sum()


@pytest.mark.parametrize("bad", [1e-7, 0.5, -1.0, 0.0])
def test_bad_first_stagger_tolerance_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="first_stagger_rtol"):
        RunOptions(first_stagger_rtol=bad)


def test_default_is_off_and_left_out_of_the_run_keys():
    assert RunOptions().first_stagger_rtol is None and "first_stagger_rtol" not in RunOptions().to_dict()
    assert RunOptions.from_dict(RunOptions(first_stagger_rtol=1e-3).to_dict()).first_stagger_rtol == 1e-3

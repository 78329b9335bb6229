"""The named models of solver.presets (issue #47, item 2): the paper's model is the defaults, the experiment's
rate follows from the measured pump rate and geometry, and the presets reach the CLI and campaign specs."""
import argparse
import math

import pytest

from solver import Parameters
from solver.presets import measured_injection_velocity, preset_names, preset_parameters


def test_paper_preset_is_the_defaults():
    assert preset_parameters("paper") == Parameters()


def test_experiment_rate_is_the_pump_rate_over_the_inlet_surface():
    # 100 mL/min = 1666.7 mm³/s through the lateral surface 2π · 5 mm · 1.96 mm = 61.58 mm²
    assert measured_injection_velocity() == pytest.approx(100e3 / 60 / (2 * math.pi * 5.0 * 1.96), rel=1e-15)
    assert round(measured_injection_velocity(), 2) == 27.07
    p = preset_parameters("experiment")
    assert p.w_i == measured_injection_velocity()
    assert (p.outer_saturation_bc, p.mu_outer_bc) == ("outflow", "zero_flux")
    assert preset_parameters("experiment", kbar=0.01).kbar == 0.01  # changes go on top
    with pytest.raises(ValueError, match="flow_rate=0"):
        measured_injection_velocity(flow_rate=0.0)


def test_unknown_preset_names_the_allowed_ones():
    with pytest.raises(ValueError, match=r"preset 'lab' is not defined; allowed: \['paper', 'experiment'\]"):
        preset_parameters("lab")
    assert preset_names() == ["paper", "experiment"]


def test_preset_reaches_the_run_command_and_campaign_specs(tmp_path):
    from sweep.cli import _run_inputs
    from sweep.campaign.spec import SpecError, spec_from_dict

    args = argparse.Namespace(config=None, set=["kbar=0.01"], h=None, t_end=None, out=str(tmp_path / "run"),
                              preset="experiment")
    params, _, _ = _run_inputs(args)
    assert params == preset_parameters("experiment", kbar=0.01)
    spec = spec_from_dict({"name": "c", "base": {"preset": "experiment", "kbar": 0.01}, "axes": {"seed": [0, 1]}})
    assert Parameters(**spec.params) == preset_parameters("experiment", kbar=0.01)
    with pytest.raises(SpecError, match="base.preset"):
        spec_from_dict({"name": "c", "base": {"preset": "lab"}, "axes": {"seed": [0]}})


def test_a_campaign_sweeps_a_parameter_its_preset_sets_and_the_axis_wins():
    """A preset's parameters are defaults of the [base] layer, as a model file's: an axis over one of them (the
    experiment preset's measured w_i) replaces it, a [base] key on top of it still may not be swept."""
    from sweep.campaign.spec import spec_from_dict
    from sweep.campaign.spec_model import SpecError
    from sweep.campaign.sampler import grid_points

    spec = spec_from_dict({"name": "x", "base": {"preset": "experiment"}, "axes": {"w_i": [10.0, 20.0]}})
    assert "w_i" not in spec.params and spec.params["outer_saturation_bc"] == "outflow"
    assert sorted(p.params["w_i"] for p in grid_points(spec)) == [10.0, 20.0]
    with pytest.raises(SpecError, match="'w_i' is both swept and set in base"):
        spec_from_dict({"name": "x", "base": {"preset": "experiment", "w_i": 5.0}, "axes": {"w_i": [10.0]}})

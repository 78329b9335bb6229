"""A single-condition data set with held-out observables (sweep/discrepancy/heldout.py, ``[holdout]
observables``): the split keeps every curve exactly once, the spec checks the table, and on the toy a hidden
damage viscosity is named from one condition's pressure and front radius with the crack length held out
(the known answer: the twin's hidden strength; the held-out gap at least halves).  Units kPa, mm, s."""
import numpy as np
import pytest

from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict
from sweep.discrepancy.heldout import HELD_SUFFIX, split_observables

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}
TIMES = np.linspace(0.02, 1.0, 50)


def _one(tmp_path, hidden):
    return load_measured(make_twin(tmp_path / "data", ToyForward(BASE, h=2.0), {"exp": {"w_i": 50.0}}, TIMES,
                                   hidden, seed=4, observables=("p_inj", "front_radius_mean", "crack_length")))


def _spec(holdout):
    return spec_from_dict({"baseline": {"effects_off": OFF},
                           "calibrate": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
                           "candidates": {"effects": ["damage_viscosity", "crack_permeability"]},
                           "holdout": holdout, "options": {"h": 8.0, "t_end": 1.0}})


def test_split_moves_the_listed_observables_to_a_twin_condition(tmp_path):
    data = _one(tmp_path, {"beta": 40.0})
    s = split_observables(data, ["crack_length"])
    assert s.ids == ["exp", "exp" + HELD_SUFFIX]
    assert s.condition_params("exp" + HELD_SUFFIX) == data.condition_params("exp")
    assert set(s.curves[s.curves.condition == "exp"].observable) == {"p_inj", "front_radius_mean"}
    assert set(s.curves[s.curves.condition == "exp" + HELD_SUFFIX].observable) == {"crack_length"}
    assert len(s.curves) == len(data.curves) and split_observables(s, ["crack_length"]) is s
    with pytest.raises(ValueError, match="not measured"):
        split_observables(data, ["front_radius_branches"])
    with pytest.raises(ValueError, match="would keep no observable"):
        split_observables(data, ["p_inj", "front_radius_mean", "crack_length", "regime"])
    with pytest.raises(ValueError, match="holdout.observables"):
        _spec({"observables": ["pressure"]})
    with pytest.raises(ValueError, match="not both"):
        _spec({"ids": ["exp"], "observables": ["crack_length"]})


def test_one_condition_names_the_hidden_effect_with_the_crack_length_held_out(tmp_path):
    data = _one(tmp_path, {"beta": 40.0})
    rep = run_workflow(data, _spec({"observables": ["crack_length"]}), ToyForward({}, h=8.0), out_dir=tmp_path / "out",
                       figures=False)
    assert rep["train"] == ["exp"] and rep["holdout"] == ["exp" + HELD_SUFFIX]
    assert rep["verdict"] == "named" and rep["named_effect"] == "damage_viscosity"
    lo, hi = rep["strength_interval"]
    assert lo <= 40.0 <= hi
    assert rep["gap_after"]["total"] <= 0.5 * rep["gap_before"]["total"]

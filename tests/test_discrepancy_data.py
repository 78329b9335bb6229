"""Effects catalogue, measured-data format and loader, spec validation (no solver runs)."""
import numpy as np
import pandas as pd
import pytest

from solver import Parameters
from solver.effects import EFFECTS, effect_strength, get_effect, is_off, off_effects, switch_off
from sweep.discrepancy.data import load_measured, write_measured
from sweep.discrepancy.spec import spec_from_dict


def test_catalogue_has_the_five_effects_with_exact_off_values():
    assert set(EFFECTS) >= {"damage_viscosity", "volumetric_coupling", "korteweg_stress", "compliant_boundary",
                            "crack_permeability"}
    names = {f for f in Parameters.__dataclass_fields__}
    for name, e in EFFECTS.items():
        param, off, desc, sig = e[:4]
        assert param in names and off == 0.0 and desc and sig
        assert e.off < e.probe <= e.upper
    p = switch_off(Parameters(), *EFFECTS)
    assert p.beta == 0.0 and p.volumetric_coupling == 0.0 and p.korteweg_factor == 0.0
    assert p.outer_compliance == 0.0 and p.crack_permeability == 0.0
    assert sorted(off_effects(p)) == sorted(EFFECTS)
    # the paper's model: β follows 65.7 √C, the outer wall, the cell and the line rigid (= off), the water mobile
    # at any saturation (no critical saturation, = off), the others on
    ref = Parameters(cement=1.44)
    assert effect_strength(ref, "damage_viscosity") == pytest.approx(65.7 * 1.2)
    assert off_effects(ref) == ["compliant_boundary", "elastic_cell", "line_compliance", "critical_saturation"]
    assert not is_off(ref, "damage_viscosity")
    with pytest.raises(ValueError, match="not in the catalogue"):
        get_effect("gravity")


def _write(tmp_path, cond_text, obs_text):
    (tmp_path / "conditions.csv").write_text(cond_text)
    (tmp_path / "observations.csv").write_text(obs_text)
    return tmp_path


GOOD_C = "id,w_i\nc1,30\nc2,50\n"
GOOD_O = ("condition,observable,time,value,uncertainty\n"
          "c1,p_inj,0.1,10,1\nc1,p_inj,0.2,20,1\nc2,front_radius_mean,0.1,7.5,0.2\nc2,regime,0.2,fracturing,0\n")


def test_loader_reads_a_valid_folder(tmp_path):
    d = load_measured(_write(tmp_path, GOOD_C, GOOD_O))
    assert d.ids == ["c1", "c2"]
    assert d.condition_params("c1") == {"w_i": 30.0}
    assert d.times("c1", "p_inj").tolist() == [0.1, 0.2]
    assert d.regimes == {"c2": (0.2, "fracturing")}
    assert len(d.curves) == 3


@pytest.mark.parametrize("cond,obs,match", [
    (GOOD_C, GOOD_O.replace("uncertainty", "sd"), r"observations.csv, row 1, column 'uncertainty': missing column"),
    (GOOD_C, GOOD_O.replace("c1,p_inj,0.2,20,1", "c1,pressure,0.2,20,1"), r"row 3, column 'observable': unknown observable 'pressure'"),
    (GOOD_C, GOOD_O.replace("c1,p_inj,0.2,20,1", "c1,p_inj,0.2,nan,1"), r"row 3, column 'value': 'nan' is not a finite"),
    (GOOD_C, GOOD_O.replace("c1,p_inj,0.2,20,1", "c1,p_inj,0.2,20,-1"), r"row 3, column 'uncertainty': negative uncertainty"),
    (GOOD_C, GOOD_O.replace("c1,p_inj,0.2,20,1", "c1,p_inj,0.2,20,0"), r"row 3, column 'uncertainty': zero uncertainty"),
    (GOOD_C, GOOD_O.replace("c1,p_inj,0.2,20,1", "c9,p_inj,0.2,20,1"), r"row 3, column 'condition': unknown condition 'c9'"),
    (GOOD_C + "c3,70\n", GOOD_O, r"conditions.csv, row 4, column 'id': condition 'c3' has no observations"),
    ("name,w_i\nc1,30\n", GOOD_O, r"conditions.csv, row 1, column 'id': missing column"),
    ("id,wi\nc1,30\n", GOOD_O, r"column 'wi': unknown column"),
    ("id,w_i\nc1,-5\nc2,50\n", GOOD_O, r"conditions.csv, row 2.*w_i=-5"),
    ("id,w_i\nc1,30\nc1,50\n", GOOD_O, r"row 3, column 'id': duplicated id"),
])
def test_loader_errors_name_file_row_and_column(tmp_path, cond, obs, match):
    with pytest.raises(ValueError, match=match):
        load_measured(_write(tmp_path, cond, obs))


def test_missing_file_is_named(tmp_path):
    (tmp_path / "conditions.csv").write_text(GOOD_C)
    with pytest.raises(ValueError, match="observations.csv: file not found"):
        load_measured(tmp_path)


def test_writer_round_trip(tmp_path):
    curves = pd.DataFrame({"condition": ["a", "a", "b"], "observable": ["p_inj", "p_inj", "crack_length"],
                           "time": [0.1, 0.2, 0.1], "value": [1.5, 2.5, 0.0], "uncertainty": [0.5, 0.5, 0.3]})
    write_measured(tmp_path, {"a": {"w_i": 40.0}, "b": {"w_i": 60.0, "cement": 2.0}}, curves, {"b": (0.1, "porous_invasion")})
    d = load_measured(tmp_path)
    assert d.condition_params("b") == {"w_i": 60.0, "cement": 2.0}
    assert d.condition_params("a") == {"w_i": 40.0}
    np.testing.assert_array_equal(d.curves.value.to_numpy(), [1.5, 2.5, 0.0])
    assert d.regimes["b"] == (0.1, "porous_invasion")


BASE_SPEC = {"baseline": {"effects_off": ["damage_viscosity"]},
             "calibrate": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
             "holdout": {"every": 3}, "options": {"h": 8.0, "t_end": 0.1}}


def test_spec_validation():
    s = spec_from_dict(BASE_SPEC)
    assert s.candidates == ("damage_viscosity",)
    assert s.baseline_overrides() == {"beta": 0.0}
    assert s.holdout(["a", "b", "c", "d", "e", "f", "g"]) == ["a", "d", "g"]
    assert s.calibrate[0].initial == 0.0015 and s.calibrate[0].x_step == pytest.approx(0.02)
    for bad, match in [({"calibrate": [{"name": "beta", "lower": 0, "upper": 1}]}, "not an effect strength"),
                       ({"calibrate": [{"name": "kbar", "lower": 5e-3, "upper": 5e-4}]}, "lower < upper"),
                       ({"candidates": {"effects": ["crack_permeability"]}}, "off in the baseline"),
                       ({"holdout": {}}, "whole conditions"),
                       ({"options": {"h": -1.0}}, r"\[options\]"),
                       ({"fit": {"delta_bik": -10}}, r"\[fit\] \[.delta_bik.\] unknown")]:
        with pytest.raises(ValueError, match=match):
            spec_from_dict({**BASE_SPEC, **bad})

"""The discrepancy workflow's named model carried into campaigns (issue #47 item 7): ``dchfrac discrepancy model``
writes the model a report names, and a campaign's ``[base] model = ...`` takes it as if typed in ``[base]``.

The written parameters are checked against the workflow's own forward-run overrides
(sweep.discrepancy.problem.values_to_overrides) on the same values; a campaign with the file against the same
campaign with the values typed (parameters and run keys)."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from solver.tomlio import read_toml, toml_value
from sweep.campaign.sampler import grid_points
from sweep.campaign.spec import SpecError, load_spec as load_campaign
from sweep.campaign.store import run_key
from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow
from sweep.discrepancy.named_model import read_report, write_named_model
from sweep.discrepancy.problem import values_to_overrides
from sweep.discrepancy.spec import load_spec

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
SPEC = """
[baseline]
porosity_floor = 0.1          # mm-free: a baseline value the named model keeps
outer_saturation_bc = "outflow"
effects_off = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
[[calibrate]]
name = "kbar"
lower = 5e-4
upper = 5e-3
[[calibrate]]
name = "E"
lower = 150.0
upper = 700.0
[candidates]
effects = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
scaling = { damage_viscosity = "sqrt_cement" }
[holdout]
ids = ["d"]
[options]
h = 8.0
t_end = 1.0
"""
CONDS = {"a": {"w_i": 30.0, "cement": 1.0}, "b": {"w_i": 50.0, "cement": 2.0}, "c": {"w_i": 70.0, "cement": 1.5},
         "d": {"w_i": 40.0, "cement": 1.2}}


def _spec_file(tmp_path, text=SPEC) -> Path:
    p = tmp_path / "spec.toml"
    p.write_text(text)
    return p


def _report(tmp_path, verdict="named", effect="compliant_boundary", strength=0.0512, **extra) -> Path:
    """A minimal report.json of the fields the named model reads (as build_report writes them)."""
    final = {"kbar": 0.0021, "E": 412.5}
    if verdict == "named":
        final["effect:" + effect] = strength
    rep = {"verdict": verdict, "named_effect": effect if verdict == "named" else None,
           "strength": strength if verdict == "named" else None,
           "strength_interval": [0.9 * strength, 1.1 * strength] if verdict == "named" else None,
           "strength_scaling": "none", "tie": [], "calibrated_baseline": {"kbar": 0.002, "E": 400.0},
           "final_values": final, "code": {"solver": "abc123", "workflow": "def456"}, **extra}
    p = tmp_path / "out" / "report.json"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(rep))
    return p


def _measured(tmp_path, conds=CONDS) -> Path:
    return make_twin(tmp_path / "data", ToyForward({}, h=2.0), conds, np.linspace(0.05, 1.0, 5), {}, seed=1,
                     observables=("p_inj",))


def _workflow_overrides(spec, values, cond) -> dict:
    return values_to_overrides(spec, spec.baseline_overrides(), cond, values)


@pytest.fixture(scope="module")
def toy_named(tmp_path_factory):
    """A real (toy) discrepancy run naming compliant_boundary: its report, SPEC, measured data."""
    tmp = tmp_path_factory.mktemp("toy")
    conds = {k: {"w_i": v["w_i"]} for k, v in CONDS.items()}
    data = make_twin(tmp / "data", ToyForward({"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0,
                                               "volumetric_coupling": 0.0}, h=2.0), conds, np.linspace(0.02, 1.0, 50),
                     {"outer_compliance": 0.05}, seed=1, observables=("p_inj", "front_radius_mean", "crack_length"))
    spec_path = _spec_file(tmp)
    rep = run_workflow(load_measured(data), load_spec(spec_path), ToyForward({}, h=8.0), out_dir=tmp / "out",
                       figures=False)
    assert rep["verdict"] == "named" and rep["named_effect"] == "compliant_boundary"
    return tmp / "out" / "report.json", spec_path, data


def test_written_model_is_the_workflows_forward_run_model(toy_named, tmp_path):
    report, spec_path, data = toy_named
    out, verdict = write_named_model(report, spec_path, data, tmp_path / "named_model.toml")
    written, spec, md = read_toml(out), load_spec(spec_path), load_measured(data)
    values = json.loads(report.read_text())["final_values"]
    for cid in md.ids:              # the file plus a condition is what the workflow ran for that condition
        cond = md.condition_params(cid)
        assert {**written, **cond} == _workflow_overrides(spec, values, cond)
    assert "w_i" not in written and written["outer_compliance"] == values["effect:compliant_boundary"] > 0
    assert written["kbar"] == values["kbar"] and written["beta"] == 0.0 and written["porosity_floor"] == 0.1
    assert json.loads(report.read_text())["condition_columns"] == ["w_i"]      # recorded by the workflow:
    bare = write_named_model(report, spec_path, None, tmp_path / "bare.toml")[0]   # --measured not needed
    assert read_toml(bare) == written
    text = out.read_text()
    assert f"Report: {report}" in text and "verdict: named" in text and "#   w_i: a condition column" in text
    assert json.loads(report.read_text())["code"]["solver"] in text and "units mm, s, kPa" in text


def test_an_effect_scaled_by_a_condition_column_is_left_out_and_its_law_stated(tmp_path):
    rep = _report(tmp_path, effect="damage_viscosity", strength=61.5)
    out, _ = write_named_model(rep, _spec_file(tmp_path), _measured(tmp_path), tmp_path / "m.toml")
    written = read_toml(out)
    assert "beta" not in written and "cement" not in written and "w_i" not in written
    assert "beta = 61.5 * sqrt(cement)" in out.read_text()
    spec = load_spec(tmp_path / "spec.toml")
    values = json.loads(rep.read_text())["final_values"]
    for cond in CONDS.values():      # with β = c √C per condition, the file gives the workflow's runs
        want = _workflow_overrides(spec, values, cond)
        assert {**written, **cond, "beta": 61.5 * math.sqrt(cond["cement"])} == want


def test_an_effect_scaled_by_a_baseline_cement_is_written_at_it(tmp_path):
    rep = _report(tmp_path, effect="damage_viscosity", strength=61.5)
    data = _measured(tmp_path, {k: {"w_i": v["w_i"]} for k, v in CONDS.items()})
    written = read_toml(write_named_model(rep, _spec_file(tmp_path), data, tmp_path / "m.toml")[0])
    spec = load_spec(tmp_path / "spec.toml")
    assert written["beta"] == _workflow_overrides(spec, json.loads(rep.read_text())["final_values"], {})["beta"]
    assert written["beta"] == pytest.approx(61.5 * math.sqrt(1.2), rel=1e-15)     # Parameters' default C = 1.2 %


def test_no_effect_named_writes_the_calibrated_baseline_and_says_so(tmp_path):
    rep = _report(tmp_path, verdict="no_missing_effect")
    out, verdict = write_named_model(rep, _spec_file(tmp_path), _measured(tmp_path), tmp_path / "m.toml")
    written = read_toml(out)
    assert verdict == "no_missing_effect" and "No effect named: the calibrated baseline only" in out.read_text()
    assert (written["kbar"], written["E"], written["beta"], written["outer_compliance"]) == (0.0021, 412.5, 0.0, 0.0)


@pytest.mark.parametrize("edit,msg", [
    ("missing", "not found"),
    ("tie", "'tie' between ['compliant_boundary', 'damage_viscosity']"),
    ("inconclusive", "verdict 'inconclusive' carries no model"),
    ("unknown_effect", "effect 'bogus' is not in the catalogue"),
    ("not_candidate", "not a candidate of the model SPEC"),
    ("unknown_param", "'kbarr' is not a solver.Parameters field"),
    ("no_columns", "does not record its condition columns .*: give --measured DIR"),
])
def test_bad_reports_are_refused_with_a_clear_error(tmp_path, edit, msg):
    rep = _report(tmp_path)
    d = json.loads(rep.read_text())
    if edit == "missing":
        rep = tmp_path / "nowhere" / "report.json"
    elif edit in ("tie", "inconclusive"):
        d.update(verdict=edit, tie=["compliant_boundary", "damage_viscosity"] if edit == "tie" else [])
    elif edit == "unknown_effect":
        d["final_values"]["effect:bogus"] = 1.0
    elif edit == "not_candidate":
        d["final_values"]["effect:elastic_cell"] = 1e-4
    elif edit == "unknown_param":
        d["final_values"]["kbarr"] = 1.0
    if edit != "missing":
        rep.write_text(json.dumps(d))
    out = tmp_path / "m.toml"
    pattern = msg if edit == "no_columns" else msg.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")
    with pytest.raises(ValueError, match=pattern):
        write_named_model(rep, _spec_file(tmp_path), None if edit == "no_columns" else _measured(tmp_path), out)
    assert not out.exists()


def test_cli_writes_the_model_and_refuses_a_tie_in_one_line(tmp_path, capsys):
    from sweep.cli import main

    rep, spec, data = _report(tmp_path), _spec_file(tmp_path), _measured(tmp_path)
    args = ["discrepancy", "model", "--report", str(rep), "--model", str(spec), "--measured", str(data)]
    assert main([*args, "--out", str(tmp_path / "m.toml")]) == 0
    assert read_toml(tmp_path / "m.toml")["outer_compliance"] == 0.0512
    assert "[base] model" in capsys.readouterr().out
    d = json.loads(rep.read_text())
    d.update(verdict="tie", tie=["compliant_boundary", "damage_viscosity"])
    rep.write_text(json.dumps(d))
    assert main([*args, "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tie" in err[0] and "damage_viscosity" in err[0] and not (tmp_path / "t.toml").exists()


# ----------------------------------------------------------------------------- campaigns: [base] model = ...
CAMPAIGN = """
name = "named_probe"
[base]
{base}
[options]
h = 4.0
t_end = 0.1
[axes]
w_i = [30.0, 60.0]
cement = [1.2, 2.0]
"""


def _campaign(folder: Path, base: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / "spec.toml"
    p.write_text(CAMPAIGN.format(base=base))
    return p


def _keys(spec) -> list:
    return [run_key(p.params, p.options) for p in grid_points(spec)]


def test_campaign_with_the_model_file_is_the_campaign_with_the_values_typed(tmp_path):
    rep = _report(tmp_path)
    model = write_named_model(rep, _spec_file(tmp_path), _measured(tmp_path), tmp_path / "models" / "m.toml")[0]
    typed = "\n".join(f"{k} = {toml_value(v)}" for k, v in read_toml(model).items() if k != "kbar")
    by_file = load_campaign(_campaign(tmp_path / "studies", 'model = "../models/m.toml"\nkbar = 0.003'))
    by_hand = load_campaign(_campaign(tmp_path / "typed", typed + "\nkbar = 0.003"))
    assert by_file.params == by_hand.params and by_file.params["kbar"] == 0.003       # [base] keys win
    assert by_file.params["outer_compliance"] == 0.0512
    assert _keys(by_file) == _keys(by_hand) and len(set(_keys(by_file))) == 4


def test_campaign_refuses_a_missing_or_bad_model_file_naming_the_key_and_path(tmp_path):
    with pytest.raises(SpecError, match=r"base\.model: model file 'none\.toml' not found .*allowed: a flat TOML"):
        load_campaign(_campaign(tmp_path / "a", 'model = "none.toml"'))
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "bad.toml").write_text("kbar = 0.002\nkbarr = 1.0\n")
    with pytest.raises(SpecError, match=r"base\.model: .*bad\.toml' sets 'kbarr', which is not a model parameter"):
        load_campaign(_campaign(tmp_path / "b", 'model = "bad.toml"'))
    with pytest.raises(SpecError, match=r"base\.model: expected a path"):
        load_campaign(_campaign(tmp_path / "c", "model = 3"))


def test_a_block_takes_its_own_model_file(tmp_path):
    from sweep.campaign.spec import spec_from_dict

    (tmp_path / "m.toml").write_text("kbar = 0.0025\n")
    spec = spec_from_dict({"name": "blk", "options": {"h": 4.0, "t_end": 0.1},
                           "blocks": [{"label": "x", "base": {"model": "m.toml"}, "axes": {"w_i": [30.0, 60.0]}},
                                      {"label": "y", "axes": {"w_i": [30.0]}}]},
                          source=str(_campaign(tmp_path, "")))
    assert spec.blocks[0].params == {"kbar": 0.0025} and spec.blocks[1].params == {}
    with pytest.raises(SpecError, match=r"blocks\[0\]\.base\.model: model file 'x\.toml' not found"):
        spec_from_dict({"name": "blk", "blocks": [{"base": {"model": "x.toml"}, "axes": {"w_i": [30.0]}}]},
                       source=str(tmp_path / "spec.toml"))


def test_the_campaigns_spec_copy_reads_the_same_model_where_it_lies(tmp_path):
    from sweep.campaign.base_model import spec_copy_text

    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "m.toml").write_text("kbar = 0.0025\nE = 400.0\n")
    src = _campaign(tmp_path / "studies", "model = '../models/m.toml'  # the named model\nE = 350.0")
    dest = tmp_path / "results" / "named_probe"
    (dest / "spec.toml").parent.mkdir(parents=True)
    (dest / "spec.toml").write_text(spec_copy_text(src, dest))
    copy = load_campaign(dest / "spec.toml")
    assert copy.params == load_campaign(src).params == {"kbar": 0.0025, "E": 350.0}
    assert _keys(copy) == _keys(load_campaign(src))
    assert 'model = "base_models/0_m.toml"  # the named model' in (dest / "spec.toml").read_text()
    assert spec_copy_text(dest / "spec.toml", dest) == (dest / "spec.toml").read_text()   # a copy's copy: itself
    plain = _campaign(tmp_path / "plain", "kbar = 0.002")
    assert spec_copy_text(plain, dest) == plain.read_text()


def test_a_parameter_the_grid_sets_replaces_the_files_value(tmp_path):
    """An N_f–N_b grid sweeps k̄ and a [derived] β = 65.7 √C replaces the file's: the file gives the rest."""
    (tmp_path / "m.toml").write_text("kbar = 0.0025\nE = 400.0\nbeta = 10.0\n")
    p = _campaign(tmp_path, 'model = "m.toml"')
    p.write_text(p.read_text().replace("w_i = [30.0, 60.0]", "kbar = [0.001, 0.01]")
                 + '[derived]\nbeta = "65.7*sqrt(cement)"\n')
    spec = load_campaign(p)
    assert spec.params == {"E": 400.0}
    pts = grid_points(spec)
    assert sorted({pt.params["kbar"] for pt in pts}) == [0.001, 0.01] and {pt.params["E"] for pt in pts} == {400.0}
    assert sorted({pt.params["beta"] for pt in pts}) == pytest.approx([65.7 * math.sqrt(c) for c in (1.2, 2.0)])

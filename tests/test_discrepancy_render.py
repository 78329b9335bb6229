"""``dchfrac discrepancy render``: report.md regenerated from report.json alone, with no forward run (a committed
discrepancy report regenerates on a fresh clone, whose forward-run cache is not committed).  The closed-form toy
forward model (sweep.discrepancy.toy).  Units mm, s, kPa."""
import numpy as np

from sweep.cli import build_parser
from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}
CONDS = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}


def _run(tmp_path):
    spec = spec_from_dict({"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
                           "candidates": {"effects": ["damage_viscosity"]}, "holdout": {"ids": ["d"]},
                           "options": {"h": 8.0, "t_end": 1.0}})
    data = load_measured(make_twin(tmp_path / "data", ToyForward(BASE, h=2.0), CONDS, np.linspace(0.02, 1.0, 20),
                                   {"beta": 40.0}, seed=1, observables=("p_inj", "front_radius_mean")))
    return run_workflow(data, spec, ToyForward({}, h=8.0), out_dir=tmp_path / "out", figures=False)


def _cli(argv):
    args = build_parser().parse_args(argv)
    return args.func(args)


def test_render_rewrites_the_report_byte_for_byte_and_redraws_the_profile_figure(tmp_path, capsys):
    rep = _run(tmp_path)
    assert rep["verdict"] == "named"
    out = tmp_path / "out"
    md = (out / "report.md").read_text()
    assert "profile_damage_viscosity.png" not in md           # figures=False: no figure, and no link to one
    (out / "report.md").write_text("stale")
    assert _cli(["discrepancy", "render", str(out)]) == 0
    assert (out / "report.md").read_text() == md and str(out / "report.md") in capsys.readouterr().out
    assert not (out / "profile_damage_viscosity.png").exists()
    assert _cli(["discrepancy", "render", "--figures", str(out)]) == 0
    assert (out / "profile_damage_viscosity.png").is_file()
    assert "![Profile likelihood of damage_viscosity](profile_damage_viscosity.png)" in (out / "report.md").read_text()


def test_render_refuses_a_folder_without_a_report_before_writing_any(tmp_path, capsys):
    _run(tmp_path)
    (tmp_path / "out" / "report.md").write_text("kept")
    (tmp_path / "empty").mkdir()
    assert _cli(["discrepancy", "render", str(tmp_path / "out"), str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err
    assert "empty" in err and "no report.json" in err
    assert (tmp_path / "out" / "report.md").read_text() == "kept"

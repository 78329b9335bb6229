"""A discrepancy verdict never rests on forward runs that did not reach the observation times (issue #48).

The forward model is the closed-form toy (sweep.discrepancy.toy) with a condition it "cannot run": every
prediction NaN for an injection velocity above 1e6 mm/s (as the solver fails at w_i = 1e9 mm/s), or NaN
after a time (a run that stopped early).  The fit steers away from failing points with its nan_residual
penalty, but no verdict may be drawn from those placeholders.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
TIMES = np.linspace(0.02, 1.0, 30)
CONDS = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}
DATA_BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}


class _Failing(ToyForward):
    """The toy, with no prediction (NaN) at w_i > 1e6 mm/s and, for w_i == ``short_w``, after ``short_after`` s."""

    def __init__(self, short_w=None, short_after=np.inf):
        super().__init__({}, h=8.0)
        self.short_w, self.short_after = short_w, short_after

    def predict_one(self, overrides, times):
        out = super().predict_one(overrides, times)
        for o in times:
            if o == "regime":
                continue
            if overrides["w_i"] > 1e6:
                out[o] = np.full(len(times[o]), np.nan)
            elif overrides["w_i"] == self.short_w:
                out[o] = np.where(np.asarray(times[o]) > self.short_after, np.nan, out[o])
        return out


def _spec():
    return spec_from_dict({"baseline": {"effects_off": OFF},
                           "calibrate": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3},
                                         {"name": "E", "lower": 150.0, "upper": 700.0}],
                           "candidates": {"effects": OFF}, "holdout": {"ids": ["d"]},
                           "options": {"h": 8.0, "t_end": 1.0}})


def _data(tmp_path, unrunnable=False):
    """Twin data of CONDS (with an outside effect: the toy's verdict is "unexplained_discrepancy"); with
    ``unrunnable``, condition c's injection velocity is then set to 1e9 mm/s, a condition the model cannot run."""
    fwd = ToyForward(DATA_BASE, h=2.0, anomaly=1.0)
    folder = make_twin(tmp_path / "data", fwd, CONDS, TIMES, {}, seed=1, observables=("p_inj", "front_radius_mean"))
    if unrunnable:
        conds = Path(folder) / "conditions.csv"
        conds.write_text(conds.read_text().replace("c,70.0", "c,1000000000.0"))
    return load_measured(folder)



def test_a_condition_without_a_successful_run_gives_no_verdict(tmp_path):
    rep = run_workflow(_data(tmp_path, unrunnable=True), _spec(), _Failing(), out_dir=tmp_path / "out", figures=False)
    assert rep["verdict"] == "inconclusive" and rep["named_effect"] is None
    failed = rep["failed_points"]["calibrated baseline"]
    assert failed == {"c": {"failed": 60, "points": 60}}         # 2 observables x 30 times, none reached
    assert rep["rounds"] == []                                    # no candidate screened on placeholders
    md = (tmp_path / "out" / "report.md").read_text()
    assert "No verdict" in md and "`c`: 60 of 60 points, no successful run" in md


def test_a_run_that_stops_early_gives_no_verdict_naming_its_points(tmp_path):
    rep = run_workflow(_data(tmp_path), _spec(), _Failing(short_w=50.0, short_after=0.5))
    assert rep["verdict"] == "inconclusive"
    n_late = int(np.sum(TIMES > 0.5)) * 2
    assert rep["failed_points"]["calibrated baseline"] == {"b": {"failed": n_late, "points": 60}}


def test_the_same_data_with_runs_that_reach_the_times_gives_a_verdict(tmp_path):
    """The control: the toy without failures draws the verdict the outside effect calls for."""
    rep = run_workflow(_data(tmp_path), _spec(), _Failing())
    assert rep["verdict"] == "unexplained_discrepancy" and rep["failed_points"] == {}


def test_cli_exits_3_with_one_line_per_stage_naming_the_condition(tmp_path, monkeypatch, capsys):
    import sweep.discrepancy.forward as forward
    from sweep.discrepancy.cli import EXIT_INCONCLUSIVE, main

    _data(tmp_path, unrunnable=True)
    spec = tmp_path / "spec.toml"
    spec.write_text('[baseline]\neffects_off = ["damage_viscosity", "compliant_boundary", "crack_permeability", '
                    '"volumetric_coupling"]\n[[calibrate]]\nname = "kbar"\nlower = 5e-4\nupper = 5e-3\n'
                    '[[calibrate]]\nname = "E"\nlower = 150.0\nupper = 700.0\n[candidates]\neffects = '
                    '["damage_viscosity"]\n[holdout]\nids = ["d"]\n[options]\nh = 8.0\nt_end = 1.0\n')
    monkeypatch.setattr(forward, "SolverForward", lambda *a, **k: _Failing())
    monkeypatch.setattr(forward, "fine_forwards", lambda *a, **k: [])
    code = main(["discrepancy", "run", "--measured", str(tmp_path / "data"), "--model", str(spec),
                 "--out", str(tmp_path / "out"), "--no-figures", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_INCONCLUSIVE == 3
    assert any("no verdict" in line and "condition 'c': 60 of 60 observation points (no successful run)" in line
               for line in err)
    assert json.loads((tmp_path / "out" / "report.json").read_text())["verdict"] == "inconclusive"

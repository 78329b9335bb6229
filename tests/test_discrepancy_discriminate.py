"""The measurements that would tell tied models apart (sweep.discrepancy.discriminate; issue #47 item 4).

Known answers on the closed-form toy (sweep.discrepancy.toy.ToyForward): the outer compliance rescales the
pressure as P0/(1 + 2c), exactly as k̄ does (P0 ∝ 1/k̄), but speeds the front by (1 + 20 c), which no k̄
does.  So on pressure data a compliance and a k̄ rival tie, and the front, which the data do not hold, is the
measurement that tells them apart: by 15 t (w_i/50) 20 c mm, largest at the last time and the highest rate.
Units mm, s, kPa.
"""
import math

import numpy as np
import pytest

from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict
from sweep.discrepancy.discriminate import _separation, discriminating_measurements
from sweep.discrepancy.observables import REGISTRY
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.report import _discriminating_lines

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
TIMES = np.linspace(0.02, 1.0, 50)
CONDS = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}
DATA_BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}


def _pressure_twin(tmp_path, hidden):
    fwd = ToyForward(DATA_BASE, h=2.0)
    return load_measured(make_twin(tmp_path / "data", fwd, CONDS, TIMES, hidden, seed=1, observables=("p_inj",)))


def test_a_compliance_tying_with_a_kbar_rival_is_told_apart_by_the_front(tmp_path):
    """k̄ 10 % high on pressure data: the compliance (c = 0.05 with the book k̄) and the k̄ rival tie; the
    report names the front at the highest rate and the last time, a measurement the data do not hold."""
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "alternative": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
         "candidates": {"effects": ["compliant_boundary", "damage_viscosity"]},
         "holdout": {"ids": ["d"]}, "options": {"h": 8.0, "t_end": 1.0}, "acceptance": {"min_ratio": 0.0}}
    rep = run_workflow(_pressure_twin(tmp_path, {"kbar": 0.00165}), spec_from_dict(d), ToyForward({}, h=8.0),
                       out_dir=tmp_path / "out", figures=False)
    assert rep["verdict"] == "tie" and rep["tie"] == ["compliant_boundary", "alternative:kbar"]
    rows = rep["discriminating_measurements"]
    best = rows[0]
    assert (best["observable"], best["condition"], best["measured"]) == ("front_radius_mean", "c", False)
    assert best["time"] == pytest.approx(1.0) and best["noise_source"] == "default"
    a, b = best["predictions"].values()
    assert best["separation"] == pytest.approx(abs(a - b) / REGISTRY["front_radius_mean"].default_noise)
    # the difference is 15 t (70/50) 20 c at t = 1 s, with 1 + 2c = 0.00165/0.0015 (the tie): c = 0.05
    assert abs(a - b) == pytest.approx(15 * 1.0 * 1.4 * 20 * 0.05, rel=0.05)
    # the pressure the data hold separates them by less than its noise: the tie is real
    assert all(r["observable"] != "p_inj" for r in rows if r["separation"] > 1.0)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "the measurements that would are listed below" in md
    assert "## The measurements that would tell them apart" in md and "| front_radius_mean | c | 1 |" in md


def test_the_separation_is_the_worst_pair_at_the_time_it_is_largest():
    preds = {"A": {"p_inj": [0.0, 1.0, 4.0]}, "B": {"p_inj": [0.0, 3.0, 0.0]}, "C": {"p_inj": [0.0, 2.0, 5.0]}}
    # pairs: |A-B| = 0,2,4; |A-C| = 0,1,1; |B-C| = 0,1,5 -> smallest per time 0,1,1 -> largest 1 at the 2nd time
    sep, k = _separation("p_inj", preds, 0.5)
    assert (sep, k) == (2.0, 1)
    assert _separation("regime", {"A": {"regime": "x"}, "B": {"regime": "y"}}, math.nan)[0] == math.inf
    assert _separation("regime", {"A": {"regime": "x"}, "B": {"regime": "x"}}, math.nan)[0] == 0.0
    assert _separation("regime", {"A": {"regime": "x"}, "B": {"regime": None}}, math.nan)[0] == 0.0


def test_the_noise_is_the_datas_where_measured_else_the_registrys_and_one_model_is_refused(tmp_path):
    from sweep.discrepancy.discriminate import observable_noise

    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
         "candidates": {"effects": ["compliant_boundary"]}, "holdout": {"ids": ["d"]}, "options": {"h": 8.0}}
    data = _pressure_twin(tmp_path, {})
    prob = Problem(data, spec_from_dict(d), ToyForward({}, h=8.0))
    sd = data.curves.uncertainty[data.curves.observable == "p_inj"].median()
    assert observable_noise(prob, "p_inj") == (pytest.approx(sd), "data")
    assert observable_noise(prob, "crack_length") == (REGISTRY["crack_length"].default_noise, "default")
    with pytest.raises(ValueError, match="at least 2"):
        discriminating_measurements(prob, {"one": {"kbar": 0.0015}})
    # the toy does not model the outflow: it is left out, the others are predicted at every condition (the
    # regime too: the twin's data label every condition at its last time)
    assert all("regime" in prob.times[c] for c in CONDS)
    rows = discriminating_measurements(prob, {"A": {"kbar": 0.0015}, "B": {"kbar": 0.003}}, top=100)
    assert {r["observable"] for r in rows} == {"p_inj", "front_radius_mean", "crack_length", "regime"}
    assert {r["condition"] for r in rows} == set(CONDS)


def test_a_differing_regime_reads_as_labels_differ_in_the_report():
    row = {"observable": "regime", "unit": "label", "condition": "a", "time": 2.0,
           "predictions": {"A": "invasive_fracturing", "B": "porous_invasion"}, "separation": None,
           "noise_sd": None, "noise_source": "label", "measured": False}
    text = "\n".join(_discriminating_lines({"discriminating_measurements": [row]}))
    assert "| regime | a | 2 | invasive_fracturing | porous_invasion | labels differ | label | no |" in text


def test_the_water_outflow_is_read_from_the_solvers_time_series():
    """The registered outflow observable reads the solver's cumulative ``water_outflow_volume`` column (mm²),
    interpolated at the observation times like every curve; a time series without it names the column."""
    import pandas as pd

    from sweep.discrepancy.forward import observables_from_timeseries
    from sweep.discrepancy.observables import ObservableUnavailable

    ts = pd.DataFrame({"t": [0.0, 1.0, 2.0], "water_outflow_volume": [0.0, 0.0, 40.0]})
    out = observables_from_timeseries(ts, {"water_outflow_volume": [0.5, 1.5, 2.0]}, 5.0)
    assert np.allclose(out["water_outflow_volume"], [0.0, 20.0, 40.0])
    with pytest.raises(ObservableUnavailable, match="water_outflow_volume"):
        observables_from_timeseries(ts.drop(columns="water_outflow_volume"), {"water_outflow_volume": [1.0]}, 5.0)


def test_a_candidate_confounded_with_an_alternative_is_paired_with_its_mimic_and_told_apart_by_the_front(tmp_path):
    """The truth is k̄ 10 % high with k̄ declared uncertain ([[alternative]]): the compliance is confounded with
    k̄ on pressure data (P0/(1 + 2c) against P0 ∝ 1/k̄), so nothing is refitted and there is no tie.  Its mimic
    is the baseline with k̄ × (1 + 2c) at the probe c = 0.02 (to first order), which reproduces the compliance's
    pressure where the data are, and the front tells them apart by 15 t (w_i/50) 20 c mm (largest at t = 1 s and
    the highest rate, w_i = 70: 8.4 mm)."""
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "alternative": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
         "candidates": {"effects": ["compliant_boundary", "damage_viscosity"]},
         "holdout": {"ids": ["d"]}, "options": {"h": 8.0, "t_end": 1.0}}
    rep = run_workflow(_pressure_twin(tmp_path, {"kbar": 0.00165}), spec_from_dict(d), ToyForward({}, h=8.0),
                       out_dir=tmp_path / "out", figures=False)
    assert rep["verdict"] == "unexplained_discrepancy" and not rep["tie"]
    assert list(rep["confounded_measurements"]) == ["compliant_boundary"]
    e = rep["confounded_measurements"]["compliant_boundary"]
    assert e["probe"] == pytest.approx(0.02) and e["clipped"] == []
    # the first-order move: k̄ by the secant through its finite-difference step, so 1 + 2c to second order in c
    assert e["mimic"]["kbar"] == pytest.approx(0.0015 * 1.04, rel=2e-3)
    assert e["linear_misfit"] < 0.05
    assert e["training_rms"] < 0.1          # the pressures agree to a tenth of their noise (second order in c)
    best = e["measurements"][0]
    assert (best["observable"], best["condition"], best["measured"]) == ("front_radius_mean", "c", False)
    a, b = best["predictions"].values()
    assert abs(a - b) == pytest.approx(15 * 1.0 * 1.4 * 20 * 0.02, rel=0.01)
    assert best["separation"] == pytest.approx(abs(a - b) / REGISTRY["front_radius_mean"].default_noise)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "## What would tell each confounded candidate from the alternatives" in md
    assert "what would tell them apart is listed below" in md and "| front_radius_mean | c | 1 |" in md


def test_the_confounded_measurements_can_be_turned_off(tmp_path):
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "alternative": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
         "candidates": {"effects": ["compliant_boundary"]}, "holdout": {"ids": ["d"]},
         "options": {"h": 8.0, "t_end": 1.0}, "acceptance": {"confounded_measurements": False}}
    rep = run_workflow(_pressure_twin(tmp_path, {"kbar": 0.00165}), spec_from_dict(d), ToyForward({}, h=8.0))
    assert rep["candidates"][0]["confounded_with"] == ["kbar"] and rep["confounded_measurements"] == {}
    with pytest.raises(ValueError, match="confounded_measurements"):
        spec_from_dict({**d, "acceptance": {"confounded_measurements": "yes"}})

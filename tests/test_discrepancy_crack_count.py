"""The crack count as a discrepancy observable (issue #47 item 4: held out, the crack length *and count*).

`crack_count` is registered in sweep/discrepancy/observables.py and read from a run's last snapshot through the
regime classifier (its crack-branch tips).  Known answers: synthetic run folders whose porosity has 0 or 3 open
radial slots (the classifier's own test geometry, tests/test_classify.py), the count of a real solver run equal to
the classifier's count of the same folder, and observations at a time other than t_end refused before any run.
Units mm, s, kPa.
"""
import json

import numpy as np
import pandas as pd
import pytest
from scipy.spatial import Delaunay

from solver import RunOptions
from sweep.discrepancy.checks import check_data_against_model
from sweep.discrepancy.data import load_measured, write_measured
from sweep.discrepancy.forward import SolverForward, snapshot_observables
from sweep.discrepancy.heldout import split_observables
from sweep.discrepancy.observables import CURVES, REGISTRY, SNAPSHOT_CURVES, read_curves

RI, RO = 5.0, 53.0


def _annulus(h=2.0):
    """Ring points of the annulus r_i..r_o (mm), Delaunay, the hole removed."""
    pts = []
    for j, r in enumerate(np.linspace(RI, RO, int(np.ceil((RO - RI) / (h * 0.866))) + 1)):
        n = max(8, int(round(2 * np.pi * r / h)))
        th = 2 * np.pi * (np.arange(n) + 0.5 * (j % 2)) / n
        pts.append(np.c_[r * np.cos(th), r * np.sin(th)])
    p = np.vstack(pts)
    tri = Delaunay(p).simplices
    c = p[tri].mean(axis=1)
    return p, tri[np.hypot(c[:, 0], c[:, 1]) > RI + 1e-9]


def _run_folder(path, angles, lengths, status="ok"):
    """A finished run folder (the solver's format) whose last snapshot has open radial slots 4 mm wide at
    ``angles`` reaching r_i + ``lengths`` (mm), porosity U[0.2, 0.6] elsewhere, water inside r = 30 mm."""
    (path / "snapshots").mkdir(parents=True)
    p, t = _annulus()
    np.savez(path / "snapshots" / "mesh.npz", points=p, triangles=t)
    (path / "params.toml").write_text(f"r_inner = {RI}\nr_outer = {RO}\nl_S = 4.0\nl_d = 4.0\n")
    phi = np.random.default_rng(1).uniform(0.2, 0.6, len(t))
    xy = p[t].mean(axis=1)
    for a, L in zip(angles, lengths):
        e = np.array([np.cos(a), np.sin(a)])
        along, perp = xy @ e, np.abs(xy[:, 0] * e[1] - xy[:, 1] * e[0])
        phi[(along >= 0) & (along <= RI + L) & (perp <= 2.0)] = 1.0
    S = 0.5 * (1 - np.tanh(np.hypot(p[:, 0], p[:, 1]) - 30.0))
    np.savez(path / "snapshots" / "snap_00000.npz", t=2.0, S=S, phi=phi)
    (path / "summary.json").write_text(json.dumps({"status": status, "t_reached": 2.0}))
    pd.DataFrame({"t": [1.0, 2.0], "p_inj": [100.0, 200.0], "open_tip_radius": [0.0, 17.0]}).to_csv(
        path / "timeseries.csv", index=False)
    return path


def test_crack_count_is_a_registered_snapshot_curve():
    o = REGISTRY["crack_count"]
    assert "crack_count" in CURVES and SNAPSHOT_CURVES == ("crack_count",)
    assert o.unit == "-" and o.default_noise == 1.0 and o.read is None
    # the time-series reader leaves it out (it is not a time-series column)
    ts = pd.DataFrame({"t": [1.0], "p_inj": [5.0]})
    assert list(read_curves(ts, ["p_inj", "crack_count"], RI)) == ["p_inj"]


@pytest.mark.parametrize("angles, lengths", [((), ()), ((0.3, 2.4, 4.4), (10.0, 12.0, 11.0))])
def test_crack_count_reads_the_open_slots_of_the_last_snapshot(tmp_path, angles, lengths):
    rd = _run_folder(tmp_path / "run", angles, lengths)
    np.testing.assert_array_equal(snapshot_observables(rd, {"crack_count": [2.0]}, True)["crack_count"],
                                  [float(len(angles))])


def test_crack_count_of_a_failed_or_unreadable_run_is_no_prediction(tmp_path, caplog):
    rd = _run_folder(tmp_path / "run", (0.3,), (10.0,), status="failed")
    assert np.isnan(snapshot_observables(rd, {"crack_count": [2.0]}, False)["crack_count"]).all()
    (rd / "snapshots" / "snap_00000.npz").unlink()                 # no snapshot to classify
    with caplog.at_level("WARNING", logger="dchfrac.discrepancy"):
        assert np.isnan(snapshot_observables(rd, {"crack_count": [2.0]}, True)["crack_count"]).all()
    assert "crack_count" in caplog.text


def test_solver_forward_predicts_the_classifier_count_of_its_run(tmp_path):
    from sweep.regimes.classify import classify_run

    fwd = SolverForward({"beta": 0.0}, RunOptions(h=12.0, t_end=0.006, dt0=0.002, dt_max=0.002), tmp_path)
    out = fwd.predict_one({"w_i": 50.0}, {"p_inj": np.array([0.006]), "crack_count": np.array([0.006])})
    n = classify_run(fwd.run_dir({"w_i": 50.0})).classification.n_cracks
    assert out["crack_count"].tolist() == [float(n)] and np.isfinite(out["p_inj"]).all()


def _data(tmp_path, t_count):
    curves = pd.DataFrame({"condition": ["a", "a", "b", "b"], "observable": ["p_inj", "crack_count", "p_inj", "p_inj"],
                           "time": [1.0, t_count, 1.0, 2.0], "value": [100.0, 3.0, 90.0, 150.0],
                           "uncertainty": [10.0, 1.0, 10.0, 10.0]})
    return load_measured(write_measured(tmp_path / "data", {"a": {"w_i": 50.0}, "b": {"w_i": 40.0}}, curves))


class _Spec:
    """What the checks read of a spec: the baseline, nothing calibrated, condition b held out."""
    calibrate = ()

    def baseline_overrides(self):
        return {}

    def holdout(self, ids):
        return ["b"]


class _Fwd:
    def __init__(self, t_end):
        self.options = RunOptions(h=8.0, t_end=t_end)


def test_a_crack_count_away_from_t_end_is_refused_before_any_run(tmp_path):
    with pytest.raises(ValueError, match=r"crack_count time=1.5 s.*last snapshot.*t_end = 2 s"):
        check_data_against_model(_data(tmp_path, 1.5), _Spec(), [_Fwd(2.0)])
    check_data_against_model(_data(tmp_path / "ok", 2.0), _Spec(), [_Fwd(2.0)])


def test_the_crack_count_can_be_held_out(tmp_path):
    held = split_observables(_data(tmp_path, 2.0), ["crack_count"])
    moved = held.curves[held.curves.observable == "crack_count"]
    assert len(moved) == 1 and moved.condition.iloc[0] == "a~held" and moved.value.iloc[0] == 3.0

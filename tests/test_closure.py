"""sweep.studies.closure / `dchfrac closure`: the closing probes' per-run quantities against hand-computed answers
on a made-up time series and a made-up run folder (units mm, s, kPa)."""
import json
import math

import numpy as np
import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies.closure import series_row

R_I, R_O = 5.0, 53.0
# node rings: each window of closure.RADII (half-width 1 mm) and of the wall rings (r_o - 3, - 1, - 0.2 mm, half-widths
# 0.5, 0.5, 0.1 mm) holds exactly one of them
RINGS = [4.5, 6.0, 8.0, 10.0, 12.5, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 42.5, 45.0, 47.5, 50.0, 52.0, 52.8, 53.0]
N_THETA = 32


def _series(t_end=2.5):
    t = np.arange(0.0, t_end + 1e-9, 0.5)
    crack = np.array([0.0, 2.0, 5.0, 4.0, 3.0, 1.0])[: t.size]
    return pd.DataFrame({"t": t, "open_tip_radius": R_I + crack, "max_damage": np.linspace(0.0, 0.5, t.size),
                         "p_inj": 100.0 * t, "injected_volume": t, "outflow_volume": 0.5 * t})


def test_series_row_reads_the_longest_and_the_judged_crack():
    row = series_row(_series(), R_I, 2.0)
    assert (row["crack_longest"], row["t_longest"], row["crack_judged"]) == (5.0, 1.0, 3.0)
    assert row["max_damage_longest"] == pytest.approx(0.2) and row["max_damage_judged"] == pytest.approx(0.4)
    assert (row["p_inj_1s"], row["p_inj_2s"], row["p_inj_end"]) == (pytest.approx(100.0), pytest.approx(200.0), 250.0)
    assert row["outflow_frac_1s"] == pytest.approx(0.5) and row["outflow_frac_end"] == pytest.approx(0.5)


def test_series_row_leaves_times_after_the_run_empty():
    row = series_row(_series(t_end=1.5), R_I, 1.5)
    assert math.isnan(row["p_inj_2s"]) and row["p_inj_1s"] == pytest.approx(100.0)


def _annulus():
    th = np.linspace(0.0, 2 * np.pi, N_THETA, endpoint=False)
    pts = np.array([(r * np.cos(a), r * np.sin(a)) for r in RINGS for a in th])
    tris = []
    for i in range(len(RINGS) - 1):
        for j in range(N_THETA):
            a, b = i * N_THETA + j, i * N_THETA + (j + 1) % N_THETA
            tris += [(a, b, a + N_THETA), (b, b + N_THETA, a + N_THETA)]
    return pts, np.array(tris)


@pytest.fixture
def campaign(tmp_path):
    pts, tris = _annulus()
    run = tmp_path / "runs" / "k1"
    (run / "snapshots").mkdir(parents=True)
    np.savez(run / "snapshots" / "mesh.npz", points=pts, triangles=tris)
    phi = np.full(len(tris), 0.3)
    phi[-1] = 0.05   # an element of the outermost band (centroid beyond r_o - 2 mm)
    phi[0] = 0.01    # an element of the innermost band: not at the wall
    for k, t in enumerate((0.0, 1.0)):
        np.savez(run / "snapshots" / f"snap_{k:05d}.npz", t=t, p=np.hypot(*pts.T), phi=phi)
    params = {"r_inner": R_I, "r_outer": R_O, "porosity_floor": 0.1, "beta": 60.0}
    (run / "record.json").write_text(json.dumps({"status": "ok", "params": params,
                                                 "classification": {"t_classified": 2.0, "regime": "fracturing"}}))
    _series().to_csv(run / "timeseries.csv", index=False)
    return tmp_path


def test_command_writes_the_runs_with_ring_means_and_the_wall_minimum(campaign, tmp_path):
    out, md = tmp_path / "probe.json", tmp_path / "probe.md"
    assert main(["closure", str(campaign), "--out", str(out), "--md", str(md)]) == 0
    (run,) = json.loads(out.read_text())
    assert (run["key"], run["label"], run["crack_judged"]) == ("k1", "fracturing", 3.0)
    (ring,) = run["rings"]                       # the snapshot at t = 0 is left out
    assert ring["t"] == 1.0 and ring["phi_min_wall"] == pytest.approx(0.05)
    for rc in (6.0, 10.0, 20.0, 30.0, 40.0, 45.0, 50.0, 52.0, 52.8):   # p = r at the nodes: each ring's mean is rc
        assert ring[f"p@{rc:g}"] == pytest.approx(rc)
    assert ring["phi@45"] == pytest.approx(0.3) and math.isnan(ring["phi@20"])  # no element centroid within 19-21 mm
    assert "| porosity_floor |" in md.read_text()


def test_a_folder_without_runs_is_refused_in_one_line(tmp_path, capsys):
    assert main(["closure", str(tmp_path), "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "no runs/ folder" in err and len(err.splitlines()) == 1 and not (tmp_path / "x.json").exists()

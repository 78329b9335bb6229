"""Re-classification of a campaign on a (phi_open, L_min) grid (sweep.studies.threshold_sensitivity), on synthetic runs.

Known answers: each run has one radial crack (porosity 1) of a chosen length and, ahead of its tip, a zone of
porosity 0.985 (open at phi_open = 0.98, closed at 0.99), so the crack length at each level is known to within
one element; the labels come from a known separatrix Ca*_c = A exp(B C), so the fit must bracket its B.
"""
import math

import numpy as np
import pandas as pd
import pytest

from solver.mesh import annulus_mesh
from sweep.studies.threshold_sensitivity import ThresholdGrid, crack_lengths, main, separatrix_grid

RI, RO, H = 5.0, 53.0, 2.0
A_TRUE, B_TRUE = 1e6, 1.5  # separatrix Ca*_c = A exp(B C), C in %
L_LONG, L_SHORT, ZONE = 10.0, 2.0, 4.0  # mm: fracturing and porous crack lengths, nearly-open zone ahead


def _phi(points, tris, length, zone, angle=0.3):
    """Porosity per element: 0.4 background, 1 on a 3 mm wide radial slot of ``length`` beyond r_i, 0.985
    on its continuation over ``zone`` mm."""
    c = points[tris].mean(axis=1)
    r = np.hypot(*c.T)
    e = np.array([math.cos(angle), math.sin(angle)])
    along, across = c @ e, np.abs(c @ np.array([-e[1], e[0]]))
    slot = (along > 0) & (across < 1.5)
    phi = np.full(len(tris), 0.4)
    phi[slot & (r < RI + length)] = 1.0
    phi[slot & (r >= RI + length) & (r < RI + length + zone)] = 0.985
    return phi


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("campaign")
    m = annulus_mesh(RI, RO, h=H)
    points, tris = np.asarray(m.points), np.asarray(m.triangles)
    rng = np.random.default_rng(3)
    C = rng.uniform(0.5, 3.0, 40)
    ca = np.exp(rng.uniform(np.log(A_TRUE), np.log(A_TRUE) + B_TRUE * 3.5, 40))
    truth = ca > A_TRUE * np.exp(B_TRUE * C)
    rows = []
    for i, (c, a, f) in enumerate(zip(C, ca, truth)):
        d = root / "runs" / f"run{i:02d}"
        (d / "snapshots").mkdir(parents=True)
        np.savez(d / "snapshots" / "mesh.npz", points=points, triangles=tris)
        S = (np.hypot(*points.T) < 20.0).astype(float)
        np.savez(d / "snapshots" / "snap_00000.npz", t=1.0, S=S,
                 phi=_phi(points, tris, L_LONG if f else L_SHORT, ZONE))
        (d / "params.toml").write_text(f"r_inner = {RI}\nr_outer = {RO}\n")
        rows.append({"key": f"run{i:02d}", "status": "ok", "run_dir": f"runs/run{i:02d}", "cement": c,
                     "Ca_star": a, "t_classified": 1.0})
    rows.append({"key": "failed", "status": "failed", "run_dir": "runs/none", "cement": 1.0, "Ca_star": 1e7,
                 "t_classified": math.nan})
    pd.DataFrame(rows).to_csv(root / "table.csv", index=False)
    return root, truth


def test_lengths_follow_the_porosity_level(campaign):
    root, truth = campaign
    L = crack_lengths(root, (0.98, 0.99))
    assert len(L) == len(truth)  # the failed run is left out
    # phi_open = 0.99: the slot only; 0.98: the slot and the nearly-open zone (within an element and a pixel)
    tol = H + 0.4 * H
    want99 = np.where(truth, L_LONG, L_SHORT)
    assert np.all(np.abs(L["L@0.99"] - want99) <= tol)
    assert np.all(np.abs(L["L@0.98"] - (want99 + ZONE)) <= tol)


def test_separatrix_grid_recovers_the_labels_and_brackets_b(campaign):
    root, truth = campaign
    L = crack_lengths(root, (0.99,))
    fits = separatrix_grid(L, ThresholdGrid((0.99,), (6.0, 30.0)))
    good, none = fits
    assert good["n_fracturing"] == int(truth.sum()) and good["n"] == len(truth)
    lo, hi = good["B_interval"]
    assert lo <= B_TRUE <= hi and good["excludes_zero"] == (lo > 0)
    assert none["n_fracturing"] == 0 and "error" in none and "B" not in none


def test_cli_writes_json_and_markdown(campaign, tmp_path):
    root, _ = campaign
    out, md = tmp_path / "s.json", tmp_path / "s.md"
    assert main([str(root), "--phi-open", "0.99", "--l-min", "6", "--out", str(out), "--md", str(md)]) == 0
    import json

    data = json.loads(out.read_text())
    assert data["grid"] == {"phi_open": [0.99], "l_min": [6.0]} and len(data["lengths"]) == 40
    assert "| 0.99 | 6 |" in md.read_text()


@pytest.mark.parametrize("kw, name", [(dict(phi_open=(1.2,), l_min=(4.0,)), "phi_open"),
                                      (dict(phi_open=(0.99,), l_min=()), "l_min"),
                                      (dict(phi_open=(0.99,), l_min=(-1.0,)), "l_min")])
def test_bad_grid_is_refused_by_name(kw, name):
    with pytest.raises(ValueError, match=name):
        ThresholdGrid(**kw)


def test_not_a_campaign_folder_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="table.csv"):
        crack_lengths(tmp_path, (0.99,))


def test_lengths_from_an_earlier_output_redo_the_fits_without_run_folders(campaign, tmp_path):
    root, _ = campaign
    first, again = tmp_path / "first.json", tmp_path / "again.json"
    argv = ["--phi-open", "0.99", "--l-min", "6", "--md"]
    assert main([str(root), *argv, str(tmp_path / "first.md"), "--out", str(first)]) == 0
    import shutil

    shutil.rmtree(root / "runs")  # a fresh clone: the run folders are not committed
    assert main([str(root), "--lengths", str(first), *argv, str(tmp_path / "again.md"), "--out", str(again)]) == 0
    assert again.read_bytes() == first.read_bytes()
    assert (tmp_path / "again.md").read_text() == (tmp_path / "first.md").read_text()
    empty = tmp_path / "empty.json"
    empty.write_text("{}")
    with pytest.raises(ValueError, match="no 'lengths' records"):
        main([str(root), "--lengths", str(empty), *argv, str(tmp_path / "x.md"), "--out", str(tmp_path / "x.json")])


@pytest.mark.slow
@pytest.mark.parametrize("folder", ["ca_star_boundary_h1_floor", "ca_star_boundary_h2_floor",
                                    "ca_star_boundary_h4_floor"])
def test_committed_sensitivity_regenerates_from_its_own_lengths(folder, tmp_path):
    from pathlib import Path

    d = Path(__file__).resolve().parents[1] / "results" / folder
    out, md = tmp_path / "s.json", tmp_path / "s.md"
    assert main([str(d), "--lengths", str(d / "threshold_sensitivity.json"), "--phi-open", "0.95", "0.97", "0.98",
                 "0.99", "0.995", "--l-min", "3", "4", "5", "--out", str(out), "--md", str(md)]) == 0
    import json

    assert json.loads(out.read_text())["fits"] == json.loads((d / "threshold_sensitivity.json").read_text())["fits"]
    assert md.read_text() == (d / "threshold_sensitivity.md").read_text()

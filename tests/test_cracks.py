"""sweep.studies.cracks / `dchfrac cracks`: a snapshot's crack against a made-up open wedge of known length; the
committed crack summaries and the h = 1 line's longest-crack separatrix regenerate from the committed tables."""
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies import cracks

RESULTS = Path(__file__).resolve().parents[1] / "results"
R_I, R_O, DR = 5.0, 53.0, 0.5   # mm; DR: the ring spacing near the cavity (the wedge's resolution)


def _annulus(n_theta=180):
    rings = np.r_[np.arange(R_I, 15.0 + 1e-9, DR), np.linspace(16.0, R_O, 38)]
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    pts = np.array([(r * np.cos(a), r * np.sin(a)) for r in rings for a in th])
    tris = [(i * n_theta + j, i * n_theta + (j + 1) % n_theta, (i + 1) * n_theta + j)
            for i in range(len(rings) - 1) for j in range(n_theta)]
    tris += [(i * n_theta + (j + 1) % n_theta, (i + 1) * n_theta + (j + 1) % n_theta, (i + 1) * n_theta + j)
             for i in range(len(rings) - 1) for j in range(n_theta)]
    return pts, np.array(tris)


def test_snapshot_row_reads_an_open_wedge_at_each_threshold():
    """A wedge open to phi = 1 out to 11 mm and to phi = 0.97 from 11 to 14 mm: crack 9 mm at phi_open = 0.95,
    6 mm at 0.99 and 0.995 (within one ring spacing); damage and strain ranges read in the phi >= 0.99 part."""
    pts, tris = _annulus()
    c = pts[tris].mean(axis=1)
    rc, ang = np.hypot(*c.T), np.arctan2(c[:, 1], c[:, 0])
    wedge = np.abs(ang) < 0.1
    phi = np.full(len(tris), 0.3)
    phi[wedge & (rc < 14.0)] = 0.97
    phi[wedge & (rc < 11.0)] = 1.0
    eps_v = np.where(phi >= 0.99, 0.1, 0.0)
    z = {"t": 1.0, "S": np.where(np.hypot(*pts.T) < 8.0, 1.0, -1.0), "phi": phi, "d": np.full(len(pts), 0.2),
         "eps_v": eps_v}
    row = cracks.snapshot_row(pts, tris, R_I, R_O, z)
    assert row["L_0.95"] == pytest.approx(9.0, abs=DR)
    assert row["L_0.99"] == pytest.approx(6.0, abs=DR) and row["L_0.995"] == row["L_0.99"]
    assert row["n_cracks_0.99"] >= 1  # a crack longer than L_MIN = 4 mm counts at least once
    assert row["phi_max"] == 1.0
    assert row["d_open_min"] == row["d_open_max"] == pytest.approx(0.2)
    assert row["eps_v_open_min"] == row["eps_v_open_max"] == pytest.approx(0.1)


@pytest.mark.parametrize("folder", ["ca_star_boundary_h1_floor", "ca_star_peak_label_h2", "nucleation_length_h2"])
def test_committed_crack_summary_regenerates_from_the_committed_history(folder):
    hist = pd.read_csv(RESULTS / folder / "crack_history.csv")
    assert cracks.summary_markdown(cracks.summary(hist)) == (RESULTS / folder / "crack_summary.md").read_text()


def test_a_folder_without_runs_is_refused_in_one_line(tmp_path, capsys):
    assert main(["cracks", "history", str(tmp_path), "--out", str(tmp_path / "h.csv")]) == 2
    assert main(["cracks", "separatrix", str(tmp_path), "--l-min", "4", "--out", str(tmp_path / "s.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "no runs/ folder" in err[0] and "no crack_history.csv" in err[1]
    assert "no runs/ or longest_crack_steps.csv" in err[2]


def _close(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_close(u, v) for u, v in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-6, abs=1e-9)
    return a == b


@pytest.mark.slow
def test_h1_line_longest_crack_separatrix_regenerates(tmp_path):
    """The Markdown byte for byte; the JSON to the fits' optimizer tolerance (1e-6 relative)."""
    folder = RESULTS / "ca_star_boundary_h1_floor"
    out, md = tmp_path / "l.json", tmp_path / "l.md"
    assert main(["cracks", "separatrix", str(folder), "--l-min", "3", "4", "5", "6", "8", "10",
                 "--out", str(out), "--md", str(md)]) == 0
    assert md.read_text() == (folder / "longest_crack_separatrix.md").read_text()
    assert _close(json.loads(out.read_text()), json.loads((folder / "longest_crack_separatrix.json").read_text()))


def test_peak_label_separatrix_regenerates_without_its_runs(tmp_path):
    """The h = 2 peak-label folder keeps no runs/: the steps' lengths come from its longest_crack_steps.csv, and
    both files regenerate (Markdown byte for byte, JSON to the fits' optimizer tolerance)."""
    folder = RESULTS / "ca_star_peak_label_h2"
    assert not (folder / "runs").exists()
    out, md = tmp_path / "l.json", tmp_path / "l.md"
    assert main(["cracks", "separatrix", str(folder), "--l-min", *map(str, range(2, 11)),
                 "--out", str(out), "--md", str(md)]) == 0
    assert md.read_text() == (folder / "longest_crack_separatrix.md").read_text()
    assert _close(json.loads(out.read_text()), json.loads((folder / "longest_crack_separatrix.json").read_text()))


def test_steps_csv_stands_in_for_the_runs(tmp_path):
    """Lengths written with --steps-out from a folder with runs/ (a made-up two-run store) give the same steps
    half when read back from longest_crack_steps.csv in a copy of the folder without runs/; a run missing from
    the CSV is named."""
    folder = tmp_path / "with_runs"
    rows = []
    for key, (tc, tips) in {"a1": (1.0, [5.0, 9.0, 7.0]), "b2": (2.0, [5.0, 6.0, 12.0])}.items():
        rd = folder / "runs" / key
        rd.mkdir(parents=True)
        pd.DataFrame({"t": [0.5, 1.0, 1.5], "open_tip_radius": tips}).to_csv(rd / "timeseries.csv", index=False)
        (rd / "params.toml").write_text("[parameters]\nr_inner = 5.0\n")
        rows.append({"key": key, "status": "ok", "t_classified": tc})
    table = pd.DataFrame(rows).set_index("key")
    steps = cracks.longest_from_steps(folder, table)
    assert steps.loc["a1", "L@0.99"] == pytest.approx(4.0) and steps.loc["a1", "t_longest"] == 1.0
    assert steps.loc["b2", "L@0.99"] == pytest.approx(7.0) and steps.loc["b2", "t_longest"] == 1.5
    bare = tmp_path / "bare"
    bare.mkdir()
    steps.rename_axis("key").reset_index()[cracks.STEPS_COLUMNS].to_csv(bare / cracks.STEPS_CSV, index=False)
    pd.testing.assert_frame_equal(cracks.longest_from_steps(bare, table), steps[cracks.STEPS_COLUMNS[1:]],
                                  check_names=False)
    table.loc["c3"] = ["ok", 1.0]
    with pytest.raises(ValueError, match=r"no rows for the finished runs \['c3'\]"):
        cracks.longest_from_steps(bare, table)

"""sweep.studies.nf_nb_quadrants / `dchfrac judge nf_nb_quadrants`: rows 17–17d of results/README.md counted on
each side of the paper's delimiters, on a grid built with a known answer and on the committed floor grid, whose
counts the README states; the fallback fills failed points only; bad input is refused."""
import json
from pathlib import Path

import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies import nf_nb_quadrants as nq
from sweep.studies.experiment_lines import with_fallback

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _grid() -> pd.DataFrame:
    """16 runs: dp_vis 100, 300 (N_f < 1) and 3,000, 10,000 kPa (N_f > 1), one outcome against the trend on each
    side of the transition, so the logistic fit is not separable and its dp_cri lies between 300 and 3,000 kPa;
    N_b = 0.1 or 10 per run, with the paper's regime in each quadrant but for three runs."""
    dp = [100, 100, 300, 300] * 2 + [3000, 3000, 10000, 10000] * 2
    nb = [0.1] * 4 + [10.0] * 4 + [0.1] * 4 + [10.0] * 4
    fr = [False, False, False, True] * 2 + [False, True, True, True] * 2
    regime = (["uniform_invasion"] * 3 + ["invasive_fracturing"]            # N_f < 1, N_b < 1
              + ["viscous_fingering"] * 3 + ["fracturing_fingering"]        # N_f < 1, N_b > 1
              + ["viscous_fingering"] + ["invasive_fracturing"] * 3         # N_f > 1, N_b < 1
              + ["viscous_fingering"] + ["non_invasive_fracturing"] * 3)    # N_f > 1, N_b > 1
    n = len(dp)
    return pd.DataFrame({"status": "ok", "dp_vis": [float(x) for x in dp], "N_b": nb, "fracturing": fr,
                         "regime": regime, "eta_o": [1e-4 * (i + 1) for i in range(n)], "eta_w": 1e-3,
                         "kbar": 0.01})


def test_the_rows_count_each_quadrant_against_the_paper():
    out = nq.judge_runs(_grid())
    assert 300 < out["dp_cri_kPa"] < 3000
    assert out["17"] == {"fracture_with_N_f_above_1": {"k": 6, "n": 8},
                         "no_fracture_with_N_f_below_1": {"k": 6, "n": 8}}
    assert out["17a"]["N_b < 1"] == {"invasive_fracturing": 1, "uniform_invasion": 3}
    assert out["17a"]["reproduced"] and out["17b"]["reproduced"]
    nif = out["17b"]["paper_regime_shares"]["non_invasive_fracturing"]
    assert (nif["N_b < 1"]["k"], nif["N_b < 1"]["n"], nif["N_b > 1"]["k"], nif["N_b > 1"]["n"]) == (0, 4, 3, 4)
    lo, hi = nif["N_b > 1"]["wilson_95"]  # Wilson 95 % of 3 of 4: [0.301, 0.954]
    assert (lo, hi) == pytest.approx((0.3006, 0.9544), abs=1e-3) and nif["N_b < 1"]["wilson_95"][0] == 0.0
    assert out["17c"] == {"N_f < 1, N_b < 1": 0, "N_f < 1, N_b > 1": 1, "N_f > 1, N_b < 1": 0, "N_f > 1, N_b > 1": 0}
    assert out["17d"] == {"viscous_fingering_with_N_b_and_N_f_above_1": 1, "reproduced": False}


def test_a_tie_for_the_most_frequent_label_does_not_reproduce_the_row():
    g = _grid()
    g.loc[1, "regime"] = "viscous_fingering"  # N_f < 1, N_b < 1: 2 uniform invasion, 1 fingering, 1 invasive
    g.loc[3, "regime"] = "viscous_fingering"  # 2 against 2
    assert not nq.judge_runs(g)["17a"]["reproduced"]


def test_a_failed_run_carries_no_label_and_the_fallback_fills_it():
    g = _grid()
    failed = g.assign(status=["failed" if i in (0, 9) else "ok" for i in range(len(g))],
                      regime=[None if i in (0, 9) else r for i, r in enumerate(g["regime"])])
    primary = nq.judge_runs(failed)
    assert (primary["labelled"], primary["without_label"]) == (14, 2)
    merged, n = with_fallback(failed, g.loc[[0, 9]], point=nq.POINT, who="nf_nb_quadrants")
    assert n == 2 and nq.judge_runs(merged)["17a"] == nq.judge_runs(g)["17a"]
    with pytest.raises(ValueError, match="nf_nb_quadrants: fallback run at"):
        with_fallback(failed, g.loc[[1]], point=nq.POINT, who="nf_nb_quadrants")


def test_the_committed_floor_grid_gives_the_counts_its_readme_states():
    """results/nf_vs_nb_h2_wall_floor/README.md, "Verdicts", and compare_with_wall.md (61 of 62 labels kept)."""
    out = nq.judge(RESULTS / "nf_vs_nb_h2_wall_floor", reference_dir=RESULTS / "nf_vs_nb_h2_wall")
    p = out["primary"]
    assert p["dp_cri_kPa"] == pytest.approx(1.38e4, rel=0.01)
    assert p["17a"]["N_b < 1"] == {"uniform_invasion": 2, "viscous_fingering": 5}
    assert p["17a"]["N_b > 1"] == {"fracturing_fingering": 4, "invasive_fracturing": 3, "uniform_invasion": 1,
                                   "viscous_fingering": 25}
    assert p["17b"]["N_b < 1"] == {"fracturing_fingering": 1, "invasive_fracturing": 9, "viscous_fingering": 3}
    assert p["17b"]["N_b > 1"] == {"invasive_fracturing": 24, "non_invasive_fracturing": 3}
    assert not p["17a"]["reproduced"] and not p["17b"]["reproduced"] and p["17d"]["reproduced"]
    ref = out["against_reference"]
    assert (ref["labelled_in_both"], ref["same_label"]) == (62, 61)


def test_cli_judges_with_a_fallback_named_for_the_campaign(tmp_path, table_folder, capsys):
    g = _grid()
    grid = table_folder("grid", g.assign(status=["failed" if i == 0 else "ok" for i in range(len(g))],
                                                 regime=[None] + g["regime"].tolist()[1:]))
    fb = table_folder("grid_upwind_fallback", g.loc[[0]])
    out = tmp_path / "summary.json"
    assert main(["judge", "nf_nb_quadrants", str(grid), "--fallback", str(fb), "--out", str(out)]) == 0
    s = json.loads(out.read_text())
    assert s["primary"]["labelled"] == 15 and s["secondary"]["replaced"] == 1
    assert s["secondary"]["fallback_labels"] == {"uniform_invasion": 1}
    assert main(["judge", "nf_nb_quadrants", str(grid), "--fallback", str(fb), "--fallback", str(fb)]) == 2
    assert "allowed: one fallback each" in capsys.readouterr().err
    wrong = table_folder("other_upwind_fallback", g.loc[[0]])
    assert main(["judge", "nf_nb_quadrants", str(grid), "--fallback", str(wrong)]) == 2
    assert "allowed lines: ['grid']" in capsys.readouterr().err


def test_the_committed_uniform_mesh_grid_gives_row_17_as_results_readme_states():
    """results/README.md row 17: 36 of 37 runs with N_f > 1 fracture, 32 of 39 with N_f < 1 do not; dp_cri 9.9e3."""
    p = nq.judge(RESULTS / "nf_vs_nb_h2")["primary"]
    assert p["dp_cri_kPa"] == pytest.approx(9.9e3, rel=0.01)
    assert p["17"] == {"fracture_with_N_f_above_1": {"k": 36, "n": 37},
                       "no_fracture_with_N_f_below_1": {"k": 32, "n": 39}}
    assert p["17c"]["N_f < 1, N_b > 1"] + p["17c"]["N_f > 1, N_b < 1"] == 7


def test_the_committed_experiment_grid_gives_the_verdict_its_readme_states():
    """results/experiment_nf_vs_nb/README.md, "Verdict": rows 17, 17a and 17d reproduced, 17b not (no non-invasive
    fracturing); the fallback's one run changes no row's verdict; 39 of 79 labels as the paper model's floor grid."""
    out = nq.judge(RESULTS / "experiment_nf_vs_nb", reference_dir=RESULTS / "nf_vs_nb_h2_wall_floor",
                   fallback_dir=RESULTS / "experiment_nf_vs_nb_upwind_fallback")
    p, s = out["primary"], out["secondary"]
    assert p["dp_cri_kPa"] == pytest.approx(1.89e3, rel=0.01)
    assert p["17"] == {"fracture_with_N_f_above_1": {"k": 53, "n": 55},
                       "no_fracture_with_N_f_below_1": {"k": 24, "n": 24}}
    assert p["17a"]["reproduced"] and p["17d"]["reproduced"] and not p["17b"]["reproduced"]
    assert p["17b"]["N_b > 1"] == {"fracturing_fingering": 30, "invasive_fracturing": 8}
    assert (s["replaced"], s["fallback_labels"]) == (1, {"fracturing_fingering": 1})
    assert [s[r]["reproduced"] for r in ("17a", "17b", "17d")] == [True, False, True]
    ref = out["against_reference"]
    assert (ref["labelled_in_both"], ref["same_label"]) == (79, 39)

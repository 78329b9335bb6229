"""Replicates as a campaign concept (sweep.campaign.replicates): the [replicates] table, one run per replicate in
the store, per-point aggregates with known answers, resume and isolation, the loaders."""
import math

import numpy as np
import pandas as pd
import pytest

from sweep.campaign.run import run_campaign
from sweep.campaign.load import load_campaign
from sweep.campaign.replicates import expand_replicates, point_table
from sweep.campaign.sampler import grid_points
from sweep.campaign.spec import SpecError, spec_from_dict
from sweep.regimes.probability import wilson_interval

VERSION = "test-replicates"


def seed_runner(params, options, run_dir):
    """Known answers per replicate: fracturing iff seed < cement (so p = C / n at cement C), crack length
    seed * cement mm; fails for cement == 3 and seed == 3 (a failure isolated to one replicate)."""
    C, s = params["cement"], params["seed"]
    if C == 3.0 and s == 3:
        raise RuntimeError("boom at seed 3")
    fr = s < C
    return {"status": "ok", "regime": "fracturing" if fr else "porous_invasion",
            "metrics": {"fracturing": bool(fr), "crack_length": float(s * C), "mesh_seed_seen": options["mesh_seed"]}}


def _spec(reps=None, **extra):
    d = {"name": "reps", "base": {"w_i": 10.0}, "options": {"h": 4.0},
         "axes": {"cement": [1.0, 2.0, 3.0], "eta_o": [0.1, 0.5]}, **extra}
    if reps is not None:
        d["replicates"] = reps
    return spec_from_dict(d)


@pytest.mark.parametrize("reps, extra, match", [
    ({"porosity": 3}, {}, r"replicates\.porosity: unknown key"),
    ({"porosity_seed": 0}, {}, r"replicates\.porosity_seed=0: must be an integer in \[1, 1000\]"),
    ({"porosity_seed": 2.0}, {}, r"replicates\.porosity_seed=2\.0"),
    ({"porosity_seed": True}, {}, r"replicates\.porosity_seed=True"),
    ([3], {}, r"replicates: expected a table"),
    ({"porosity_seed": 3}, {"axes": {"cement": [1.0], "seed": [0, 1]}}, r"'seed' is also swept"),
    ({"mesh_seed": 2}, {"axes": {"cement": [1.0], "mesh_seed": [0, 1]}}, r"'mesh_seed' is also swept"),
    ({"porosity_seed": 3}, {"base": {"w_i": 10.0, "porosity_field": "constant"}}, r"porosity_field='constant'"),
])
def test_bad_replicates_are_refused_naming_the_key(reps, extra, match):
    with pytest.raises(SpecError, match=match):
        _spec(reps, **extra)


def test_replicates_count_against_max_runs():
    with pytest.raises(SpecError, match="60 runs exceed the limit max_runs = 50"):
        _spec({"porosity_seed": 10}, run={"max_runs": 50})


def test_expansion_seeds_and_mesh_seeds():
    spec = _spec({"porosity_seed": 3, "mesh_seed": 2}, base={"w_i": 10.0, "seed": 4})
    pts = expand_replicates(spec, grid_points(spec))
    assert len(pts) == 6 * 6 and [p.index for p in pts] == list(range(36))
    first = pts[:6]
    assert [p.params["seed"] for p in first] == [4, 5, 6, 4, 5, 6]
    assert [p.options["mesh_seed"] for p in first] == [None] * 3 + [1] * 3
    assert all(p.swept == first[0].swept for p in first)
    assert expand_replicates(_spec(), grid_points(_spec())) == grid_points(_spec())


def test_replicate_runs_aggregates_resume_and_loaders(tmp_path):
    res = run_campaign(_spec({"porosity_seed": 2}), tmp_path, runner=seed_runner, jobs=1, code_hash=VERSION,
                       progress=None)
    assert (res.n_points, res.n_executed, res.n_ok, res.n_failed) == (12, 12, 12, 0)
    # more replicates later: only the new ones run (replicate r is seed r, the same run as before)
    res = run_campaign(_spec({"porosity_seed": 4}), tmp_path, runner=seed_runner, jobs=1, code_hash=VERSION,
                       progress=None)
    assert (res.n_points, res.n_executed, res.n_failed) == (24, 12, 2)   # the failures stay isolated
    table = load_campaign(tmp_path / "reps")
    assert len(table) == 24 and table.groupby(["cement", "eta_o"]).size().tolist() == [4] * 6
    pts = load_campaign(tmp_path / "reps", points=True)
    assert len(pts) == 6 and pts.attrs["campaign_dir"] == str(tmp_path / "reps")
    p = pts.set_index(["cement", "eta_o"]).sort_index()
    # cement C: seeds 0..3 fracture iff seed < C; at C = 3 seed 3 failed: seeds 0, 1, 2 all fracture
    assert p["n_runs"].tolist() == [4] * 6 and p["n_ok"].tolist() == [4, 4, 4, 4, 3, 3]
    assert p["p_fracturing"].tolist() == pytest.approx([0.25, 0.25, 0.5, 0.5, 1.0, 1.0])
    lo, hi = wilson_interval(1, 4)
    assert p.loc[(1.0, 0.1), "p_fracturing_lo"] == pytest.approx(float(lo)) and p.loc[(1.0, 0.1), "p_fracturing_hi"] == pytest.approx(float(hi))
    assert p.loc[(1.0, 0.1), "p_porous_invasion"] == 0.75 and bool(p.loc[(1.0, 0.1), "mixed"])
    assert not bool(p.loc[(3.0, 0.1), "mixed"])
    # crack length seed * C: mean 1.5 C and sd C sd(0, 1, 2, 3) at C = 1, 2; at C = 3 seeds 0, 1, 2
    assert p.loc[(2.0, 0.5), "crack_length_mean"] == pytest.approx(3.0)
    assert p.loc[(2.0, 0.5), "crack_length_sd"] == pytest.approx(2.0 * np.std([0, 1, 2, 3], ddof=1))
    assert p.loc[(3.0, 0.5), "crack_length_mean"] == pytest.approx(3.0)
    cols = pd.read_csv(tmp_path / "reps" / "points_columns.csv", keep_default_na=False).set_index("name")
    assert cols.loc["crack_length_mean", "unit"] == "mm" and cols.loc["p_fracturing", "unit"] == "-"
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "reps" / "points.csv"), pts, check_dtype=False)
    # the campaign's Ca*-C diagram is the probability diagram (replicates grouped per point)
    from sweep.campaign.plot import plot_campaign

    spec = _spec({"porosity_seed": 4}, diagrams=[{"kind": "ca_star_vs_cement", "formats": []}])
    paths = plot_campaign(spec, tmp_path, table=table.assign(run_dir=""))
    assert [p.name for p in paths] == ["ca_star_vs_cement.png"] and paths[0].exists()


def test_point_table_of_a_table_without_labels_columns():
    t = pd.DataFrame({"cement": [1.0, 1.0, 2.0], "status": ["ok", "failed", "ok"], "regime": ["a", None, "b"]})
    p = point_table(t, ["cement"])
    assert p["n_runs"].tolist() == [2, 1] and p["n_ok"].tolist() == [1, 1] and p["p_a"].tolist() == [1.0, 0.0]
    with pytest.raises(ValueError, match="no column for axis 'eta_o'"):
        point_table(t, ["eta_o"])


def test_a_points_majority_label_is_its_first_runs_on_a_tie_whatever_the_string_hashing():
    """The boundary figure's label of a replicated point: the majority, a tie going to the first run's label. A
    vote over a set picked the tie by the interpreter's string hashing, so the figure changed from run to run."""
    import subprocess
    import sys

    from sweep.campaign.replicate_sampler import majority_label

    assert majority_label(["True", "False"]) == "True" and majority_label(["False", "True"]) == "False"
    assert majority_label(["False", "True", "True"]) == "True" and majority_label(["True"]) == "True"
    code = ("from sweep.campaign.replicate_sampler import majority_label as m; "
            "print(m(['True', 'False']), m(['False', 'True']), m(['a', 'b', 'c', 'b', 'c']))")
    outs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**__import__("os").environ, "PYTHONHASHSEED": str(seed)}).stdout for seed in (1, 2, 3)}
    assert outs == {"True False b\n"}


def test_an_archived_replicate_is_matched_to_its_own_draw_never_another(tmp_path):
    """A committed table whose keys no longer match the spec (a parameter added to the model changes every key) is
    matched to the points by their swept values; replicates share those, so the draw (seed) must match too.  Here
    the committed rows of one point hold seeds 0 and 2 (seed 1 never finished): seed 1 is pending, seed 2's row
    goes to the point of seed 2, and no draw is counted twice."""
    import shutil

    from sweep.campaign.plan import plan_campaign
    from sweep.campaign.table import build_table

    spec = _spec({"porosity_seed": 3})
    run_campaign(spec, tmp_path, runner=seed_runner, jobs=1, code_hash=VERSION, progress=None)
    d = tmp_path / "reps"
    t = pd.read_csv(d / "table.csv")
    gap = (t["cement"] == 2.0) & (t["eta_o"] == 0.1) & (t["seed"] == 1)
    t = t[~gap].assign(key="old-" + t["key"])          # keys of an older model; the seed-1 run of one point absent
    t.to_csv(d / "table.csv", index=False)
    (d / "table.parquet").unlink()
    shutil.rmtree(d / "runs")
    plan = plan_campaign(spec, tmp_path, code_hash=VERSION)
    assert len(plan.pending) == 1 and plan.pending[0][0].params["seed"] == 1
    for p, k in plan.archived:
        assert plan.archived_rows[k]["seed"] == p.params["seed"]
    table = build_table(spec, tmp_path, plan=plan)
    assert not table.duplicated(["cement", "eta_o", "seed"]).any()


def test_blocks_with_equal_axis_values_and_other_fixed_values_are_distinct_points(tmp_path):
    """Two blocks sweep the same axes at another fixed parameter (w_i 10 and 20 mm/s): equal axis values are then
    two points, not one point's replicates (the point table grouped by the axes alone pooled them)."""
    def runner(params, options, run_dir):
        fr = params["w_i"] > 15.0                       # the fixed parameter decides the label
        return {"status": "ok", "regime": "fracturing" if fr else "porous_invasion",
                "metrics": {"fracturing": fr, "crack_length": params["w_i"]}}

    spec = spec_from_dict({"name": "blk", "options": {"h": 4.0}, "replicates": {"porosity_seed": 2},
                           "blocks": [{"label": "slow", "base": {"w_i": 10.0}, "axes": {"cement": [1.0, 2.0]}},
                                      {"label": "fast", "base": {"w_i": 20.0}, "axes": {"cement": [1.0, 2.0]}}]})
    run_campaign(spec, tmp_path, runner=runner, jobs=1, code_hash=VERSION, progress=None)
    pts = load_campaign(tmp_path / "blk", points=True)
    assert len(pts) == 4 and pts["n_ok"].tolist() == [2] * 4 and not pts["mixed"].any()
    assert sorted(pts["p_fracturing"]) == [0.0, 0.0, 1.0, 1.0] and sorted(pts["w_i"]) == [10.0, 10.0, 20.0, 20.0]
    assert sorted(pts["crack_length_sd"]) == [0.0] * 4


def test_points_behind_their_table_are_rebuilt_from_it(tmp_path):
    """A campaign killed after a periodic table write (table.* only) leaves points.* of an earlier write: the
    loader checks that the points hold every run of the table (sum of n_runs) and rebuilds them from the table
    when they do not, instead of returning the stale counts."""
    import shutil

    run_campaign(_spec({"porosity_seed": 2}), tmp_path, runner=seed_runner, jobs=1, code_hash=VERSION, progress=None)
    d = tmp_path / "reps"
    for f in ("points.csv", "points.parquet"):
        shutil.copy(d / f, tmp_path / f)
    run_campaign(_spec({"porosity_seed": 4}), tmp_path, runner=seed_runner, jobs=1, code_hash=VERSION, progress=None)
    for f in ("points.csv", "points.parquet"):
        shutil.copy(tmp_path / f, d / f)                  # the points of the 2-draw write beside the 4-draw table
    pts = load_campaign(d, points=True)
    assert pts["n_runs"].tolist() == [4] * 6 and pts["n_runs"].sum() == len(load_campaign(d))

"""The boundary sampler with replicates (sweep.campaign.replicate_sampler) on a stochastic oracle in the
(cement, eta_o) plane: replicates go near the boundary, it stops by the band's width, it resumes, and a campaign
with a fake runner writes the per-point table."""
import json
import shutil

import numpy as np
import pandas as pd
import pytest

from sweep.campaign.boundary import BoundarySampler
from sweep.campaign.run import run_campaign
from sweep.campaign.spec import SpecError, spec_from_dict
from sweep.studies.oracle import StochasticOracle

# Ca* is proportional to eta_o at fixed w_i: the boundary eta_o,c = A exp(B C), in the sampled range
ORACLE = StochasticOracle(A=0.05, B=1.2, width=0.2, ca_lo=0.01, ca_hi=10.0)


def oracle_runner(params, options, run_dir):
    """The oracle's draw for the point (cement, eta_o) and porosity seed (study seed 0)."""
    fr = ORACLE.label((params["cement"], params["eta_o"]), params["seed"], 0)
    return {"status": "ok", "regime": "fracturing" if fr else "porous_invasion", "metrics": {"fracturing": fr}}


def _spec(reps=5, axes=None, **sampler):
    d = {"name": "rep_boundary", "base": {"eta_w": 1e-6, "kbar": 0.0015}, "options": {"h": 4.0},
         "axes": axes or {"cement": {"linear": [0.5, 3.0, 3]}, "eta_o": {"log": [0.01, 10.0, 3]}},
         "replicates": {"porosity_seed": reps},
         "sampler": {"kind": "boundary", "budget": 150, "tolerance": 0.1, "label": "fracturing", "batch": 6,
                     "band_tolerance": 0.3, **sampler}}
    return spec_from_dict(d)


def drive(spec, stop_after=None):
    s, rows = BoundarySampler(), []
    pts = s.initial(spec)
    while pts:
        for p in pts[:stop_after]:
            fr = ORACLE.label((p.params["cement"], p.params["eta_o"]), p.params["seed"], 0)
            rows.append({"status": "ok", "cement": p.params["cement"], "eta_o": p.params["eta_o"],
                         "seed": p.params["seed"], "fracturing": fr})
        if stop_after is not None and len(pts) > stop_after:
            return s, pd.DataFrame(rows), pts[stop_after:]
        pts = s.refine(spec, pd.DataFrame(rows))
    return s, pd.DataFrame(rows), []


def test_replicates_go_to_uncertain_points_and_the_band_stops_it():
    spec = _spec()
    s, table, _ = drive(spec)
    st = s.state(spec, table)
    assert st["stopped"] and st["reason"].startswith("converged") and st["band_half_width_decades"] <= 0.3
    assert st["runs_used"] == len(table) < 150
    reps = table.groupby(["cement", "eta_o"])["seed"].agg(["count", "max"]).reset_index()
    assert reps["max"].max() <= 4 and (reps["count"] == reps["max"] + 1).all()   # seeds 0 .. n-1, none skipped
    assert (reps["count"] > 1).any() and (reps["count"] == 1).any()
    dist = np.abs(np.log10(reps["eta_o"]) - ORACLE.line(reps["cement"]))        # decades from the boundary
    assert dist[reps["count"] > 1].median() < 0.5 * dist[reps["count"] == 1].median()


def test_a_killed_round_resumes_to_the_same_runs():
    spec = _spec()
    _, full, _ = drive(spec)
    s, part, left = drive(spec, stop_after=4)          # the first round is cut after 4 of its 9 runs
    again = s.refine(spec, part)
    assert [(p.params["cement"], p.params["eta_o"], p.params["seed"]) for p in again] == \
           [(p.params["cement"], p.params["eta_o"], p.params["seed"]) for p in left]
    assert len(full) >= 9


def test_campaign_with_replicated_boundary_writes_its_points(tmp_path):
    spec = _spec(budget=30)
    res = run_campaign(spec, tmp_path, runner=oracle_runner, jobs=1, code_hash="test-rb", progress=None)
    d = tmp_path / "rep_boundary"
    st = json.loads((d / "sampler.json").read_text())
    assert res.n_executed == st["runs_used"] <= 30 and st["stopped"]
    pts = pd.read_csv(d / "points.csv")
    assert pts["n_runs"].sum() == st["runs_used"]
    assert sorted(pts["n_ok"]) == sorted(p["replicates"] for p in st["points"])
    assert not any(p["pending"] or p["unlabelled"] for p in st["points"])


@pytest.mark.parametrize("kw, match", [
    ({"band_tolerance": 0}, r"sampler\.band_tolerance=0: must be a number > 0"),
    ({"clear": 0.5}, r"sampler\.clear=0\.5: must be a number in \(0, 0\.5\)"),
    ({"axes": {"cement": {"linear": [0.5, 3.0, 3]}, "eta_o": {"linear": [0.01, 10.0, 3]}}}, r"second on a log scale"),
])
def test_bad_replicated_boundary_specs(kw, match):
    with pytest.raises(SpecError, match=match):
        _spec(**kw)


def test_replicate_settings_need_replicates():
    d = {"name": "b", "base": {"eta_w": 1e-6, "kbar": 0.0015}, "options": {"h": 4.0},
         "axes": {"cement": {"linear": [0.5, 3.0, 3]}, "eta_o": {"log": [0.01, 10.0, 3]}},
         "sampler": {"kind": "boundary", "budget": 20, "tolerance": 0.1, "band_tolerance": 0.3}}
    with pytest.raises(SpecError, match=r"sampler\.band_tolerance: a setting of the boundary sampler with replicates"):
        spec_from_dict(d)


def test_a_label_outside_the_two_named_labels_is_ignored_never_a_negative():
    """``labels = [negative, positive]`` of a text column: as for the boundary sampler without replicates, a run
    with another label is left out (it counted as a negative, pulling the fitted probability down), and a text
    column without ``labels`` is refused naming the setting (every run counted as a negative)."""
    from sweep.campaign import replicate_sampler as rs

    spec = _spec(label="regime", labels=["porous_invasion", "fracturing"])
    s = BoundarySampler()
    pts = s.initial(spec)
    regimes = ["fracturing", "porous_invasion", "viscous_fingering"] * 3
    table = pd.DataFrame([{"status": "ok", "cement": p.params["cement"], "eta_o": p.params["eta_o"],
                           "seed": p.params["seed"], "regime": r} for p, r in zip(pts, regimes)])
    cfg, _, positive = rs._setup(s, spec)
    seen = rs._observed(table, cfg, positive, int(pts[0].params["seed"]))
    assert sorted(seen.values(), key=str) == [False] * 3 + [None] * 3 + [True] * 3
    bare = _spec(label="regime")
    with pytest.raises(SpecError, match=r"sampler\.label='regime'.*labels = \[negative, positive\]"):
        BoundarySampler().refine(bare, table)


def test_a_rerun_archived_run_replaces_its_committed_row(tmp_path):
    """A committed replicated boundary campaign made by older code (another code hash, and other run keys: a
    parameter added to the model changes every key) without its run folders: ``rerun_archived`` reruns the runs the
    sampler asks for again (round 0, matched to their rows by swept values and seed), and each new run replaces its
    committed row.  The old row was left unmatched, and a sampler's table shows its unmatched rows: the table held
    two rows of each rerun run (24 rows for 15 runs, points.csv counted 24 replicates)."""
    from sweep.campaign.table import build_table

    spec = _spec(budget=15)
    run_campaign(spec, tmp_path, runner=oracle_runner, jobs=1, code_hash="older", progress=None, isolate="none")
    d = tmp_path / "rep_boundary"
    old = pd.read_csv(d / "table.csv")
    old.assign(key="old-" + old["key"]).to_csv(d / "table.csv", index=False)
    (d / "table.parquet").unlink()
    shutil.rmtree(d / "runs")
    res = run_campaign(spec, tmp_path, runner=oracle_runner, jobs=1, code_hash="newer", progress=None,
                       isolate="none", rerun_archived=True)
    assert res.n_executed == 9                                   # the initial design, one run per point
    for table in (pd.read_csv(d / "table.csv"), build_table(spec, tmp_path, code_hash="newer")):
        assert len(table) == len(old) == 15
        assert not table.duplicated(["cement", "eta_o", "seed"]).any()
        assert (table["code_hash"] == "newer").sum() == 9 and (table["code_hash"] == "older").sum() == 6
    assert pd.read_csv(d / "points.csv")["n_runs"].sum() == 15


def test_sampler_state_counts_finished_labelled_runs_as_replicates_never_pending_ones():
    """sampler.json's per-point ``replicates`` are the finished runs with a label (what the fit counts, points.csv
    ``n_ok``); the runs of the current round not yet finished are ``pending`` and a failed run ``unlabelled``, each
    under its own key.  Here the first run of round 0 fails and the first round with replicates is cut after its
    first run: the counts are read off the table and the runs left.  The replicate count was the highest replicate
    index proposed plus one, pending and failed runs included."""
    spec = _spec()
    s, rows = BoundarySampler(), []
    pts = s.initial(spec)
    base = min(p.params["seed"] for p in pts)

    def run(batch):
        return [{"status": "ok", "cement": p.params["cement"], "eta_o": p.params["eta_o"], "seed": p.params["seed"],
                 "fracturing": ORACLE.label((p.params["cement"], p.params["eta_o"]), p.params["seed"], 0)}
                for p in batch]

    rows = run(pts)
    rows[0] = {**rows[0], "status": "failed", "fracturing": None}
    pts = s.refine(spec, pd.DataFrame(rows))
    while pts and not any(p.params["seed"] > base for p in pts):     # up to the first round with a replicate
        rows += run(pts)
        pts = s.refine(spec, pd.DataFrame(rows))
    left = pts[1:]
    table = pd.DataFrame(rows + run(pts[:1]))
    st = BoundarySampler().state(spec, table)
    assert st["pending"] == len(left) >= 1 and not st["stopped"]
    got = {(p["cement"], p["eta_o"]): (p["replicates"], p["unlabelled"], p["pending"]) for p in st["points"]}
    want: dict = {}
    for k, ok in zip(zip(table["cement"], table["eta_o"]), table["status"] == "ok"):
        r, u, n = want.get(k, (0, 0, 0))
        want[k] = (r + int(ok), u + int(not ok), n)
    for p in left:
        r, u, n = want.get((p.params["cement"], p.params["eta_o"]), (0, 0, 0))
        want[(p.params["cement"], p.params["eta_o"])] = (r, u, n + 1)
    assert got == want
    assert sum(r for r, _, _ in got.values()) == len(table) - 1 and sum(u for _, u, _ in got.values()) == 1
    assert any(r >= 1 and n >= 1 for r, _, n in got.values())          # a point with a pending replicate


def test_cli_status_of_a_replicated_boundary_campaign(tmp_path, capsys):
    """``campaign status`` on a boundary campaign with replicates states the round, the budget and the replicate
    counts (it failed with KeyError 'uncertainty': the replicated sampler's state has a band, not that key)."""
    from sweep.campaign.cli import main as cli_main
    from sweep.campaign.spec import load_spec

    path = tmp_path / "rep_boundary.toml"
    path.write_text('name = "rep_boundary"\n[base]\neta_w = 1e-6\nkbar = 0.0015\n[options]\nh = 4.0\n[axes]\n'
                    'cement = {linear = [0.5, 3.0, 3]}\neta_o = {log = [0.01, 10.0, 3]}\n[replicates]\nporosity_seed = 5\n'
                    '[sampler]\nkind = "boundary"\nbudget = 15\ntolerance = 0.1\nlabel = "fracturing"\nbatch = 6\n'
                    'band_tolerance = 0.3\n[run]\nisolate = "none"\n')
    run_campaign(load_spec(path), tmp_path, runner=oracle_runner, jobs=1, code_hash="t", progress=None)
    assert cli_main(["status", str(path), "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    st = json.loads((tmp_path / "rep_boundary" / "sampler.json").read_text())
    assert f"boundary sampler: round {st['round']}, 15 of 15 runs used, 0 pending" in out
    assert f"15 labelled runs at {len(st['points'])} points (at most 5 each), 0 pending" in out
    assert "stopped: budget spent" in out


def test_a_campaign_committed_part_way_resumes_on_another_machine(tmp_path):
    """The table of a replicated boundary campaign copied part-way, without its run folders (another machine):
    ``run`` replays the sampler's rounds from the committed rows, runs only the rest and ends with the runs of the
    uninterrupted campaign.  A committed row must stand for its own replicate: matched by swept values alone, a
    point's replicate 1 took its replicate 0's row and the campaign stopped with a round pending."""

    spec = _spec(budget=40)
    run_campaign(spec, tmp_path / "whole", runner=oracle_runner, jobs=1, code_hash="test-rb", progress=None)
    whole = pd.read_csv(tmp_path / "whole" / "rep_boundary" / "table.csv")
    assert whole.groupby(["cement", "eta_o"])["seed"].max().max() >= 1          # replicates were made
    cut = int(whole["index"][whole["seed"] >= 1].min()) + 1                     # just after a first replicate
    part = tmp_path / "other" / "rep_boundary"
    part.mkdir(parents=True)
    kept = whole[whole["index"] < cut]
    kept.to_csv(part / "table.csv", index=False)
    res = run_campaign(spec, tmp_path / "other", runner=oracle_runner, jobs=1, code_hash="test-rb", progress=None)
    again = pd.read_csv(part / "table.csv")
    st = json.loads((part / "sampler.json").read_text())
    assert res.n_executed == len(whole) - len(kept) and st["stopped"] and st["pending"] == 0
    assert sorted(again["key"]) == sorted(whole["key"])

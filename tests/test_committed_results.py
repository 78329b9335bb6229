"""Committed campaigns are first-class results (issue #52): a campaign whose table is committed and whose run
folders are absent is *archived*, not pending; status, plot, report and the loaders work from its table, from any
working directory, and nothing replaces a committed file with an emptier one.  Each test works on a copy of a
committed campaign (spec and results folder, without run folders) in a temporary project."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from sweep.campaign.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]


def copy_campaign(tmp_path: Path, rel_spec: str, name: str) -> tuple[Path, Path]:
    """(spec, campaign folder) of a copy of a committed campaign in ``tmp_path/proj``, run folders left out."""
    proj = tmp_path / "proj"
    spec = proj / "campaigns" / rel_spec
    spec.parent.mkdir(parents=True)
    shutil.copy2(ROOT / "campaigns" / rel_spec, spec)
    shutil.copytree(ROOT / "results" / name, proj / "results" / name, ignore=shutil.ignore_patterns("runs"))
    return spec, proj / "results" / name


@pytest.fixture
def demo(tmp_path, monkeypatch):
    spec, folder = copy_campaign(tmp_path, "examples/demo.toml", "demo")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # paths resolve against the spec's project, not the working directory
    return spec, folder


def _cli(capsys, *args):
    rc = cli_main([str(a) for a in args])
    out = capsys.readouterr()
    return rc, out.out + out.err


def test_status_counts_an_archived_campaign_from_its_table(demo, capsys):
    spec, folder = demo
    rc, out = _cli(capsys, "status", spec)
    assert rc == 0
    assert "6 runs: 0 done, 0 failed, 0 pending, 6 archived, 0 damaged" in out and str(folder) in out
    assert "archived (rows of the committed table, run folders not here): 6 (6 ok, 0 failed)" in out
    assert "runs by code:" in out


def test_run_reruns_nothing_unless_asked_and_prints_the_cost_first(demo, capsys, monkeypatch):
    spec, folder = demo
    before = (folder / "table.csv").read_bytes()

    def no_solver(plan, todo, *a, **k):
        assert not todo, f"campaign run executed {len(todo)} archived runs"

    monkeypatch.setattr("sweep.campaign.run._execute", no_solver)
    rc, out = _cli(capsys, "run", spec, "--quiet")
    assert rc == 0 and "0 executed now" in out and "nothing to rerun: 6 archived" in out
    assert (folder / "table.csv").read_bytes() == before  # a committed table is rewritten only by new runs
    rc, out = _cli(capsys, "run", spec, "--dry-run", "--rerun-archived")
    assert rc == 0 and "estimated cost of the 6 run(s) to do" in out


def test_plot_and_report_work_from_the_table_and_keep_what_they_cannot_redraw(demo, capsys):
    spec, folder = demo
    grid = (folder / "figures" / "porosity_grid.png").read_bytes()
    rc, out = _cli(capsys, "plot", spec)
    assert rc == 0 and "ca_star_vs_cement.png" in out
    assert "porosity_grid.png kept as it is" in out  # its snapshots are not committed
    assert (folder / "figures" / "porosity_grid.png").read_bytes() == grid
    rc, out = _cli(capsys, "report", spec)
    assert rc == 0
    text = (folder / "report.md").read_text()
    assert "- archived (rows of the committed table, run folders not here): 6 (6 ok, 0 failed)" in text
    assert text.count("| ok |") == 6


def test_a_report_never_replaces_a_committed_table_with_an_emptier_one(demo, capsys):
    spec, folder = demo
    spec.write_text(spec.read_text().replace("cement = [0.5, 1.5, 3.0]", "cement = [0.5, 1.5]"))
    before = (folder / "report.md").read_bytes(), (folder / "table.csv").read_bytes()
    rc, out = _cli(capsys, "report", spec)
    assert rc == 1 and "4 rows" in out and "6" in out and "nothing written" in out
    assert ((folder / "report.md").read_bytes(), (folder / "table.csv").read_bytes()) == before


def test_load_campaign_from_another_directory_and_units(demo):
    from sweep import load_campaign

    spec, folder = demo
    d = load_campaign(spec)
    assert len(d) == 6 and d.attrs["campaign_dir"] == str(folder)
    assert str(d["Ca_star"].dtype) == "Float64" and d.attrs["units"]["cement"] == "%"


def test_an_empty_result_is_an_error_naming_the_folder(tmp_path):
    from sweep import load_campaign

    spec, folder = copy_campaign(tmp_path, "examples/demo.toml", "demo")
    shutil.rmtree(folder)
    with pytest.raises(FileNotFoundError, match=str(folder)):
        load_campaign(spec)


def test_load_timeseries_and_compare_name_what_is_missing(demo, capsys):
    from sweep import load_timeseries

    spec, folder = demo
    with pytest.raises(FileNotFoundError, match="run folders .*runs.* are not here"):
        load_timeseries(spec)
    rc, out = _cli(capsys, "compare", spec, folder.parent / "nowhere")
    assert rc == 2 and "nowhere" in out and "no column" not in out


def test_load_run_reads_a_pruned_committed_run_and_names_what_it_lacks():
    from sweep import load_run

    runs = ROOT / "results" / "ca_star_boundary_h1_floor" / "runs"
    run = load_run(next(p for p in sorted(runs.iterdir()) if (p / "params.toml").is_file()))
    assert run.units["cement"] == "%" and run.units["p_inj"] == "kPa" and run.timeseries.attrs["units"]["t"] == "s"
    assert len(run.timeseries) > 1 and run.options["h"] == 1.0
    assert len(run.snapshots) == 1 and {"t", "S", "phi"} <= set(run.snapshots[0])  # the classified snapshot
    assert run.mesh["points"].shape[1] == 2 and run.mesh["triangles"].shape[1] == 3
    assert any("(pruned)" in m for m in run.missing)


def test_load_run_refuses_a_folder_that_is_not_a_run(tmp_path):
    from sweep import load_run

    with pytest.raises(FileNotFoundError, match=str(tmp_path)):
        load_run(tmp_path)


def test_load_timeseries_of_committed_pruned_runs_has_units():
    from sweep import load_timeseries

    ts = load_timeseries(ROOT / "campaigns" / "studies" / "ca_star_boundary_h2_pockets_tip.toml")
    assert ts["key"].nunique() == 34 and ts.attrs["units"]["p_inj"] == "kPa" and ts.attrs["units"]["cement"] == "%"


def test_animate_on_a_pruned_run_names_what_is_missing(capsys):
    from sweep.cli import main

    runs = ROOT / "results" / "ca_star_boundary_h1_floor" / "runs"
    run = next(p for p in sorted(runs.iterdir()) if (p / "params.toml").is_file())
    assert main(["animate", str(run), "--fields", "S,d"]) == 2
    err = capsys.readouterr().err
    assert "not d" in err and "pruned" in err and "Traceback" not in err
    assert main(["animate", str(run), "--fields", "S,phi"]) == 2
    assert "one snapshot" in capsys.readouterr().err


def test_a_command_line_run_writes_frames_for_an_animation(tmp_path):
    import argparse

    from sweep.cli import CLI_FRAMES, _run_inputs

    args = argparse.Namespace(config=None, set=[], h=None, t_end=None, out=str(tmp_path / "r"))
    assert _run_inputs(args)[1].frames == CLI_FRAMES >= 10
    args.set = ["frames=3"]
    assert _run_inputs(args)[1].frames == 3


def test_an_archived_row_of_a_resumed_run_takes_the_solvers_whole_wall_time(demo):
    """A committed row written from an older record of a run resumed from its checkpoint holds the last piece's
    wall time only; the solver's own wall time (which carries the earlier pieces) raises it, other rows stay."""
    import pandas as pd

    from sweep.campaign.spec import load_spec
    from sweep.campaign.table import build_table

    spec, folder = demo
    t = pd.read_parquet(folder / "table.parquet")
    t.loc[0, "solver_wall_time_s"] = t.loc[0, "wall_time_s"] + 1000.0  # the earlier pieces' 1,000 s
    t.to_parquet(folder / "table.parquet")
    out = build_table(load_spec(spec), folder.parent)
    assert out["wall_time_s"].iloc[0] == pytest.approx(t.loc[0, "wall_time_s"] + 1000.0)
    assert out["wall_time_s"].iloc[1:].tolist() == pytest.approx(t["wall_time_s"].iloc[1:].tolist())

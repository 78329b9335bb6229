"""Damaged results are detected: status names them, run reruns them, plot/report/classify refuse them.

Runs are written in the solver's format by ``contract_runner`` (tests/test_campaign_run.py) plus a
summary.json; the damage is done by hand afterwards, as a user or a disk would.
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from sweep.campaign.plan import DamagedRunsError, plan_campaign

from sweep.campaign.table import build_table

from sweep.campaign.plot import plot_campaign

from sweep.campaign.run import reclassify, run_campaign
from sweep.campaign.cli import main as cli_main
from sweep.campaign.store import file_manifest, verify_run

pytest.importorskip("sweep.regimes.classify")


def solver_format_runner(params, options, run_dir):
    """contract_runner's run folder (snapshots, time series) and a summary.json, classified by sweep.regimes.classify."""
    from sweep.regimes.classify import classify_run
    from sweep.campaign.scheduler import classification_dict
    from test_campaign_run import contract_runner

    contract_runner(params, options, run_dir)
    Path(run_dir, "summary.json").write_text(json.dumps({"status": "ok", "t_reached": 1.0}))
    return {"status": "ok", "classification": classification_dict(classify_run(run_dir))}


_SPEC = """
name = "fourruns"
[axes]
eta_o = [0.25, 0.5, 0.75, 1.0]
[[diagrams]]
kind = "timeseries"
x = "t"
y = "p_inj"
by = "eta_o"
[run]
runner = "test_damaged_runs:solver_format_runner"
isolate = "none"
"""


@pytest.fixture
def campaign(tmp_path):
    spec = tmp_path / "fourruns.toml"
    spec.write_text(_SPEC)
    root = tmp_path / "res"
    assert cli_main(["run", str(spec), "--results", str(root), "--quiet"]) == 0
    plan = plan_campaign(spec, root)
    return spec, root, [plan.store.run_dir(k) for k in plan.keys]


def _damage(run_dirs):
    """Corrupted summary.json, deleted timeseries.csv, deleted snapshots/; the 4th run is intact."""
    (run_dirs[0] / "summary.json").write_text('{"status": "ok", "t_reach')
    (run_dirs[1] / "timeseries.csv").unlink()
    for f in (run_dirs[2] / "snapshots").iterdir():
        f.unlink()
    (run_dirs[2] / "snapshots").rmdir()


def test_record_lists_each_file_with_size_and_checksum(campaign):
    _, _, dirs = campaign
    rec = json.loads((dirs[0] / "record.json").read_text())
    assert rec["files"] == file_manifest(dirs[0])
    assert {"summary.json", "timeseries.csv", "snapshots/mesh.npz"} <= set(rec["files"])
    assert verify_run(dirs[0], rec) == []


def test_a_same_size_change_is_found_by_its_checksum(campaign):
    _, _, dirs = campaign
    f = dirs[3] / "snapshots" / "snap_00001.npz"
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    rec = json.loads((dirs[3] / "record.json").read_text())
    assert "snapshots/snap_00001.npz differs from the file the record wrote (SHA-256)" in verify_run(dirs[3], rec)


def test_status_names_the_damaged_runs_and_run_repairs_them(campaign, capsys):
    spec, root, dirs = campaign
    before = build_table(spec, root)
    _damage(dirs)
    capsys.readouterr()
    assert cli_main(["status", str(spec), "--results", str(root)]) == 1
    out = capsys.readouterr().out
    assert "1 done, 0 failed, 0 pending, 0 archived, 3 damaged" in out
    assert f"damaged {dirs[0].name} (eta_o=0.25): " in out and "summary.json does not parse" in out
    assert f"damaged {dirs[1].name} (eta_o=0.5): timeseries.csv is missing" in out
    assert f"damaged {dirs[2].name} (eta_o=0.75): snapshots/mesh.npz is missing" in out
    # the table does not keep the old regime of a run whose snapshots are gone
    t = build_table(spec, root).set_index("eta_o")
    assert list(t["status"]) == ["damaged", "damaged", "damaged", "ok"]
    assert t["regime"].isna().tolist() == [True, True, True, False]

    assert cli_main(["run", str(spec), "--results", str(root), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "3 executed now" in out and "reran 3 damaged run(s)" in out
    after = build_table(spec, root)
    cols = ["key", "status", "regime", "front_radius_mean"]
    pd.testing.assert_frame_equal(after[cols], before[cols])


def test_plot_report_and_classify_refuse_damaged_runs_naming_them(campaign, capsys):
    spec, root, dirs = campaign
    (dirs[1] / "timeseries.csv").unlink()
    figure = root / "fourruns" / "figures" / "timeseries.png"
    for cmd in ("plot", "report", "classify"):
        capsys.readouterr()
        assert cli_main([cmd, str(spec), "--results", str(root)]) == 1, cmd
        err = capsys.readouterr().err
        assert "1 damaged run(s)" in err and f"{dirs[1].name} (eta_o=0.5): timeseries.csv is missing" in err, cmd
    assert not figure.exists()  # no figure with 3 of 4 curves
    with pytest.raises(DamagedRunsError, match=dirs[1].name):
        reclassify(spec, root)
    figs = plot_campaign(spec, root, allow_damaged=True)  # asked for: drawn without it, with a warning
    assert figs == [figure, figure.with_suffix(".pdf")] and "left out" in capsys.readouterr().err


def test_a_lost_record_is_a_damaged_run(campaign):
    spec, root, dirs = campaign
    (dirs[0] / "record.json").write_text("{")
    plan = plan_campaign(spec, root)
    assert [k for _, k in plan.damaged] == [dirs[0].name]
    assert plan.problems(dirs[0].name) == ["record.json is missing or does not parse"]
    res = run_campaign(spec, root, progress=None)
    assert res.damaged_rerun == [dirs[0].name] and res.n_executed == 1


def test_a_record_without_a_file_list_still_needs_the_snapshots_it_was_classified_from(campaign):
    spec, root, dirs = campaign
    f = dirs[2] / "record.json"
    rec = json.loads(f.read_text())
    del rec["files"]
    f.write_text(json.dumps(rec))
    (dirs[2] / "params.toml").write_text("")  # a solver run folder
    assert verify_run(dirs[2], rec) == []
    for p in (dirs[2] / "snapshots").iterdir():
        p.unlink()
    assert verify_run(dirs[2], rec) == ["snapshots/mesh.npz is missing"]


def test_columns_compare_and_load_timeseries_name_the_damaged_runs(campaign, capsys):
    """Issue #48: these skipped damaged runs silently (load_timeseries returned 5 of 6 series)."""
    import warnings

    from sweep.campaign.load import load_timeseries

    spec, root, dirs = campaign
    _damage(dirs)
    capsys.readouterr()
    assert cli_main(["columns", str(spec), "--results", str(root)]) == 0
    err = capsys.readouterr().err
    assert "3 damaged run(s)" in err and f"damaged {dirs[1].name} (eta_o=0.5): timeseries.csv is missing" in err
    assert cli_main(["compare", str(spec), str(spec), "--results", str(root)]) == 0
    assert f"damaged {dirs[1].name} (eta_o=0.5): timeseries.csv is missing" in capsys.readouterr().err
    with pytest.raises(DamagedRunsError, match=f"{dirs[1].name} .*timeseries.csv: missing"):
        load_timeseries(spec, root)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        ts = load_timeseries(spec, root, allow_damaged=True)
    assert any(dirs[1].name in str(x.message) for x in w)
    assert dirs[1].name not in set(ts["key"])

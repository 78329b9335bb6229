"""Results keyed on the code that made them: code hashes, stale campaign runs, the forward cache.

A change of the solver's source is simulated by replacing ``solver.codehash.code_hash`` (what every
reader of the current hash calls), never by editing the real files; the hash itself is tested on a
temporary copy of the package.
"""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from solver import codehash
from sweep.regimes import provenance
from sweep.campaign.plan import plan_campaign
from sweep.campaign.run import run_campaign
from sweep.campaign.cli import main as cli_main
from sweep.campaign.spec import spec_from_dict

SOLVER_DIR = Path(codehash.__file__).resolve().parent


def one_run_runner(params, options, run_dir):
    """A cheap run: writes its input product and returns it as a metric."""
    x = params["eta_o"] * params["w_i"]
    Path(run_dir, "out.json").write_text(json.dumps({"x": x}))
    return {"status": "ok", "regime": "porous_invasion", "metrics": {"x": x}}


def _copy_solver(dst: Path) -> Path:
    dst.mkdir(parents=True)
    for f in SOLVER_DIR.glob("*.py"):
        shutil.copy2(f, dst / f.name)
    return dst


def _pretend_code(monkeypatch, h: str) -> None:
    monkeypatch.setattr(codehash, "code_hash", lambda: h)


# ---------------------------------------------------------------------------
# the hash
# ---------------------------------------------------------------------------
def test_code_hash_is_the_hash_of_the_package_files_wherever_they_are(tmp_path):
    copy = _copy_solver(tmp_path / "solver")
    assert codehash.directory_hash(copy) == codehash.code_hash()  # content, not location
    assert len(codehash.code_hash()) == codehash.HASH_DIGITS


def test_code_hash_changes_with_a_solver_source_file_not_with_its_time_stamp(tmp_path):
    copy = _copy_solver(tmp_path / "solver")
    before = codehash.directory_hash(copy)
    physics = copy / "physics.py"
    physics.touch()  # new modification time, same content
    assert codehash.directory_hash(copy) == before
    physics.write_text(physics.read_text() + "\n\ndef unused():\n    return 0\n")
    assert codehash.directory_hash(copy) != before
    (copy / "physics.py").unlink()
    assert codehash.directory_hash(copy) != before


def test_git_hashes_give_the_hash_of_a_committed_copy(tmp_path):
    if shutil.which("git") is None:
        pytest.skip("git not installed")
    repo = tmp_path / "repo"
    _copy_solver(repo / "solver")
    (repo / "sweep").mkdir()
    (repo / "sweep" / "regimes").mkdir()
    shutil.copy2(SOLVER_DIR.parent / "sweep" / "regimes" / "classify.py", repo / "sweep" / "regimes" / "classify.py")
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "."], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "c"], check=True)
    h = provenance.git_hashes("HEAD", repo)
    assert h == {"code_hash": codehash.code_hash(), "classifier_hash": provenance.classifier_code_hash()}


def test_the_classifier_hash_is_unchanged_by_the_move_of_its_file(tmp_path):
    """A revision holding the classifier at its logical (old) path hashes like one holding it at today's path."""
    if shutil.which("git") is None:
        pytest.skip("git not installed")
    repo = tmp_path / "repo"
    _copy_solver(repo / "solver")
    (repo / "sweep").mkdir()
    shutil.copy2(SOLVER_DIR.parent / "sweep" / "regimes" / "classify.py", repo / "sweep" / "classify.py")
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "."], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "c"], check=True)
    assert provenance.git_hashes("HEAD", repo)["classifier_hash"] == provenance.classifier_code_hash()


# ---------------------------------------------------------------------------
# a one-run campaign whose code changes (the scenario)
# ---------------------------------------------------------------------------
_SPEC = """
name = "onerun"
[base]
w_i = 10.0
[options]
h = 4.0
t_end = 0.01
[axes]
eta_o = [0.5]
[run]
runner = "test_code_provenance:one_run_runner"
"""


def _cli(capsys, *args):
    rc = cli_main(list(args))
    out = capsys.readouterr()
    return rc, out.out + out.err


def test_a_run_of_other_code_is_stale_kept_and_rerun_only_when_asked(tmp_path, capsys, monkeypatch):
    """Stale decides nothing on its own: status lists the code of the runs, run keeps them unless --rerun-stale."""
    spec = tmp_path / "onerun.toml"
    spec.write_text(_SPEC)
    res = ["--results", str(tmp_path / "res")]
    _pretend_code(monkeypatch, "aaaaaaaaaaaaaaaa")
    rc, out = _cli(capsys, "run", str(spec), *res, "--quiet")
    assert rc == 0 and "1 executed now" in out
    rc, out = _cli(capsys, "status", str(spec), *res)
    assert "1 done, 0 failed, 0 pending, 0 archived, 0 damaged" in out and "aaaaaaaaaaaaaaaa (current): 1" in out
    assert "made by other code" not in out

    _pretend_code(monkeypatch, "bbbbbbbbbbbbbbbb")  # the solver's source changed
    rc, out = _cli(capsys, "status", str(spec), *res)
    assert "1 done, 0 failed, 0 pending, 0 archived, 0 damaged" in out  # still used
    assert "1 made by other code (stale)" in out
    assert "aaaaaaaaaaaaaaaa: 1" in out and "current code: solver bbbbbbbbbbbbbbbb" in out
    rc, out = _cli(capsys, "run", str(spec), *res, "--quiet")
    assert rc == 0 and "0 executed now" in out and "kept 1 run(s) made by other solver code" in out
    for flag in ([], ["--accept-stale"]):  # --accept-stale: the default, kept for old scripts
        rc, out = _cli(capsys, "run", str(spec), *res, "--quiet", *flag)
        assert rc == 0 and "0 executed now" in out
    rc, out = _cli(capsys, "run", str(spec), *res, "--dry-run", "--rerun-stale")
    assert "1 made by other code to rerun" in out

    rc, out = _cli(capsys, "run", str(spec), *res, "--quiet", "--rerun-stale")
    assert rc == 0 and "1 executed now" in out and "reran 1 run(s) made by other solver code" in out
    assert "1 run(s) to do, estimated" in out  # the cost is printed before the run starts
    key = plan_campaign(spec, tmp_path / "res").keys[0]
    rec = json.loads((tmp_path / "res" / "onerun" / "runs" / key / "record.json").read_text())
    assert rec["code_hash"] == "bbbbbbbbbbbbbbbb"
    table = (tmp_path / "res" / "onerun" / "table.csv").read_text()
    assert "bbbbbbbbbbbbbbbb" in table  # the table states the code of each run


def test_a_record_without_a_code_hash_is_stale_and_keeps_its_folder(tmp_path, monkeypatch):
    """Runs stored before records had a code hash keep their key (folder) and count as stale."""
    _pretend_code(monkeypatch, "aaaaaaaaaaaaaaaa")
    spec = spec_from_dict({"name": "legacy", "base": {"w_i": 10.0}, "axes": {"eta_o": [0.5, 1.0]}})
    run_campaign(spec, tmp_path, runner=one_run_runner, progress=None)
    plan = plan_campaign(spec, tmp_path)
    f = plan.store.run_dir(plan.keys[0]) / "record.json"
    rec = json.loads(f.read_text())
    del rec["code_hash"]
    rec["solver_version"] = "0.1.0"
    f.write_text(json.dumps(rec))
    plan = plan_campaign(spec, tmp_path)
    assert [k for _, k in plan.stale] == [plan.keys[0]] and len(plan.done) == 2
    kept = run_campaign(spec, tmp_path, runner=one_run_runner, progress=None)
    assert kept.n_executed == 0 and kept.stale_reused == [plan.keys[0]]
    again = run_campaign(spec, tmp_path, runner=one_run_runner, progress=None, rerun_stale=True)
    assert again.n_executed == 1 and again.stale_rerun == [plan.keys[0]]


def test_labels_of_other_classifier_code_are_kept_unless_relabel_is_asked(tmp_path, monkeypatch):
    pytest.importorskip("sweep.regimes.classify")
    from test_campaign_run import contract_runner

    def labelled_by_old_classifier(params, options, run_dir):
        out = contract_runner(params, options, run_dir)
        return {**out, "regime": "viscous_fingering", "classifier_hash": "0ld0ld0ld0ld0ld0"}

    spec = spec_from_dict({"name": "relabel", "axes": {"eta_o": [0.25]}})
    first = run_campaign(spec, tmp_path, runner=labelled_by_old_classifier, progress=None, isolate="none")
    key = first.table["key"][0]
    record = tmp_path / "relabel" / "runs" / key / "record.json"
    assert first.reclassified == [] and first.labels_kept == [key]       # kept, listed, not relabelled
    assert json.loads(record.read_text())["classifier_hash"] == "0ld0ld0ld0ld0ld0"
    assert first.table["regime"][0] == "viscous_fingering"
    assert first.table["classifier_hash"][0] == "0ld0ld0ld0ld0ld0"     # the table shows which code labelled it
    asked = run_campaign(spec, tmp_path, runner=labelled_by_old_classifier, progress=None, isolate="none",
                         relabel=True)
    assert asked.n_executed == 0 and asked.reclassified == [key]
    rec = json.loads(record.read_text())
    assert rec["classifier_hash"] == provenance.classifier_code_hash()
    assert rec["classification"]["regime"] == "uniform_invasion"  # S = 1 inside a circle, no crack
    again = run_campaign(spec, tmp_path, runner=labelled_by_old_classifier, progress=None, isolate="none")
    assert again.n_executed == 0 and again.reclassified == [] and again.labels_kept == []


# ---------------------------------------------------------------------------
# the discrepancy forward cache
# ---------------------------------------------------------------------------
def _entry(rd: Path, status: str, code: str, rows: int = 3) -> Path:
    rd.mkdir(parents=True)
    (rd / "summary.json").write_text(json.dumps({"status": status, "code_hash": code, "t_reached": 0.002 * rows}))
    t = np.arange(rows) * 0.002
    lines = ["t,p_inj,front_radius_mean,open_tip_radius"] + [f"{x},{100 * x},{5 + x},0" for x in t]
    (rd / "timeseries.csv").write_text("\n".join(lines) + "\n")
    return rd


def test_forward_cache_reads_only_finished_runs_of_the_current_code(tmp_path):
    from sweep.discrepancy.forward import finished

    here = codehash.code_hash()
    assert finished(_entry(tmp_path / "ok", "ok", here))
    assert finished(_entry(tmp_path / "failed", "failed", here))  # a recorded failure is a finished entry
    assert not finished(_entry(tmp_path / "other", "ok", "0" * 16))
    assert not finished(_entry(tmp_path / "nohash", "ok", None))
    assert not finished(_entry(tmp_path / "running", "running", here))
    damaged = _entry(tmp_path / "damaged", "ok", here)
    (damaged / "timeseries.csv").write_text("")
    assert not finished(damaged)


def test_a_forward_run_that_raises_is_a_recorded_failure_read_as_no_prediction(tmp_path, monkeypatch):
    import solver
    from solver import RunOptions
    from sweep.discrepancy.forward import SolverForward, finished

    def broken(*a, **k):
        raise ValueError("mesh size h = 8 mm is too large for the annulus")

    monkeypatch.setattr(solver, "simulate", broken)
    fwd = SolverForward({}, RunOptions(h=8.0, t_end=0.006), tmp_path)
    times = {"p_inj": np.array([0.002, 0.004]), "regime": None}
    pred = fwd.predict_one({"r_outer": 20.0}, times)
    assert np.isnan(pred["p_inj"]).all() and pred["regime"] is None
    rd = fwd.run_dir({"r_outer": 20.0})
    summ = json.loads((rd / "summary.json").read_text())
    assert summ["status"] == "failed" and "too large" in summ["reason"] and finished(rd)
    fwd.predict_one({"r_outer": 20.0}, times)
    assert fwd.n_runs == 1  # the recorded failure is not rerun by the same code ...
    monkeypatch.setattr(codehash, "code_hash", lambda: "dddddddddddddddd")
    fwd.predict_one({"r_outer": 20.0}, times)
    assert fwd.n_runs == 2  # ... but is by other code


def test_summary_json_states_the_code_hash(tmp_path):
    from solver.output import RunWriter

    w = RunWriter(tmp_path / "run")
    w._summary({"status": "running"})
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["code_hash"] == codehash.code_hash()

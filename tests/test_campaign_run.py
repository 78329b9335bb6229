"""Campaign execution: isolation, timeout, retries, fail-fast, resume after Ctrl-C, dask = loky, CLI.

The runners below are real run functions (module level, so that worker and child processes
can import them): they compute known answers from their parameters and write files in
their run folder, or fail, hang, or count their attempts.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from sweep.campaign.table import build_table

from sweep.campaign.plan import plan_campaign

from sweep.campaign.run import run_campaign

from sweep.campaign.report import write_report
from sweep.campaign.cli import main as cli_main
from sweep.campaign.columns import typed_table
from sweep.campaign.spec import spec_from_dict

VERSION = "test-1"
HERE = Path(__file__).resolve().parent
VOLATILE = ["wall_time_s", "host", "finished_at", "run_dir"]


# ---------------------------------------------------------------------------
# runners
# ---------------------------------------------------------------------------
def toy_runner(params, options, run_dir):
    """Ca*-like product eta_o * w_i (kPa*mm/s... any consistent unit) and a threshold in C."""
    x = params["eta_o"] * params["w_i"]
    Path(run_dir, "out.json").write_text(json.dumps({"x": x}))
    regime = "fracturing" if x > 2.0 * params["cement"] else "porous_invasion"
    return {"status": "ok", "regime": regime, "metrics": {"x": x, "h_used": options["h"]}}


def failing_runner(params, options, run_dir):
    """Raises for cement == 2.0, reports a non-converged run for cement == 3.0."""
    if params["cement"] == 2.0:
        raise RuntimeError(f"boom at cement={params['cement']}")
    if params["cement"] == 3.0:
        return {"status": "failed", "reason": "Newton did not converge at t=0.3 s"}
    return toy_runner(params, options, run_dir)


def _block(run_dir) -> None:
    """Mark the run as started (its pid in ``run_dir/started``), then block until ``run_dir/release`` exists:
    a file only a test could create (none does), so no clock decides when the run ends."""
    Path(run_dir, "started").write_text(str(os.getpid()))
    while not Path(run_dir, "release").exists():
        time.sleep(0.02)


def hanging_runner(params, options, run_dir):
    """Hangs for cement == 3.0 and eta_o == 0.5 after writing its pid: only the timeout's kill ends it."""
    Path(run_dir, "pid").write_text(str(os.getpid()))
    if params["cement"] == 3.0 and params["eta_o"] == 0.5:
        _block(run_dir)
    return toy_runner(params, options, run_dir)


def gated_runner(params, options, run_dir):
    """toy_runner at once for cement == 1.0; every other run blocks (never released), so the campaign
    cannot finish before the test's SIGINT, whatever the load."""
    if params["cement"] != 1.0:
        _block(run_dir)
    return toy_runner(params, options, run_dir)


def flaky_runner(params, options, run_dir):
    """Fails on the first attempt of each point, succeeds on the second (counter in $FLAKY_DIR)."""
    counter = Path(os.environ["FLAKY_DIR"]) / f"c{params['cement']}"
    n = int(counter.read_text()) + 1 if counter.exists() else 1
    counter.write_text(str(n))
    if n == 1:
        raise OSError("transient")
    return toy_runner(params, options, run_dir)


def _spec(**extra):
    d = {"name": "toy", "base": {"w_i": 10.0}, "options": {"h": 4.0},
         "axes": {"cement": [1.0, 2.0, 3.0], "eta_o": [0.1, 0.5]}}
    d.update(extra)
    return spec_from_dict(d)


def _stable(df):
    return df.drop(columns=[c for c in VOLATILE if c in df.columns]).reset_index(drop=True)


# ---------------------------------------------------------------------------
# results and table
# ---------------------------------------------------------------------------
def test_table_rows_known_answers_and_store_layout(tmp_path):
    res = run_campaign(_spec(), tmp_path, runner=toy_runner, jobs=2, code_hash=VERSION, progress=None)
    assert (res.n_points, res.n_executed, res.n_ok, res.n_failed) == (6, 6, 6, 0)
    t = pd.read_csv(tmp_path / "toy" / "table.csv")
    assert list(t["index"]) == list(range(6))
    assert list(zip(t["cement"], t["eta_o"])) == [(1.0, 0.1), (1.0, 0.5), (2.0, 0.1), (2.0, 0.5), (3.0, 0.1), (3.0, 0.5)]
    assert list(t["x"]) == pytest.approx(list(t["eta_o"] * 10.0), rel=1e-15)
    # x = 10 eta_o (1 or 5) against 2 C (2, 4, 6): fracturing only for (C=1, 0.5) and (C=2, 0.5)
    assert list(t["regime"]) == ["porous_invasion", "fracturing", "porous_invasion", "fracturing",
                                 "porous_invasion", "porous_invasion"]
    assert set(t["status"]) == {"ok"} and list(t["h_used"]) == [4.0] * 6
    # dimensionless numbers of sweep.regimes.numbers: Ca = eta_o w_i / gamma (gamma = 0.03 kPa*mm by default)
    assert list(t["Ca"]) == pytest.approx(list(t["eta_o"] * 10.0 / 0.03), rel=1e-12)
    for key in t["key"]:
        d = tmp_path / "toy" / "runs" / key
        rec = json.loads((d / "record.json").read_text())
        assert rec["status"] == "ok" and rec["code_hash"] == VERSION
        assert json.loads((d / "out.json").read_text())["x"] == pytest.approx(rec["params"]["eta_o"] * 10.0)
    assert not [p for p in (tmp_path / "toy" / "runs").iterdir() if p.name.startswith(".")]
    assert res.table_paths == [tmp_path / "toy" / f for f in ("table.csv", "table.parquet", "columns.csv")]
    pq = pd.read_parquet(tmp_path / "toy" / "table.parquet")
    pd.testing.assert_frame_equal(_stable(pq), _stable(typed_table(res.table)))


def test_failures_are_isolated_and_their_reasons_tabled(tmp_path):
    res = run_campaign(_spec(), tmp_path, runner=failing_runner, jobs=2, code_hash=VERSION, progress=None)
    assert (res.n_ok, res.n_failed, res.aborted) == (2, 4, False)
    t = res.table.set_index("cement")
    assert set(t.loc[1.0, "status"]) == {"ok"}
    assert all(r.startswith("RuntimeError: boom at cement=2.0") for r in t.loc[2.0, "reason"])
    assert set(t.loc[3.0, "reason"]) == {"Newton did not converge at t=0.3 s"}
    # rerun: failures are recorded, so nothing executes ...
    again = run_campaign(_spec(), tmp_path, runner=toy_runner, jobs=1, code_hash=VERSION, progress=None)
    assert again.n_executed == 0
    # ... unless asked to retry them, which reruns exactly the 4 failures
    retried = run_campaign(_spec(), tmp_path, runner=toy_runner, jobs=1, code_hash=VERSION, progress=None,
                           retry_failed=True)
    assert (retried.n_executed, retried.n_ok) == (4, 4)
    assert set(retried.table["status"]) == {"ok"}


def test_fail_fast_stops_at_the_first_failure(tmp_path):
    res = run_campaign(_spec(), tmp_path, runner=failing_runner, jobs=1, code_hash=VERSION, progress=None,
                       fail_fast=True)
    # grid order: (1, .1) ok, (1, .5) ok, (2, .1) raises -> stop
    assert res.aborted and (res.n_executed, res.n_ok, res.n_failed) == (3, 2, 1)
    plan = plan_campaign(_spec(), tmp_path, code_hash=VERSION)
    assert (len(plan.done), len(plan.failed), len(plan.pending)) == (2, 1, 3)


def test_retries_rerun_a_failed_attempt(tmp_path, monkeypatch):
    monkeypatch.setenv("FLAKY_DIR", str(tmp_path))
    spec = _spec(axes={"cement": [1.0, 2.0]})
    res = run_campaign(spec, tmp_path, runner=flaky_runner, jobs=1, retries=1, code_hash=VERSION, progress=None)
    assert (res.n_ok, res.n_failed) == (2, 0)
    assert list(res.table["attempts"]) == [2, 2]
    assert sorted(int(p.read_text()) for p in tmp_path.glob("c*")) == [2, 2]


def test_timeout_kills_the_hung_run_only(tmp_path):
    # the hung run waits for a release that never comes: the timeout's kill is the only way it ends.  The
    # limit leaves room for a child's start (python + this test module's imports: ~1-2 s on a loaded
    # 2-core machine), so the five other runs finish inside it
    res = run_campaign(_spec(), tmp_path, runner=hanging_runner, jobs=2, timeout=10.0, code_hash=VERSION, progress=None)
    t = res.table
    assert list(t.loc[t["status"] == "failed", "index"]) == [5], list(t["reason"])
    assert (res.n_ok, res.n_failed) == (5, 1)
    hung = t[t["status"] == "failed"]
    assert all(r.startswith("timeout: the run exceeded 10 s") for r in hung["reason"])
    assert all(w >= 10.0 for w in hung["wall_time_s"])
    for key in hung["key"]:
        pid = int((tmp_path / "toy" / "runs" / key / "pid").read_text())
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


_INTERRUPTED = textwrap.dedent("""
    import signal, sys
    signal.signal(signal.SIGINT, signal.default_int_handler)  # a terminal's Ctrl-C, whatever disposition the test
    sys.path[:0] = [{here!r}, {repo!r}]                        # process passed on (an ignored SIGINT is inherited)
    from test_campaign_run import _spec, gated_runner, VERSION
    from sweep.campaign.run import run_campaign
    spec = _spec(axes={{"cement": [1.0, 2.0, 3.0, 4.0], "eta_o": [0.1, 0.5, 0.9]}})
    run_campaign(spec, {root!r}, runner=gated_runner, jobs=2, code_hash=VERSION, progress=None)
""")


def _alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


_HANG_S = 900.0  # s: longer than anything the machine's load makes of a step that ends by itself


def _wait_until(condition, proc, limit_s: float = _HANG_S) -> None:
    """Poll ``condition`` until it holds; fail (never pass) if ``proc`` exits first (while it should run)
    or after ``limit_s``."""
    t0 = time.monotonic()
    while not condition():
        assert proc.returncode is not None or proc.poll() is None, \
            f"the campaign ended early: {proc.communicate()[1].decode()[-2000:]}"
        assert time.monotonic() - t0 < limit_s, "the campaign did not reach the awaited state"
        time.sleep(0.05)


def test_resume_after_ctrl_c_runs_only_the_rest_and_gives_the_same_table(tmp_path):
    # the 3 runs at cement = 1 finish at once; the 9 others block until the test releases them, so the
    # SIGINT lands mid-campaign whatever the machine's load (no clock decides the outcome)
    root = tmp_path / "interrupted"
    spec = _spec(axes={"cement": [1.0, 2.0, 3.0, 4.0], "eta_o": [0.1, 0.5, 0.9]})
    proc = subprocess.Popen([sys.executable, "-c", _INTERRUPTED.format(here=str(HERE), repo=str(HERE.parent), root=str(root))],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    runs = root / "toy" / "runs"
    _wait_until(lambda: len(list(runs.glob("*/record.json"))) >= 3 and any(runs.glob(".tmp-*/started")), proc)
    started = [int(p.read_text() or 0) for p in runs.glob(".tmp-*/started")]
    proc.send_signal(signal.SIGINT)
    # the way out (workers killed, the table rebuilt and written, interpreter shut down) takes seconds; it
    # never waits for the blocked runs.  The bound only tells a hang from a slow machine, so it is far above
    # any load (results/input_validation/README.md: 4-12 s measured, with two CPU-bound processes added)
    _, err = proc.communicate(timeout=_HANG_S)
    assert proc.returncode != 0 and b"KeyboardInterrupt" in err
    # the interrupted campaign stops its workers: the blocked runs never finish (nothing releases them)
    for pid in started:
        _wait_until(lambda: not _alive(pid), proc)
    before = {k: r for k, r in plan_campaign(spec, root, code_hash=VERSION).records.items()}
    k = len(before)
    assert k == 3  # the runs at cement = 1, finished before the interrupt
    assert (root / "toy" / "table.csv").exists()  # written on the way out
    assert len(pd.read_csv(root / "toy" / "table.csv")) == k
    assert not [p for p in runs.iterdir() if p.name.startswith(".")]  # no half-written run left

    res = run_campaign(spec, root, runner=toy_runner, jobs=2, code_hash=VERSION, progress=None)
    assert (res.n_executed, res.n_skipped) == (12 - k, k)
    after = plan_campaign(spec, root, code_hash=VERSION).records
    assert all(after[key] == rec for key, rec in before.items())  # finished runs untouched

    full = run_campaign(spec, tmp_path / "uninterrupted", runner=toy_runner, jobs=1, code_hash=VERSION, progress=None)
    assert full.n_executed == 12
    pd.testing.assert_frame_equal(_stable(res.table), _stable(full.table))
    pd.testing.assert_frame_equal(_stable(pd.read_csv(root / "toy" / "table.csv")),
                                  _stable(pd.read_csv(tmp_path / "uninterrupted" / "toy" / "table.csv")))


def test_dask_local_cluster_gives_the_loky_table(tmp_path):
    pytest.importorskip("dask.distributed")
    loky = run_campaign(_spec(), tmp_path / "loky", runner=failing_runner, jobs=2, code_hash=VERSION, progress=None)
    dask = run_campaign(_spec(), tmp_path / "dask", runner=failing_runner, jobs=2, backend="dask",
                        code_hash=VERSION, progress=None)
    assert (dask.n_ok, dask.n_failed) == (2, 4)
    pd.testing.assert_frame_equal(_stable(dask.table), _stable(loky.table))


def test_bad_backend_and_arguments_are_rejected_before_running(tmp_path):
    with pytest.raises(ValueError, match="backend='spark'"):
        run_campaign(_spec(), tmp_path, runner=toy_runner, backend="spark", code_hash=VERSION, progress=None)
    with pytest.raises(ValueError, match="jobs=0"):
        run_campaign(_spec(), tmp_path, runner=toy_runner, jobs=0, code_hash=VERSION, progress=None)
    with pytest.raises(ValueError, match="timeout"):
        run_campaign(_spec(), tmp_path, runner=toy_runner, timeout=-1.0, code_hash=VERSION, progress=None)


# ---------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------
_CLI_SPEC = """
name = "clitoy"
[base]
w_i = 10.0
[options]
h = 2.0
t_end = 1.5
[axes]
cement = [1.0, 2.0, 3.0]
eta_o = [0.1, 0.5]
[[diagrams]]
kind = "scatter"
x = "eta_o"
y = "cement"
file = "regimes.png"
[run]
runner = "test_campaign_run:failing_runner"
"""


def test_cli_dry_run_run_status_plot_report(tmp_path, capsys, monkeypatch):
    import solver.budget as budget
    from sweep.campaign.run import _hms

    spec = tmp_path / "clitoy.toml"
    spec.write_text(_CLI_SPEC)
    root = tmp_path / "res"
    (root / "bench").mkdir(parents=True)
    (root / "bench" / "bench.json").write_text(json.dumps({"shared_run_factor": 2.0}))
    monkeypatch.setattr(budget, "calibration", lambda ls, kern: {"factor": 3.0})  # a machine 3x the reference's
    assert cli_main(["run", str(spec), "--results", str(root), "--dry-run", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    # 6 runs x (one h = 2 mm run's wall time to 1.5 s on this machine x 2 beside another), halved on 2 jobs
    nodes, _ = budget.mesh_counts(2.0)
    one = budget.wall_time_s(7 * nodes, 1.5, budget._path()[0], 3.0)
    assert "6 runs in the grid" in out and f"{_hms(12 * one)} CPU" in out and f"{_hms(6 * one)} wall on 2 job(s)" in out
    assert "x 2: a run beside 1 other(s) against alone, bench" in out and "this machine 3x" in out

    assert cli_main(["run", str(spec), "--results", str(root), "--jobs", "2", "--quiet"]) == 1  # failures
    out = capsys.readouterr().out
    assert "6 executed now (2 ok, 4 failed)" in out and "measured:" not in out   # no run had finished
    assert cli_main(["run", str(spec), "--results", str(root), "--retry-failed", "--quiet"]) == 1
    out = capsys.readouterr().out   # the start line gives the finished runs' own cost beside the estimate
    assert "campaign clitoy: 4 run(s) to do" in out and "  measured: this campaign's 6 finished run(s) took" in out

    assert cli_main(["status", str(spec), "--results", str(root)]) == 0
    out = capsys.readouterr().out
    assert "2 done, 4 failed, 0 pending" in out
    assert out.count("RuntimeError: boom at cement=2.0") == 2 and out.count("Newton did not converge") == 2

    assert cli_main(["plot", str(spec), "--results", str(root)]) == 0
    assert (root / "clitoy" / "figures" / "regimes.png").stat().st_size > 1000
    assert cli_main(["report", str(spec), "--results", str(root)]) == 0
    rep = (root / "clitoy" / "report.md").read_text()
    assert "- done: 2" in rep and "- failed: 4" in rep and "![regimes](figures/regimes.png)" in rep
    assert "Newton did not converge at t=0.3 s" in rep


def test_cli_rejects_a_bad_spec_naming_the_key(tmp_path, capsys):
    spec = tmp_path / "bad.toml"
    spec.write_text('name = "bad"\n[axes]\ncement = {linear = [0.5, 3.0]}\n')
    assert cli_main(["run", str(spec), "--results", str(tmp_path)]) == 2
    assert "axes.cement.linear" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()  # nothing ran, nothing written


def test_report_of_an_unrun_campaign_lists_pending(tmp_path):
    p = write_report(_spec(), tmp_path, code_hash=VERSION)
    text = p.read_text()
    assert "- pending: 6" in text and "- done: 0" in text


def test_add_campaign_commands_parses_every_option():
    import argparse

    from sweep.campaign.cli import add_campaign_commands, cmd_run, cmd_status

    parser = argparse.ArgumentParser(prog="dchfrac")
    add_campaign_commands(parser.add_subparsers(dest="command"))
    a = parser.parse_args(["campaign", "run", "c.toml", "--jobs", "3", "--backend", "dask", "--scheduler", "tcp://h:8786",
                           "--dry-run", "--retry-failed", "--fail-fast", "--timeout", "5", "--results", "out"])
    assert (a.spec, a.jobs, a.backend, a.scheduler, a.timeout, a.results) == ("c.toml", 3, "dask", "tcp://h:8786", 5.0, "out")
    assert a.dry_run and a.retry_failed and a.fail_fast and a.func is cmd_run
    b = parser.parse_args(["campaign", "status", "c.toml"])
    assert b.func is cmd_status and b.results is None  # the spec's project results/ (sweep.campaign.paths)
    c = parser.parse_args(["campaign", "run", "c.toml", "--rerun-stale", "--rerun-archived", "--accept-stale"])
    assert c.rerun_stale and c.rerun_archived and c.accept_stale
    with pytest.raises(SystemExit):
        parser.parse_args(["campaign", "run", "c.toml", "--backend", "spark"])


def test_ray_backend_without_ray_says_which_extra(tmp_path, monkeypatch):
    try:
        import ray  # noqa: F401
    except ImportError:
        with pytest.raises(ValueError, match=r"dchfrac\[ray\]"):
            run_campaign(_spec(), tmp_path, runner=toy_runner, backend="ray", code_hash=VERSION, progress=None)
    else:  # the local Ray's workers import the runner from this folder and the project
        here = Path(__file__).resolve().parent
        monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(here), str(here.parent), os.environ.get("PYTHONPATH", "")]))
        res = run_campaign(_spec(), tmp_path, runner=toy_runner, backend="ray", jobs=2, code_hash=VERSION, progress=None)
        assert (res.n_ok, res.n_failed) == (6, 0)


def contract_runner(params, options, run_dir):
    """Writes a run folder in the solver's format (annulus r_i..r_o mesh, snapshots, time series):
    invading fluid S = 1 inside R = 20 + 20 eta_o mm, no crack (phi = 0.4 everywhere)."""
    import numpy as np

    ri, ro = params["r_inner"], params["r_outer"]
    r = np.linspace(ri, ro, 33)
    th = np.linspace(0.0, 2 * np.pi, 129)[:-1]
    R, T = np.meshgrid(r, th, indexing="ij")
    pts = np.column_stack([(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel()])
    nr, nt = len(r), len(th)
    i, j = np.meshgrid(np.arange(nr - 1), np.arange(nt), indexing="ij")
    a, b = (i * nt + j).ravel(), (i * nt + (j + 1) % nt).ravel()
    c, d = a + nt, b + nt
    tri = np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    snaps = Path(run_dir, "snapshots")
    snaps.mkdir()
    np.savez(snaps / "mesh.npz", points=pts, triangles=tri)
    rad = np.hypot(pts[:, 0], pts[:, 1])
    front = 20.0 + 20.0 * params["eta_o"]
    for k, t in enumerate((0.5, 1.0)):
        S = np.clip((front * t - rad) / 2.0 + 0.5, 0.0, 1.0)
        z = np.zeros(len(pts))
        np.savez(snaps / f"snap_{k:05d}.npz", t=t, S=S, mu=z, p=z, d=z, u=np.zeros((len(pts), 2)),
                 phi=np.full(len(tri), 0.4), eps_v=np.zeros(len(tri)), hoop_stress=np.zeros(len(tri)),
                 k=np.zeros(len(tri)), w1_mag=np.zeros(len(tri)))
    ts = pd.DataFrame({"t": [0.0, 0.5, 1.0], "p_inj": [0.0, 100.0 * params["eta_o"], 200.0 * params["eta_o"]]})
    ts.to_csv(Path(run_dir, "timeseries.csv"), index=False)
    return {"status": "ok"}


def test_reclassify_and_plots_on_solver_format_run_folders(tmp_path):
    pytest.importorskip("sweep.regimes.classify")
    from sweep.campaign.plot import plot_campaign
    from sweep.campaign.run import reclassify

    spec = spec_from_dict({"name": "fmt", "axes": {"eta_o": [0.25, 1.0]},
                           "diagrams": [{"kind": "timeseries", "x": "t", "y": "p_inj", "by": "eta_o"},
                                        {"kind": "fields", "field": "phi", "rows": "blocks", "cols": "eta_o"}]})
    run_campaign(spec, tmp_path, runner=contract_runner, jobs=1, code_hash=VERSION, progress=None)
    assert reclassify(spec, tmp_path, code_hash=VERSION) == 2
    t = build_table(spec, tmp_path, code_hash=VERSION).set_index("eta_o")
    assert list(t["regime"]) == ["uniform_invasion", "uniform_invasion"]
    assert not t["fracturing"].any() and list(t["n_cracks"]) == [0, 0]
    # S = 0.5 at R = 20 + 20 eta_o mm at t = 1 s (25 and 40 mm); radial mesh spacing 1.5 mm
    assert list(t["front_radius_mean"]) == pytest.approx([25.0, 40.0], abs=1.5)
    assert list(t["t_classified"]) == [1.0, 1.0]
    figs = plot_campaign(spec, tmp_path, code_hash=VERSION)
    assert [f.name for f in figs] == ["timeseries.png", "timeseries.pdf", "fields.png", "fields.pdf"]
    assert all(f.stat().st_size > 5000 for f in figs)


def test_dry_run_prices_each_run_on_its_own_mesh_path_and_time(tmp_path):
    """One estimate: each run costs solver.budget's wall time of its own mesh (graded meshes by their graded node
    count), on the path that will run, to its own simulated time, including the fixed per-run cost; runs beside
    others cost the shared-run factor more."""
    from solver import budget
    from sweep.campaign.cost import DEFAULT_SHARED_RUN_FACTOR, estimate_cost

    spec = tmp_path / "clitoy.toml"
    spec.write_text(_CLI_SPEC.replace("t_end = 1.5", "t_end = 0.001"))
    one = estimate_cost(str(spec), tmp_path / "res", jobs=1, machine_factor=1.0)
    (g,) = one["by_mesh"]
    assert g["runs"] == 6 and g["sim_s"] == pytest.approx(0.006)
    lone = budget.wall_time_s(g["estimate"].unknowns, 0.001, g["estimate"].linear_solver, 1.0)
    assert lone > budget.REFERENCE["per_run_overhead_s"]          # the fixed cost of a run of almost no time
    assert one["cpu_s"] == pytest.approx(6 * lone) and one["wall_s"] == pytest.approx(6 * lone)
    two = estimate_cost(str(spec), tmp_path / "res", jobs=2, machine_factor=1.0)
    assert two["shared_run_factor_source"] == "default"
    assert two["cpu_s"] == pytest.approx(6 * lone * DEFAULT_SHARED_RUN_FACTOR)
    assert two["wall_s"] == pytest.approx(two["cpu_s"] / 2)
    slow = estimate_cost(str(spec), tmp_path / "res", jobs=1, machine_factor=2.0)
    assert slow["cpu_s"] == pytest.approx(2 * one["cpu_s"])   # linear in the machine factor

    graded = tmp_path / "graded.toml"
    graded.write_text(_CLI_SPEC.replace('name = "clitoy"', 'name = "graded"').replace("h = 2.0", "h = 2.0\nh_outer = 0.25"))
    gr = estimate_cost(str(graded), tmp_path / "res", jobs=1, machine_factor=1.0)
    (gg,) = gr["by_mesh"]
    assert gg["estimate"].nodes == budget.mesh_counts(2.0, h_outer=0.25)[0] > 2 * g["estimate"].nodes
    assert gr["cpu_s"] > one["cpu_s"]


def test_measured_wall_is_the_finished_runs_own_cost_beside_the_estimate(capsys):
    from types import SimpleNamespace

    from sweep.campaign.cli import _print_estimate
    from sweep.campaign.cost import measured_wall

    plan = SimpleNamespace(records={"a": {"status": "ok", "wall_time_s": 900.0},
                                    "b": {"status": "failed", "wall_time_s": 2700.0}, "c": None},
                           archived_rows={"d": {"status": "ok", "wall_time_s": 1300.0},
                                          "e": {"status": "ok", "wall_time_s": float("nan")}})
    m = measured_wall(plan)
    assert m == {"runs": 3, "median_s": 1300.0, "min_s": 900.0, "max_s": 2700.0}
    assert measured_wall(SimpleNamespace(records={}, archived_rows={})) is None
    est = {"grid_size": 5, "done": 2, "failed": 0, "archived": 1, "pending": 2, "stale": 0, "stale_kept": 0,
           "damaged": 0, "by_mesh": [], "runs_to_do": 2, "cpu_s": 400.0, "wall_s": 400.0, "measured": m}
    _print_estimate(SimpleNamespace(name="toy"), est, jobs=1)
    out = capsys.readouterr().out
    assert "measured: this campaign's 3 finished run(s) took 21m40s each (median; 15m00s to 45m00s)" in out
    assert "at that pace the 2 to do take about 43m20s CPU" in out

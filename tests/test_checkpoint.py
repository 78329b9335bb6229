"""A run killed part-way resumes from its last checkpoint (solver.checkpoint): in a run folder, in a campaign and in
the discrepancy workflow's forward cache.

A kill is emulated without any clock: ``solver.checkpoint.save`` is wrapped so that it writes the first ``kept``
checkpoints, writes none after them, and raises :class:`Killed` (a BaseException: nothing in the solver catches it,
as nothing runs after a SIGKILL) at its call ``killed_at`` (> ``kept``: steps done after the last checkpoint are
lost, as in a real kill).  ``checkpoint_interval`` = 1e-9 s makes every accepted step due for a checkpoint, so
which steps write one does not depend on the machine's speed.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from solver import Parameters, RunOptions, checkpoint, simulate
from solver.forms import MU, P, S, UX
from solver.stagger import _FLOORS

# a coarse mesh and a short run: 12 accepted steps, a snapshot in the middle
OPTS = RunOptions(h=12.0, t_end=0.02, dt0=0.002, dt_max=0.002, jacobian_reuse=0.0, checkpoint_interval=1e-9,
                  snapshot_times=[0.01], write_xdmf=False)
KEPT, KILLED_AT = 4, 7  # checkpoints written before the kill; the accepted step the kill comes after


class Killed(BaseException):
    """A kill of the process: not an Exception, so no run handler records it."""


def _interrupt(monkeypatch, kept: int = KEPT, killed_at: int = KILLED_AT, code: str | None = None):
    """Wrap checkpoint.save: the first ``kept`` calls write (with the code hash ``code`` when given), call
    ``killed_at`` raises Killed."""
    real, calls = checkpoint.save, [0]

    def save(run_dir, sim, state):
        calls[0] += 1
        if calls[0] == killed_at:
            raise Killed
        if calls[0] <= kept:
            real(run_dir, sim, {**state, "identity": {**state["identity"], "code_hash": code or
                                                     state["identity"]["code_hash"]}})

    monkeypatch.setattr(checkpoint, "save", save)


def _killed_run(monkeypatch, params, options, out, **kw):
    """The run ``simulate(params, options, out_dir=out)`` killed after its KILLED_AT-th accepted step, with the
    checkpoint of its KEPT-th left in ``out``."""
    with monkeypatch.context() as m:
        _interrupt(m, **kw)
        with pytest.raises(Killed):
            simulate(params, options, out_dir=out)
    assert (out / checkpoint.NAME).is_file()


def _same_snapshots(a, b) -> None:
    assert [t for t, _ in a] == [t for t, _ in b]
    for (_, fa), (_, fb) in zip(a, b):
        assert fa.keys() == fb.keys() and all(np.array_equal(fa[k], fb[k]) for k in fa)


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    """The uninterrupted run of OPTS, in a run folder."""
    return simulate(Parameters(), OPTS, out_dir=tmp_path_factory.mktemp("full") / "run")


def test_a_killed_run_resumes_to_the_uninterrupted_run_exactly_without_jacobian_reuse(tmp_path, monkeypatch, full):
    """With jacobian_reuse = 0 every Newton iteration factorizes a fresh Jacobian, so the kept factorization (the
    one thing a checkpoint does not hold) plays no part: the resumed run is the uninterrupted one bit for bit."""
    out = tmp_path / "run"
    _killed_run(monkeypatch, Parameters(), OPTS, out)
    before = checkpoint.load(out)[0]["elapsed"]  # s of wall time of the killed piece, up to its checkpoint
    res = simulate(Parameters(), OPTS, out_dir=out)
    assert res.status == "ok" and full.status == "ok"
    t_ck = full.timeseries["t"].iloc[KEPT - 1]
    assert res.resumed_from_t == [t_ck] and 0 < t_ck < OPTS.t_end
    pd.testing.assert_frame_equal(res.timeseries, full.timeseries, check_exact=True)
    _same_snapshots(res.snapshots, full.snapshots)
    assert res.factorizations == full.factorizations
    # the run folder: the same files as the uninterrupted run's, without a checkpoint, and the resumption recorded
    pd.testing.assert_frame_equal(pd.read_csv(out / "timeseries.csv"), pd.read_csv(Path(full.out_dir) / "timeseries.csv"))
    assert sorted(p.name for p in out.rglob("*")) == sorted(p.name for p in Path(full.out_dir).rglob("*"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["resumed_from_t"] == [t_ck] and summary["status"] == "ok"
    assert res.wall_time >= summary["wall_time_s"] > before > 0  # the pieces' wall times add up
    assert "resumed from the checkpoint" in (out / "log.txt").read_text()
    assert "resumed_from_t" not in json.loads((Path(full.out_dir) / "summary.json").read_text())


def test_a_run_resumed_twice_records_both_times(tmp_path, monkeypatch, full):
    out = tmp_path / "run"
    _killed_run(monkeypatch, Parameters(), OPTS, out, kept=2, killed_at=3)
    _killed_run(monkeypatch, Parameters(), OPTS, out, kept=2, killed_at=4)  # 2 checkpoints after the first resume
    res = simulate(Parameters(), OPTS, out_dir=out)
    t = full.timeseries["t"]
    assert res.resumed_from_t == [t.iloc[1], t.iloc[3]]
    pd.testing.assert_frame_equal(res.timeseries, full.timeseries, check_exact=True)


def test_with_jacobian_reuse_the_resumed_run_agrees_to_the_newton_tolerance(tmp_path, monkeypatch):
    """With the default jacobian_reuse the uninterrupted run starts the step after the checkpoint with a kept
    Jacobian and the resumed one with a fresh one: their Newton iterates differ, both within the Newton tolerance
    of the same discrete solution.  The Newton test accepts an iterate whose update is below newton_rtol times
    each field's scale (max |field|, floored as ``solver.stagger._FLOORS``), and the iterations contract by at
    least 1/2 when they stop (a slower contraction with a reused Jacobian is tested at a tenth of the tolerance,
    one above ``jacobian_reuse`` refreshes it), so the error left is at most the last update: newton_rtol x scale
    per solve, 2 newton_rtol x scale between the two runs' solves of one step.  The damage d follows the stagger's
    test, max |Δd| < stagger_tol, so 2 stagger_tol per step.  Backward Euler carries a difference of the start
    into the next step without amplifying it, so after the n steps from the checkpoint to t_end the runs differ
    by at most n times the per-step bound; the times by n x 2 newton_rtol relatively (the step controller reads
    the state change, which moves with the state)."""
    opts = OPTS.replace(jacobian_reuse=RunOptions().jacobian_reuse, t_end=0.03, snapshot_times=[])
    ref = simulate(Parameters(), opts, out_dir=tmp_path / "full")
    out = tmp_path / "run"
    _killed_run(monkeypatch, Parameters(), opts, out)
    res = simulate(Parameters(), opts, out_dir=out)
    assert res.resumed_from_t and len(res.timeseries) == len(ref.timeseries)
    n = int((ref.timeseries["t"] > res.resumed_from_t[0]).sum())
    rtol = 2 * n * opts.newton_rtol
    np.testing.assert_allclose(res.timeseries["t"], ref.timeseries["t"], rtol=rtol, atol=0)
    a, b = res.snapshots[-1][1], ref.snapshots[-1][1]
    for name, floor in (("u", _FLOORS[UX]), ("p", _FLOORS[P]), ("S", _FLOORS[S]), ("mu", _FLOORS[MU])):
        scale = max(float(np.abs(b[name]).max()), floor)
        assert np.abs(a[name] - b[name]).max() <= rtol * scale, name
    assert np.abs(a["d"] - b["d"]).max() <= 2 * n * opts.stagger_tol
    p_scale = max(float(np.abs(b["p"]).max()), _FLOORS[P])
    assert np.abs(res.timeseries["p_inj"] - ref.timeseries["p_inj"]).max() <= rtol * p_scale


@pytest.mark.parametrize("other", ["params", "options", "code", "mesh"])
def test_a_checkpoint_of_another_run_or_code_is_ignored_and_the_run_starts_at_zero(tmp_path, monkeypatch, full, other):
    """A checkpoint written for other parameters, options, solver code or mesh is never resumed: the run starts at
    t = 0 (its result is the uninterrupted run's) and says so in one log line."""
    from solver.mesh import annulus_mesh

    out = tmp_path / "run"
    first = {"params": (Parameters(w_i=Parameters().w_i * 1.1), OPTS), "options": (Parameters(), OPTS.replace(stagger_tol=5e-5))}
    p0, o0 = first.get(other, (Parameters(), OPTS))
    _killed_run(monkeypatch, p0, o0, out, code="0123456789abcdef" if other == "code" else None)
    mesh = annulus_mesh(Parameters().r_inner, Parameters().r_outer, OPTS.h, 1) if other == "mesh" else None
    res = simulate(Parameters(), OPTS, out_dir=out, mesh=mesh)
    log = (out / "log.txt").read_text()
    assert res.status == "ok" and res.resumed_from_t == [] and log.count("checkpoint ignored") == 1
    assert "resumed" not in log and not (out / checkpoint.NAME).exists()
    if other != "mesh":
        pd.testing.assert_frame_equal(res.timeseries, full.timeseries, check_exact=True)
        _same_snapshots(res.snapshots, full.snapshots)


def test_a_truncated_checkpoint_is_ignored_with_a_log_line(tmp_path, monkeypatch, full):
    out = tmp_path / "run"
    _killed_run(monkeypatch, Parameters(), OPTS, out)
    data = (out / checkpoint.NAME).read_bytes()
    (out / checkpoint.NAME).write_bytes(data[: len(data) // 2])
    res = simulate(Parameters(), OPTS, out_dir=out)
    log = (out / "log.txt").read_text()
    assert "checkpoint ignored" in log and "cannot be read" in log and res.resumed_from_t == []
    pd.testing.assert_frame_equal(res.timeseries, full.timeseries, check_exact=True)


def test_the_checkpoint_interval_resumes_any_setting_and_names_no_run(tmp_path, monkeypatch, full):
    """checkpoint_interval does not change a run's result: a checkpoint resumes whatever its setting, and it enters
    neither a campaign run key nor a forward-cache hash (and to_dict only when set)."""
    from sweep.campaign.store import run_key
    from sweep.discrepancy.forward import params_hash

    out = tmp_path / "run"
    _killed_run(monkeypatch, Parameters(), OPTS, out)
    res = simulate(Parameters(), OPTS.replace(checkpoint_interval=None), out_dir=out)
    assert res.resumed_from_t and not (out / checkpoint.NAME).exists()
    pd.testing.assert_frame_equal(res.timeseries, full.timeseries, check_exact=True)
    assert "checkpoint_interval" not in RunOptions().to_dict()
    o = RunOptions(checkpoint_interval=5.0).to_dict()
    assert o["checkpoint_interval"] == 5.0 and RunOptions.from_dict(o).checkpoint_interval == 5.0
    p = Parameters().to_dict()
    assert run_key(p, o) == run_key(p, RunOptions().to_dict())
    assert params_hash(p, o) == params_hash(p, RunOptions().to_dict())
    with pytest.raises(ValueError, match="checkpoint_interval=-1"):
        RunOptions(checkpoint_interval=-1.0)


def test_a_run_that_ends_failed_leaves_no_checkpoint(tmp_path):
    """A failed run is final: it removes its checkpoint, so a rerun starts at t = 0."""
    out = tmp_path / "run"
    res = simulate(Parameters(), OPTS.replace(newton_max_its=1, dt_min=5e-4), out_dir=out)
    assert res.status == "failed" and not (out / checkpoint.NAME).exists()


def test_dchfrac_run_resumes_a_killed_run_folder_and_force_starts_over(tmp_path, monkeypatch, capsys):
    from sweep.cli import main

    out = tmp_path / "run"
    args = ["run", "--out", str(out), "--quiet", "--h", "12", "--t-end", "0.01", "--set", "jacobian_reuse=0",
            "--set", "checkpoint_interval=1e-9", "--set", "write_xdmf=False"]
    with monkeypatch.context() as m:
        _interrupt(m)
        with pytest.raises(Killed):
            main(args)
    assert main(args) == 0
    assert json.loads((out / "summary.json").read_text())["resumed_from_t"][0] > 0
    assert main(args) == 2 and "existing run folder" in capsys.readouterr().err  # finished: no checkpoint left
    with monkeypatch.context() as m:
        _interrupt(m)
        with pytest.raises(Killed):
            main(args + ["--force"])
    assert main(args + ["--force"]) == 0  # --force overwrites: the checkpoint is not resumed
    assert "resumed_from_t" not in json.loads((out / "summary.json").read_text())


# ---------------------------------------------------------------------------
# campaign and discrepancy forward cache
# ---------------------------------------------------------------------------
def _campaign_spec():
    from sweep.campaign.spec import spec_from_dict

    return spec_from_dict({"name": "ck", "base": {}, "options": OPTS.to_dict(), "axes": {"w_i": [Parameters().w_i]}})


def test_a_campaign_killed_mid_run_resumes_the_run_from_its_checkpoint(tmp_path, monkeypatch):
    from sweep.campaign.run import run_campaign

    root = tmp_path / "killed"
    with monkeypatch.context() as m:
        _interrupt(m)
        with pytest.raises(Killed):
            run_campaign(_campaign_spec(), root, jobs=1, isolate="none", progress=None)
    runs = root / "ck" / "runs"
    left = [d for d in runs.iterdir() if d.name.startswith(".tmp-")]
    assert len(left) == 1 and (left[0] / checkpoint.NAME).is_file()  # kept by the campaign's clean-up
    res = run_campaign(_campaign_spec(), root, jobs=1, isolate="none", progress=None)
    full = run_campaign(_campaign_spec(), tmp_path / "full", jobs=1, isolate="none", progress=None)
    assert (res.n_executed, res.n_ok, full.n_ok) == (1, 1, 1)
    (key,) = [d.name for d in runs.iterdir()]  # the tmp folder was the run's, renamed to its key
    rec = json.loads((runs / key / "record.json").read_text())
    ref = json.loads((tmp_path / "full" / "ck" / "runs" / key / "record.json").read_text())
    assert json.loads((runs / key / "summary.json").read_text())["resumed_from_t"][0] > 0
    assert "checkpoint.npz" not in rec["files"] and not (runs / key / checkpoint.NAME).exists()
    volatile = {"solver_wall_time_s"}
    assert {k: v for k, v in rec["metrics"].items() if k not in volatile} == \
           {k: v for k, v in ref["metrics"].items() if k not in volatile}
    assert (rec["status"], rec["classification"]) == (ref["status"], ref["classification"])
    pd.testing.assert_frame_equal(pd.read_csv(runs / key / "timeseries.csv"),
                                  pd.read_csv(tmp_path / "full" / "ck" / "runs" / key / "timeseries.csv"))


def test_a_resumed_campaign_run_records_the_wall_time_of_all_its_pieces(tmp_path, monkeypatch):
    """The record's (and so the table's) wall time of a resumed run is the earlier pieces' wall time (the
    checkpoint's, set here to 1,000 s so that no clock can make the test pass) plus this execution's."""
    import io

    from sweep.campaign.run import run_campaign
    from sweep.campaign.scheduler import checkpoint_elapsed

    root = tmp_path / "killed"
    with monkeypatch.context() as m:
        _interrupt(m)
        with pytest.raises(Killed):
            run_campaign(_campaign_spec(), root, jobs=1, isolate="none", progress=None)
    (tmp,) = [d for d in (root / "ck" / "runs").iterdir() if d.name.startswith(".tmp-")]
    with np.load(tmp / checkpoint.NAME) as z:
        arrays = {k: z[k] for k in z.files}
    state = json.loads(str(arrays["state"]))
    arrays["state"] = np.array(json.dumps({**state, "elapsed": 1000.0}))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    (tmp / checkpoint.NAME).write_bytes(buf.getvalue())
    assert checkpoint_elapsed(tmp) == 1000.0 and checkpoint_elapsed(tmp_path) == 0.0
    run_campaign(_campaign_spec(), root, jobs=1, isolate="none", progress=None)
    (run,) = [d for d in (root / "ck" / "runs").iterdir()]
    rec = json.loads((run / "record.json").read_text())
    assert rec["resumed_wall_s"] == 1000.0
    assert 1000.0 < rec["metrics"]["solver_wall_time_s"] <= rec["wall_time_s"] <= rec["total_wall_time_s"]
    assert rec["wall_time_s"] < 1000.0 + 600.0  # this piece: a 12-step run on a 12 mm mesh, not another 1,000 s
    from sweep.campaign.table import build_table, record_wall_time

    assert build_table(_campaign_spec(), root)["wall_time_s"].tolist() == [rec["wall_time_s"]]
    # a record written before the scheduler summed the pieces: its last piece, with the solver's total beside it
    old = {k: v for k, v in rec.items() if k != "resumed_wall_s"}
    assert record_wall_time({**old, "wall_time_s": 421.0}) == rec["metrics"]["solver_wall_time_s"]
    assert record_wall_time({**old, "wall_time_s": 5000.0}) == 5000.0
    assert record_wall_time({**rec, "wall_time_s": 421.0}) == 421.0  # a new record is taken as it is


def test_clean_tmp_keeps_only_the_folders_with_a_checkpoint_of_this_code(tmp_path, monkeypatch):
    from sweep.campaign.store import ResultsStore

    store = ResultsStore(tmp_path, "c")
    plain, other, mine = (store.new_tmp_dir(k) for k in ("a" * 16, "b" * 16, "c" * 16))
    _killed_run(monkeypatch, Parameters(), OPTS, mine)
    _killed_run(monkeypatch, Parameters(), OPTS, other, code="0123456789abcdef")
    assert store.clean_tmp() == 2 and [d.name for d in store.runs_dir.iterdir()] == [mine.name]
    assert store.resumable_tmp_dir("c" * 16) == mine and store.resumable_tmp_dir("a" * 16) is None


def test_the_forward_cache_resumes_an_interrupted_entry_instead_of_wiping_it(tmp_path, monkeypatch, full):
    from sweep.discrepancy.forward import _run_one, finished
    from sweep.campaign.store import current_code_hash

    pdict, odict = Parameters().to_dict(), OPTS.to_dict()
    rd = tmp_path / "entry"
    with monkeypatch.context() as m:
        _interrupt(m)
        with pytest.raises(Killed):
            _run_one(pdict, odict, str(rd), current_code_hash())
    assert not finished(rd) and (rd / checkpoint.NAME).is_file()
    _run_one(pdict, odict, str(rd), current_code_hash())
    assert finished(rd) and not (rd / checkpoint.NAME).exists()
    assert json.loads((rd / "summary.json").read_text())["resumed_from_t"][0] > 0
    pd.testing.assert_frame_equal(pd.read_csv(rd / "timeseries.csv"), pd.read_csv(Path(full.out_dir) / "timeseries.csv"))

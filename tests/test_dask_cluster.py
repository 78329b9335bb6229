"""A campaign on a real dask cluster: `dask scheduler` and two `dask worker` processes on localhost,
reached through `dchfrac campaign run --backend dask --scheduler tcp://127.0.0.1:PORT`.

The table equals the loky table of the same spec, and killing one worker while runs are in flight
loses no finished run: every run recorded before the kill is recorded at the end, and every run of
the grid ends recorded "ok" (the lost worker's runs go to the other worker).
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

pytest.importorskip("dask.distributed")

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
SPEC = """name = "cluster"
[options]
h = 4.0
[axes]
cement = [1.0, 2.0, 3.0, 4.0]
eta_o = [0.1, 0.5]
[run]
runner = "fake_runs:sleepy_runner"
"""
VOLATILE = ["wall_time_s", "host", "finished_at", "run_dir"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(HERE), env.get("PYTHONPATH", "")])
    return env


def _start(args, log: Path):
    f = open(log, "w")
    return subprocess.Popen(args, stdout=f, stderr=subprocess.STDOUT, env=_env(), cwd=ROOT, start_new_session=True)


def _stop(p: subprocess.Popen):
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def _wait_for(pred, what: str, limit_s: float = 120.0):
    end = time.monotonic() + limit_s
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(0.1)


def _workers(address: str) -> int:
    from dask.distributed import Client

    with Client(address, timeout=30) as c:
        return len(c.scheduler_info()["workers"])


def _records(runs: Path) -> dict[str, dict]:
    out = {}
    for d in runs.glob("*/record.json") if runs.is_dir() else []:
        try:
            out[d.parent.name] = json.loads(d.read_text())
        except (json.JSONDecodeError, FileNotFoundError):
            pass
    return out


@pytest.fixture()
def cluster(tmp_path):
    if shutil.which("dask") is None:
        pytest.skip("no `dask` command (dask[distributed])")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [_start(["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                    tmp_path / "scheduler.log")]
    try:
        _wait_for(lambda: _can_connect(port), "the scheduler")
        for i in range(2):
            procs.append(_start(["dask", "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                                 "--name", f"w{i}"], tmp_path / f"worker{i}.log"))
        _wait_for(lambda: _workers(address) == 2, "two workers")
        yield address, procs
    finally:
        for p in reversed(procs):
            _stop(p)


def _can_connect(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def _table(root: Path) -> pd.DataFrame:
    t = pd.read_csv(root / "cluster" / "table.csv")
    return t.drop(columns=[c for c in VOLATILE if c in t.columns]).sort_values("index").reset_index(drop=True)


def test_real_cluster_table_equals_loky_and_a_killed_worker_loses_no_run(cluster, tmp_path):
    address, procs = cluster
    spec = tmp_path / "cluster.toml"
    spec.write_text(SPEC)
    loky = subprocess.run([sys.executable, "-m", "sweep.cli", "-q", "campaign", "run", str(spec), "--results",
                           str(tmp_path / "loky"), "--jobs", "2"], env=_env(), cwd=ROOT, capture_output=True, text=True)
    assert loky.returncode == 0, loky.stderr
    root = tmp_path / "dask"
    camp = subprocess.Popen([sys.executable, "-m", "sweep.cli", "-q", "campaign", "run", str(spec), "--results", str(root),
                             "--backend", "dask", "--scheduler", address], env=_env(), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs = root / "cluster" / "runs"
    # kill worker 0 (its process group: the nanny and the worker) once some runs are recorded and most are not
    _wait_for(lambda: len(_records(runs)) >= 2 or camp.poll() is not None, "the first finished runs")
    before = _records(runs)
    assert camp.poll() is None and len(before) <= 6, "the campaign ended before a worker could be killed"
    os.killpg(procs[1].pid, signal.SIGKILL)
    out, err = camp.communicate(timeout=600)
    assert camp.returncode == 0, err
    after = _records(runs)
    assert set(before) <= set(after) and len(after) == 8
    assert all(r["status"] == "ok" for r in after.values())
    pd.testing.assert_frame_equal(_table(root), _table(tmp_path / "loky"))
    t = _table(root)
    assert list(t["x"]) == pytest.approx(list(t["eta_o"] * t["cement"]), rel=1e-15)

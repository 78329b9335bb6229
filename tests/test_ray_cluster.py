"""A campaign on a real local Ray cluster: `ray start --head` on localhost (two CPUs), reached through
`dchfrac campaign run --backend ray --scheduler 127.0.0.1:PORT`; the table equals the loky table of the same spec.

Slow (a Ray head takes tens of seconds to start) and skipped without the ``ray`` extra (``pip install ".[ray]"``).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile

import pandas as pd
import pytest

from test_dask_cluster import ROOT, SPEC, _can_connect, _env, _free_port, _start, _stop, _table, _wait_for

pytest.importorskip("ray")
pytestmark = pytest.mark.slow


@pytest.fixture()
def ray_head(tmp_path, monkeypatch):
    if shutil.which("ray") is None:
        pytest.skip("no `ray` command")
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # a private head on localhost: no token to hand to the driver
    port = _free_port()
    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay under 107 bytes
    log = tmp_path / "ray.log"
    head = _start(["ray", "start", "--head", "--port", str(port), "--num-cpus", "2",
                   "--include-dashboard", "false", "--block", "--temp-dir", temp], log)
    try:
        _wait_for(lambda: _can_connect(port) or head.poll() is not None, "the Ray head", limit_s=180)
        assert head.poll() is None, f"ray start failed: {log.read_text()[-1500:]}"
        yield f"127.0.0.1:{port}"
    finally:
        _stop(head)
        shutil.rmtree(temp, ignore_errors=True)


def test_real_ray_cluster_table_equals_loky(ray_head, tmp_path):
    spec = tmp_path / "cluster.toml"
    spec.write_text(SPEC)
    for backend, extra in (("loky", ["--jobs", "2"]), ("ray", ["--backend", "ray", "--scheduler", ray_head])):
        r = subprocess.run([sys.executable, "-m", "sweep.cli", "-q", "campaign", "run", str(spec), "--results",
                            str(tmp_path / backend), *extra], env=_env(), cwd=ROOT, capture_output=True, text=True,
                           timeout=900)
        assert r.returncode == 0, r.stderr[-2000:]
    pd.testing.assert_frame_equal(_table(tmp_path / "ray"), _table(tmp_path / "loky"))
    assert len(_table(tmp_path / "ray")) == 8

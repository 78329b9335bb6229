"""``dchfrac discrepancy status``: a long discrepancy run's forward runs read from its cache while it runs
(sweep.discrepancy.forward.cache_status).  Synthetic cache entries: no solver run.  Units mm, s."""
import json

import numpy as np

from sweep.campaign.store import current_code_hash
from sweep.discrepancy.cli import main
from sweep.discrepancy.forward import cache_status


def _entry(root, key, summary, h=4.0, seed=None):
    rd = root / key
    rd.mkdir(parents=True)
    (rd / "summary.json").write_text(summary if isinstance(summary, str) else json.dumps(summary))
    (rd / "options.toml").write_text(f"h = {h}\n" + (f"mesh_seed = {seed}\n" if seed is not None else ""))
    return rd


def test_the_status_reads_finished_running_failed_and_unreadable_entries(tmp_path, capsys):
    code = current_code_hash()
    _entry(tmp_path, "a", {"status": "ok", "t_reached": 2.0, "wall_time_s": 289.4, "code_hash": code})
    rd = _entry(tmp_path, "b", {"status": "running", "code_hash": code}, h=1.0, seed=3)
    state = np.array(json.dumps({"t": 0.2892, "previous_dt": None}))
    np.savez(rd / "checkpoint.npz", state=state, U=np.zeros((5, 4)), d=np.zeros(5))
    _entry(tmp_path, "c", {"status": "running", "code_hash": code}, h=1.0, seed=1)     # before its first checkpoint
    _entry(tmp_path, "d", {"status": "failed", "t_reached": None, "code_hash": "0" * 16})
    _entry(tmp_path, "e", "{not json")
    rows = {r["key"]: r for r in cache_status(tmp_path)}
    assert rows["a"] == {"key": "a", "h": 4.0, "mesh_seed": None, "status": "ok", "t": 2.0, "wall_s": 289.4,
                         "current_code": True}
    assert (rows["b"]["status"], rows["b"]["t"], rows["b"]["mesh_seed"]) == ("running", 0.2892, 3)
    assert rows["c"]["t"] is None and rows["d"]["status"] == "failed" and not rows["d"]["current_code"]
    assert rows["e"]["status"] == "unreadable"
    assert main(["discrepancy", "status", "--cache", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "5 runs: 1 ok, 1 failed, 2 running or interrupted, 1 unreadable; 2 made by other solver code" in out
    assert "0.2892" in out


def test_the_status_of_a_missing_cache_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["discrepancy", "status", "--cache", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err
    assert "--cache" in err and "is not a folder" in err and len(err.strip().splitlines()) == 1

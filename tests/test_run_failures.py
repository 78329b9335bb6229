"""Bad input is refused before any work; a failing run ends with status "failed", its reason, and its files."""
import json

from solver import Parameters, RunOptions, simulate
from sweep.cli import main


def test_cli_rejects_bad_parameter_before_any_work(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "--out", str(out), "--set", "eta_o=-1.0", "--quiet"])
    assert code == 2
    assert "eta_o" in capsys.readouterr().err
    assert not out.exists()


def test_cli_rejects_unknown_name(tmp_path, capsys):
    code = main(["run", "--out", str(tmp_path / "r"), "--set", "viscosity=1.0", "--quiet"])
    assert code == 2
    assert "viscosity" in capsys.readouterr().err


def test_run_out_of_wall_time_fails_cleanly_and_keeps_its_files(tmp_path):
    res = simulate(Parameters(), RunOptions(h=6.0, t_end=1.0, max_wall_time=1e-3, snapshot_times=[]), out_dir=tmp_path / "r")
    assert res.status == "failed" and "max_wall_time" in res.reason
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["status"] == "failed" and summary["complete"] is False and "max_wall_time" in summary["reason"]
    assert (tmp_path / "r" / "params.toml").exists() and (tmp_path / "r" / "timeseries.csv").exists()


def test_step_below_dt_min_fails_with_reason(tmp_path):
    """With a Newton budget of one iteration no step can converge: dt is cut below dt_min and the run says why."""
    res = simulate(Parameters(), RunOptions(h=6.0, t_end=0.1, newton_max_its=1, dt0=1e-3, dt_min=5e-4, snapshot_times=[]),
                   out_dir=tmp_path / "r")
    assert res.status == "failed" and "dt_min" in res.reason
    log = (tmp_path / "r" / "log.txt").read_text()
    assert "rejected step" in log


def test_write_xdmf_option_is_honoured(tmp_path):
    """RunOptions.write_xdmf = False writes no ParaView file (campaign and discrepancy caches run thousands of
    runs); the NPZ snapshots and the summary are written either way."""
    for flag in (True, False):
        out = tmp_path / str(flag)
        res = simulate(Parameters(), RunOptions(h=12.0, t_end=0.004, dt0=0.002, dt_max=0.002, snapshot_times=[0.004],
                                                write_xdmf=flag), out_dir=out)
        assert res.status == "ok"
        assert (out / "fields.xdmf").exists() is flag
        assert list((out / "snapshots").glob("snap_*.npz")) and json.loads((out / "summary.json").read_text())["status"] == "ok"

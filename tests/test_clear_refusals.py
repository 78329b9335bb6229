"""Refusals that were tracebacks or came after work had started, now one line naming the input before any
work (issue #48).  Units mm, s, kPa."""
import pytest


def _one_line(capsys, rc, fragment, code=2):
    err = capsys.readouterr().err.strip()
    assert rc == code and fragment in err and "\n" not in err and "Traceback" not in err, err


_SPEC = 'name = "c"\n[base]\nw_i = 10.0\n[options]\nh = 4.0\nt_end = 0.5\n[axes]\ncement = [1.0, 2.0]\n'


def test_toml_errors_name_the_file_and_a_bom_is_read(tmp_path, capsys):
    from solver.tomlio import TOMLDecodeError, read_toml
    from sweep.campaign.cli import main

    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + _SPEC.encode())
    assert read_toml(bom)["name"] == "c"
    assert main(["run", str(bom), "--dry-run", "--results", str(tmp_path / "r")]) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(TOMLDecodeError, match=f"{bad}: invalid TOML"):
        read_toml(bad)
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b"name = \"\xe9\"\n")
    with pytest.raises(TOMLDecodeError, match=f"{latin}: not UTF-8 text"):
        read_toml(latin)
    capsys.readouterr()
    _one_line(capsys, main(["run", str(bad), "--dry-run", "--results", str(tmp_path / "r")]), f"{bad}: invalid TOML")


@pytest.mark.parametrize("env,value,fragment", [
    ("DCHFRAC_ASSEMBLY_THREADS", "abc", "DCHFRAC_ASSEMBLY_THREADS must be a positive integer, got 'abc'"),
    ("DCHFRAC_KERNELS", "bogus", "DCHFRAC_KERNELS='bogus' is not allowed: one of ('auto', 'numba', 'numpy')"),
])
def test_bad_environment_is_refused_before_a_run_folder_is_written(tmp_path, capsys, monkeypatch, env, value, fragment):
    import solver
    from solver import Parameters, RunOptions
    from sweep.cli import main

    monkeypatch.setenv(env, value)
    _one_line(capsys, main(["run", "--out", str(tmp_path / "run"), "--quiet"]), fragment)
    with pytest.raises(ValueError, match=env):
        solver.simulate(Parameters(), RunOptions(h=8.0, t_end=0.01), out_dir=tmp_path / "run2")
    assert not (tmp_path / "run").exists() and not (tmp_path / "run2").exists()


def test_an_unwritable_kernel_cache_is_warned(monkeypatch, tmp_path):
    from solver import kernels
    from solver.options import check_environment

    if kernels.backend() != "numba":
        pytest.skip("the kernel cache serves numba only")
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("DCHFRAC_CACHE", str(blocker / "sub"))
    (w,) = check_environment()
    assert "kernel cache DCHFRAC_CACHE" in w and "every run compiles its kernels again" in w


def test_unavailable_backends_are_refused_before_the_table_is_written(tmp_path, capsys):
    from sweep.campaign.cli import main
    from sweep.campaign.scheduler import check_backend

    spec = tmp_path / "c.toml"
    spec.write_text(_SPEC)
    try:
        import ray  # noqa: F401
    except ImportError:
        _one_line(capsys, main(["run", str(spec), "--backend", "ray", "--results", str(tmp_path / "r")]),
                  "--backend ray needs ray")
        assert not (tmp_path / "r" / "c" / "table.csv").exists()
    pytest.importorskip("dask.distributed")
    with pytest.raises(ValueError, match=r"--scheduler 'tcp://127.0.0.1:9': no dask scheduler answers within 1 s"):
        check_backend("dask", "tcp://127.0.0.1:9", timeout=1.0)
    with pytest.raises(ValueError, match="only meaningful with backend dask or ray"):
        check_backend("loky", "tcp://127.0.0.1:9")


def test_report_and_animate_refuse_bad_folders_in_one_line_and_write_nothing(tmp_path, capsys):
    from sweep.cli import main

    out = tmp_path / "rep"
    _one_line(capsys, main(["report", "reference", str(tmp_path / "NOT_A_RUN"), "--out", str(out)]),
              "run '" + str(tmp_path / "NOT_A_RUN") + "' is not a run folder: no timeseries.csv")
    _one_line(capsys, main(["report", "convergence", str(tmp_path), "--out", str(out)]),
              "report convergence takes two or more run folders")
    _one_line(capsys, main(["report", "reference", str(tmp_path), str(tmp_path), "--out", str(out)]),
              "report reference takes exactly one run folder, got 2")
    assert not out.exists()
    run = tmp_path / "run"
    (run / "snapshots").mkdir(parents=True)
    (run / "snapshots" / "mesh.npz").write_bytes(b"")
    _one_line(capsys, main(["animate", str(run), "--out", "/proc/nope/a.gif"]), "--out folder")


def test_compare_names_a_campaign_without_runs(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_SPEC)
    _one_line(capsys, main(["compare", str(spec), str(spec), "--results", str(tmp_path / "r")]),
              "no finished run in")
    _one_line(capsys, main(["compare", str(tmp_path / "missing.toml"), str(spec), "--results", str(tmp_path)]),
              "missing.toml' not found")


def test_a_different_spec_with_an_existing_campaigns_name_is_refused(tmp_path, capsys):
    import sys
    from pathlib import Path

    from sweep.campaign.run import run_campaign
    from sweep.campaign.spec import load_spec

    sys.path.insert(0, str(Path(__file__).parent))
    from test_campaign_run import VERSION, toy_runner

    first, other, wider = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "w.toml"
    first.write_text(_SPEC)
    other.write_text(_SPEC.replace("cement = [1.0, 2.0]", "cement = [3.0]"))
    wider.write_text(_SPEC.replace("cement = [1.0, 2.0]", "cement = [1.0, 2.0, 3.0]"))
    root = tmp_path / "r"
    run_campaign(load_spec(first), root, runner=toy_runner, code_hash=VERSION, progress=None)
    with pytest.raises(ValueError, match=r"campaign name 'c' must be new or name the same campaign: .* holds 2 "
                                         r"run\(s\) of another spec"):
        run_campaign(load_spec(other), root, runner=toy_runner, code_hash=VERSION, progress=None)
    assert (root / "c" / "spec.toml").read_text() == _SPEC           # its spec copy is untouched
    res = run_campaign(load_spec(wider), root, runner=toy_runner, code_hash=VERSION, progress=None)
    assert res.n_executed == 1                                       # an extended grid goes on


def test_a_400_digit_number_and_a_huge_seed_are_refused_in_one_line(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_SPEC.replace("cement = [1.0, 2.0]", "cement = [1" + "0" * 400 + "]"))
    _one_line(capsys, main(["run", str(spec), "--dry-run", "--results", str(tmp_path / "r")]),
              "parameter cement='100000000000... (401 digits)' is out of range")
    spec.write_text(_SPEC.replace("cement = [1.0, 2.0]", "seed = [1, 99999999999999999999]"))
    _one_line(capsys, main(["run", str(spec), "--dry-run", "--results", str(tmp_path / "r")]),
              "parameter seed=99999999999999999999 is out of range")
    assert not (tmp_path / "r").exists()

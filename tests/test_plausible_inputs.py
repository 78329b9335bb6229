"""Implausible inputs are warned (with the likely unit slip) or, with --strict, refused; every entry point
validates measured data alike; lengths the mesh cannot resolve are warned (issue #48, items 2-4).

Units mm, s, kPa.  The plausible ranges are declared beside the allowed ranges (solver.params._param,
solver.options._NUMBERS); these tests check the declarations, the messages and each entry point.
"""
from dataclasses import fields

import pytest

from solver import Parameters, RunOptions
from solver.options import _NUMBERS, check_run_inputs, plausibility_warnings as option_warnings
from solver.params import PLAUSIBLE, plausibility_warnings


def test_every_number_parameter_declares_a_plausible_range_holding_its_default():
    numeric = [f.name for f in fields(Parameters) if f.type in ("float", "float | None", "int")]
    assert sorted(PLAUSIBLE) == sorted(numeric)
    p = Parameters()
    for name, (lo, hi) in PLAUSIBLE.items():
        v = getattr(p, name)
        assert v is None or lo <= v <= hi, name
    assert plausibility_warnings(Parameters()) == [] and option_warnings(RunOptions()) == []
    for name, *_, rng in _NUMBERS:           # the run options' plausible ranges hold their defaults too
        v = getattr(RunOptions(), name)
        assert rng is None or v is None or rng[0] <= v <= rng[1], name


@pytest.mark.parametrize("params,opts,message", [
    (dict(E=331000.0, K_s=1.6e6), {}, "parameter E = 331000 kPa is 331 MPa: did you mean Pa?"),
    ({}, dict(t_end=2000.0), "run option t_end = 2000 s: did you mean ms?"),
    (dict(eta_o=290.0), {}, "parameter eta_o = 290 kPa·s: did you mean Pa·s?"),
    (dict(kbar=1.5e-9), {}, "parameter kbar = 1.5e-09 mm²: did you mean m²?"),
    (dict(cell_height=0.00196), {}, "parameter cell_height = 0.00196 mm: did you mean m?"),  # nearest the default
    (dict(gamma=30.0), {}, "parameter gamma = 30 kPa·mm: did you mean mN/m (= Pa·mm)?"),
    (dict(w_i=1e9), {}, "parameter w_i = 1e+09 mm/s: check its value and unit"),
    (dict(eta_w=1e-300), {}, "parameter eta_w = 1e-300 kPa·s: check its value and unit"),
    (dict(r_inner=0.005, r_outer=0.053), dict(h=0.01), "parameter r_outer = 0.053 mm: did you mean m?"),
])
def test_an_implausible_value_is_warned_with_the_likely_unit_slip(params, opts, message):
    ws = check_run_inputs(Parameters(**params), RunOptions(**opts))
    assert any(w.startswith(message) and "--strict refuses it" in w for w in ws), ws


def test_a_modulus_in_pa_is_blamed_on_e_not_on_k_s():
    with pytest.raises(ValueError) as e:
        Parameters(E=331000.0)
    msg = str(e.value)
    assert msg.startswith("parameter E=331000.0") and "E = 331000 kPa is 331 MPa: did you mean Pa?" in msg
    with pytest.raises(ValueError, match=r"parameter K_s=100.0 is out of range"):   # a plausible E: K_s blamed
        Parameters(K_s=100.0)


@pytest.mark.parametrize("params,opts,message", [
    (dict(l_d=0.5), dict(h=2.0), "parameter l_d = 0.5 mm is below 2 h = 4 mm: the mesh does not resolve the diffuse damage band"),
    (dict(l_d=100.0, Gc=1000.0), dict(h=1.0), "parameter l_d = 100 mm exceeds the annulus width r_outer - r_inner = 48 mm"),
    (dict(l_S=1000.0), dict(h=1.0), "parameter l_S = 1000 mm exceeds the annulus width"),
    (dict(r_inner=0.01), dict(h=1.0), "parameter r_inner = 0.01 mm is below the mesh size on the inner circle 1 mm"),
])
def test_lengths_the_mesh_does_not_resolve_or_the_annulus_cannot_hold_are_warned(params, opts, message):
    assert any(w.startswith(message) for w in check_run_inputs(Parameters(**params), RunOptions(**opts)))


def test_resolved_lengths_give_no_warning():
    assert check_run_inputs(Parameters(l_d=2.0, l_S=2.0), RunOptions(h=1.0)) == []


# ----------------------------------------------------------------------------- dchfrac run
@pytest.fixture
def no_simulation(monkeypatch):
    import solver

    def reached(*a, **k):
        raise AssertionError("a simulation started")

    monkeypatch.setattr(solver, "simulate", reached)


@pytest.mark.parametrize("args,message", [
    (["--set", "E=331000", "--set", "K_s=1.6e6", "--strict"],
     "--strict refuses: parameter E = 331000 kPa is 331 MPa: did you mean Pa?"),
    (["--t-end", "2000", "--strict"], "--strict refuses: run option t_end = 2000 s: did you mean ms?"),
    (["--set", "l_d=0.5", "--h", "2", "--strict"], "--strict refuses: parameter l_d = 0.5 mm is below 2 h"),
    (["--h", "8", "--set", "h=30"], "--h 8 conflicts with h=30 of --set/--config"),
    (["--t-end", "1", "--set", "t_end=2"], "--t-end 1 conflicts with t_end=2"),
    (["--set", "tend=3"], "unknown parameter or run option 'tend' (did you mean 't_end'?)"),
    (["--set", "k_s=3"], "(did you mean 'K_s'?)"),
    (["--set", "seed=99999999999999999999"], "parameter seed=99999999999999999999 is out of range: allowed an integer in [0, 2**63 - 1]"),
])
def test_dchfrac_run_refuses_implausible_or_conflicting_input(tmp_path, capsys, no_simulation, args, message):
    from sweep.cli import main

    rc = main(["run", "--out", str(tmp_path / "run"), "--quiet", *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and "\n" not in err, err
    assert not (tmp_path / "run").exists()


def test_dchfrac_run_refuses_an_empty_out_and_an_existing_run_folder_without_force(tmp_path, capsys, no_simulation):
    from sweep.cli import main

    assert main(["run", "--out", "", "--quiet"]) == 2
    assert "--out '' is not allowed: a run folder name" in capsys.readouterr().err
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "summary.json").write_text("{}")
    assert main(["run", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert ("is an existing run folder (allowed: a new folder, a run killed part-way with its checkpoint.npz, which "
            "resumes, or --force to overwrite it)") in capsys.readouterr().err
    with pytest.raises(AssertionError, match="a simulation started"):   # --force: the run starts
        main(["run", "--out", str(tmp_path / "run"), "--quiet", "--force"])


# ----------------------------------------------------------------------------- campaigns
_BASE = 'name = "c"\n[base]\nw_i = 10.0\n[options]\nh = 4.0\nt_end = 0.5\n'


def test_campaign_dry_run_lists_the_unit_slip_and_strict_refuses_before_any_run(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_BASE.replace("t_end = 0.5", "t_end = 2000.0") + "[axes]\ncement = [1.0, 2.0]\n")
    assert main(["run", str(spec), "--dry-run", "--results", str(tmp_path / "res")]) == 0
    assert "warning: 2 run(s): run option t_end = 2000 s: did you mean ms?" in capsys.readouterr().out
    assert main(["run", str(spec), "--strict", "--results", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert "--strict refuses: 2 run(s): run option t_end = 2000 s: did you mean ms?" in err
    assert not (tmp_path / "res" / "c").exists()


# ----------------------------------------------------------------------------- discrepancy init / run
def _measured(tmp_path, obs_rows: str, times=(0.1, 0.2)):
    d = tmp_path / "data"
    d.mkdir(parents=True)
    (d / "conditions.csv").write_text("id,w_i\na,30\nb,50\n")
    rows = "".join(f"{c},p_inj,{t},100,2\n" for c in "ab" for t in times)
    (d / "observations.csv").write_text("condition,observable,time,value,uncertainty\n" + rows + obs_rows)
    return d


@pytest.mark.parametrize("extra,message", [
    ("a,front_radius_mean,0.1,-1,0.1\n", "negative front_radius_mean -1.0 mm (allowed: a length >= 0 mm"),
    ("a,front_radius_mean,0.1,2,0.1\n", "front_radius_mean value=2 mm at t = 0.1 s is outside the annulus"),
    ("a,regime,0.2,fracturingg,0\n", "regime value='fracturingg' is not a label the model gives"),
])
def test_discrepancy_init_and_run_refuse_alike(tmp_path, capsys, extra, message):
    """init and run call the one validator (sweep.discrepancy.checks.check_data_against_model)."""
    from sweep.discrepancy.cli import main

    d = _measured(tmp_path, extra)
    spec = tmp_path / "spec.toml"
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(spec)]) == 2
    assert message in capsys.readouterr().err and not spec.exists()
    good = _measured(tmp_path / "ok", "")
    assert main(["discrepancy", "init", "--measured", str(good), "--out", str(spec)]) == 0
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["discrepancy", "run", "--measured", str(d), "--model", str(spec), "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not (out / "cache").exists()          # a refused run leaves no empty cache folder


def test_discrepancy_init_on_times_in_ms_warns_and_strict_refuses(tmp_path, capsys):
    from sweep.discrepancy.cli import main

    d = _measured(tmp_path, "", times=(10, 50))
    spec = tmp_path / "spec.toml"
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(spec), "--strict"]) == 2
    assert "--strict refuses: condition(s) ['a', 'b']: run option t_end = 50 s: did you mean ms?" in capsys.readouterr().err
    assert not spec.exists()
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(spec)]) == 0
    assert "warning: condition(s) ['a', 'b']: run option t_end = 50 s: did you mean ms?" in capsys.readouterr().err


@pytest.mark.parametrize("args,message", [
    (["--jobs", "0"], "--jobs 0 is not allowed: an integer in [1, 256]"),
    (["--strict"], "--strict refuses: condition(s) ['a', 'b']: run option t_end = 50 s: did you mean ms?"),
])
def test_discrepancy_run_refuses_before_any_forward_run(tmp_path, capsys, args, message):
    from sweep.discrepancy.cli import main

    d = _measured(tmp_path, "", times=(10, 50))
    spec = tmp_path / "spec.toml"
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(spec)]) == 0
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["discrepancy", "run", "--measured", str(d), "--model", str(spec), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err, err
    assert not (out / "cache").exists()


def test_discrepancy_init_refuses_an_unwritable_out_and_a_folder_in_one_line(tmp_path, capsys):
    from sweep.discrepancy.cli import main

    d = _measured(tmp_path, "")
    assert main(["discrepancy", "init", "--measured", str(d), "--out", "/proc/nope/spec.toml"]) == 2
    assert "cannot be written" in capsys.readouterr().err
    (tmp_path / "dir").mkdir()
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(tmp_path / "dir"), "--force"]) == 2
    assert "is a folder (allowed: a SPEC file name" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.tmp")) and list((tmp_path / "dir").iterdir()) == []
    assert main(["discrepancy", "init", "--measured", str(d), "--out", str(tmp_path / "new" / "sub" / "s.toml")]) == 0
    assert (tmp_path / "new" / "sub" / "s.toml").is_file()

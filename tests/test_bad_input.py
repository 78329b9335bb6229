"""Bad input is refused before any work, by a message naming the input, its value and what is allowed.

Each case is one bad input of the Python API or of a command line (``dchfrac run``, ``dchfrac campaign
run --dry-run``, ``dchfrac discrepancy run``): the message must hold the expected fragment, a command must
exit with code 2 and one line on stderr (never a traceback), and no run may start (the solver and the
discrepancy workflow are replaced by functions that fail the test if reached).  Valid inputs that used to
be refused (numpy scalars, integer parameters read from a CSV file) are accepted.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from solver import Parameters, RunOptions
from solver.options import check_run_inputs


# ---------------------------------------------------------------------------
# RunOptions and check_run_inputs (Python API)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("kw,fragment", [
    (dict(snapshot_times=1.0), "snapshot_times=1.0 is out of range: allowed a list of distinct times"),
    (dict(snapshot_times="12"), "snapshot_times='12'"),
    (dict(snapshot_times=[None]), "None is not"),
    (dict(snapshot_times=["a"]), "'a' is not"),
    (dict(snapshot_times=[True]), "True is not"),
    (dict(snapshot_times=[math.nan]), "nan is not"),
    (dict(snapshot_times=[0.5, 3.0]), "3.0 s is after t_end"),
    (dict(t_end=0.3, snapshot_times=[0.1, 0.5]), "in [0, t_end = 0.3] s; 0.5 s is after t_end"),
    (dict(snapshot_times=[0.5, 0.5]), "a time is repeated"),
    (dict(write_xdmf="false"), "write_xdmf='false' is out of range: allowed true or false"),
    (dict(write_xdmf="no"), "write_xdmf='no'"),
    (dict(write_xdmf=1), "write_xdmf=1"),
    (dict(stop_front_radius=-5.0), "stop_front_radius=-5.0"),
    (dict(h=np.float32(-1.0)), "run option h=-1.0 is out of range: allowed > 0.0"),
    (dict(h=math.inf), "h=inf is out of range: allowed a finite number"),
    (dict(mesh_seed=np.float64(3.5)), "mesh_seed=3.5 is out of range: allowed an integer"),
    (dict(mesh_seed=-1), "mesh_seed=-1 is out of range: allowed >= 0"),
    (dict(mesh_seed=True), "mesh_seed=True"),
    (dict(newton_max_its=2.5), "newton_max_its=2.5 is out of range: allowed an integer"),
    (dict(dt0=1.0), "dt0=1.0 is out of range: allowed [dt_min=1e-07, dt_max=0.02]"),
    (dict(linear_solver="mumps"), "linear_solver='mumps'"),
    (dict(linear_precision="half"), "linear_precision='half'"),
    (dict(max_wall_time=0.0), "max_wall_time=0.0"),
    (dict(h=1.0, h_inner=np.float64(2.0)), "h_inner=2.0 is out of range: allowed (0, h = 1.0]"),
])
def test_run_options_refuse(kw, fragment):
    with pytest.raises(ValueError) as e:
        RunOptions(**kw)
    assert fragment in str(e.value)


@pytest.mark.parametrize("params,opts,fragment", [
    (dict(r_outer=20.0), dict(h=8.0), "h=8.0 is out of range: allowed < (r_outer - r_inner)/2 = 7.5 mm"),
    (dict(r_inner=10.0, r_outer=20.0), dict(h=6.0), "h=6.0"),
    ({}, dict(stop_front_radius=3.0), "stop_front_radius=3.0 is out of range: allowed None or a radius in (r_inner = 5"),
    ({}, dict(stop_front_radius=60.0), "r_outer = 53] mm"),
])
def test_options_that_do_not_fit_the_annulus_are_refused(params, opts, fragment):
    with pytest.raises(ValueError) as e:
        check_run_inputs(Parameters(**params), RunOptions(**opts))
    assert fragment in str(e.value)


def test_interface_narrower_than_two_mesh_sizes_is_warned():
    assert check_run_inputs(Parameters(), RunOptions(h=1.0)) == []   # l_S = 4 mm, h = 1 mm: resolved
    (w,) = check_run_inputs(Parameters(l_S=1.0), RunOptions(h=2.0))
    assert "l_S = 1 mm is below 2 h = 4 mm" in w


def test_simulate_refuses_before_writing_the_run_folder(tmp_path):
    from solver import simulate

    with pytest.raises(ValueError, match="h=8.0"):
        simulate(Parameters(r_outer=20.0), RunOptions(h=8.0), out_dir=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_valid_numpy_scalars_and_default_snapshots_are_accepted():
    o = RunOptions(h=np.float32(4), mesh_seed=np.int64(3), t_end=np.float64(0.3), write_xdmf=np.bool_(False))
    assert (o.h, o.mesh_seed, o.t_end, o.write_xdmf) == (4.0, 3, 0.3, False)
    assert type(o.h) is float and type(o.mesh_seed) is int and type(o.t_end) is float
    assert RunOptions.from_dict(o.to_dict()) == o and '"mesh_seed": 3' in o.to_json()
    # the default snapshot times run with any t_end (those after it are not written)
    assert RunOptions(t_end=0.3).snapshot_times == (0.5, 1.0, 1.5, 2.0)
    assert RunOptions(snapshot_times=np.array([0.5, 1.0])).snapshot_times == (0.5, 1.0)


# ---------------------------------------------------------------------------
# dchfrac run (command line)
# ---------------------------------------------------------------------------
def _refused(capsys, rc, fragment):
    """Exit code 2, one line on stderr holding ``fragment``, no traceback."""
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert fragment in err and "\n" not in err and "Traceback" not in err, err


@pytest.fixture
def no_simulation(monkeypatch):
    import solver

    def reached(*a, **k):
        raise AssertionError("a simulation started")

    monkeypatch.setattr(solver, "simulate", reached)


def _config(tmp_path, text):
    p = tmp_path / "c.toml"
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("args,fragment", [
    (["--set", "snapshot_times=12"], "run option snapshot_times=12"),
    (["--set", "snapshot_times='12'"], "snapshot_times='12'"),
    (["--set", "snapshot_times=[None]"], "None is not"),
    (["--set", "snapshot_times=['a']"], "'a' is not"),
    (["--t-end", "0.5", "--set", "snapshot_times=[0.25, 1.0]"], "1.0 s is after t_end"),
    (["--set", "write_xdmf=no"], "write_xdmf='no'"),
    (["--set", "write_xdmf='false'"], "write_xdmf='false'"),
    (["--set", "r_outer=20", "--h", "8"], "h=8.0 is out of range: allowed < (r_outer - r_inner)/2 = 7.5 mm"),
    (["--set", "stop_front_radius=4"], "stop_front_radius=4"),
    (["--set", "stop_front_radius=100"], "r_outer = 53] mm"),
    (["--set", "seed=1.5"], "parameter seed=1.5"),
    (["--set", "cement"], "--set 'cement' is not allowed: name=value"),
    (["--set", "cemnt=1.0"], "unknown parameter or run option 'cemnt' (did you mean 'cement'?)"),
    (["--h", "-1"], "run option h=-1.0"),
    (["--config", "{tmp}/missing.toml"], "missing.toml': file not found"),
    (["--config", "CONFIG:[parameters]\ncement = \n"], "not valid TOML"),
    (["--config", "CONFIG:parameters = 3\n"], "[parameters] = 3 is not allowed: a table"),
    (["--config", "CONFIG:[parameters]\ncement = 'high'\n"], "parameter cement='high'"),
    (["--config", "CONFIG:[options]\nwrite_xdmf = \"false\"\n"], "write_xdmf='false'"),
    (["--config", "CONFIG:[options]\nsnapshot_times = 0.5\n"], "snapshot_times=0.5"),
])
def test_dchfrac_run_refuses(tmp_path, capsys, no_simulation, args, fragment):
    from sweep.cli import main

    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    args = [_config(tmp_path, a[7:]) if a.startswith("CONFIG:") else a for a in args]
    out = tmp_path / "run"
    _refused(capsys, main(["run", "--out", str(out), "--quiet", *args]), fragment)
    assert not out.exists()


@pytest.mark.parametrize("out,fragment", [
    ("{file}/run", "exists and is not a folder"),
    ("{file}", "exists and is not a folder"),
])
def test_dchfrac_run_refuses_an_unwritable_out(tmp_path, capsys, no_simulation, out, fragment):
    from sweep.cli import main

    (tmp_path / "f").write_text("a file")
    out = out.replace("{file}", str(tmp_path / "f"))
    _refused(capsys, main(["run", "--out", out, "--quiet"]), f"--out {out!r} cannot be written")


@pytest.mark.parametrize("argv,fragment", [
    (["bench", "--out", "{file}/bench.json"], "dchfrac bench: --out folder"),
    (["report", "reference", "{tmp}/run", "--out", "{file}/report"], "dchfrac report: --out"),
    (["report", "convergence", "{tmp}/a", "{tmp}/b", "--out", "{file}"], "exists and is not a folder"),
])
def test_bench_and_report_refuse_an_unwritable_out(tmp_path, capsys, argv, fragment):
    from sweep.cli import main

    (tmp_path / "f").write_text("a file")
    argv = [a.replace("{file}", str(tmp_path / "f")).replace("{tmp}", str(tmp_path)) for a in argv]
    _refused(capsys, main(argv), fragment)


def test_dchfrac_run_reads_true_and_false_as_toml_does(tmp_path):
    from argparse import Namespace

    from sweep.cli import _run_inputs

    args = Namespace(config=None, set=["write_xdmf=false", "snapshot_times=[0.25]"], h=2.0, t_end=0.5,
                     out=str(tmp_path / "run"))
    params, options, warnings = _run_inputs(args)
    assert options.write_xdmf is False and options.snapshot_times == (0.25,) and warnings == []


# ---------------------------------------------------------------------------
# campaign specs (dchfrac campaign run --dry-run)
# ---------------------------------------------------------------------------
_BASE = 'name = "c"\n[base]\nw_i = 10.0\n[options]\nh = 4.0\nt_end = 0.5\n'


@pytest.mark.parametrize("text,fragment", [
    (_BASE + "[axes]\ncement = [0.5, 0.5]\n", "axes.cement: value 0.5 given twice"),
    (_BASE + "[axes]\nseed = [1, 2, 1.0]\n", "axes.seed: value 1 given twice"),
    (_BASE + "[axes]\ncement = {linear = [1.0, 1.0, 3]}\n", "value 1.0 given twice"),
    (_BASE.replace('name = "c"\n', 'name = "c"\nmode = "zip"\n') + "[axes]\ncement = [1.0, 2.0, 1.0]\neta_o = [0.1, 0.2, 0.1]\n",
     "zip: zipped point {'cement': 1.0, 'eta_o': 0.1} given twice"),
    (_BASE + "[axes]\ncement = [1.0, 2.0]\neta_o = [0.1, 0.1]\nw_i = [10.0, 10.0]\nzip = [[\"eta_o\", \"w_i\"]]\n",
     "zipped point {'eta_o': 0.1, 'w_i': 10.0} given twice"),
    (_BASE.replace('"c"', '".."'), "name='..' must be a plain folder name"),
    (_BASE.replace('"c"', '"."'), "name='.'"),
    (_BASE.replace('"c"', '"a/b"'), "name='a/b'"),
    (_BASE.replace('"c"', '".hidden"'), "name='.hidden'"),
    (_BASE.replace('"c"', '""'), "name=''"),
    (_BASE + "snapshot_times = [0.25, 1.0]\n", "snapshot_times=[0.25, 1.0] is out of range"),
    (_BASE + "write_xdmf = \"false\"\n", "write_xdmf='false'"),
    (_BASE + "stop_front_radius = 2.0\n", "stop_front_radius=2.0"),
    (_BASE.replace("h = 4.0", "h = 8.0") + "[axes]\nr_outer = [53.0, 20.0]\n", "grid point (r_outer=20.0)"),
    (_BASE + "[run]\nrunner = \"no_such_module:run\"\n", "run.runner: runner='no_such_module:run' cannot be imported"),
    (_BASE + "[run]\nrunner = \"sweep.campaign.spec:no_such_function\"\n", "cannot be imported"),
    (_BASE + "[run]\nrunner = \"sweep.campaign.spec\"\n", "must be 'module:function'"),
    (_BASE + "[run]\nmax_runs = 0\n", "max_runs=0 must be an integer >= 1"),
    (_BASE + "[axes]\ncement = {linear = [0.5, 3.0, 1000]}\neta_o = {log = [0.01, 1.0, 1000]}\n",
     "axes: 1000000 runs exceed the limit max_runs = 10000"),
    (_BASE + "[axes]\nw_i = {range = [1, 1000000000, 1]}\n", "axes.w_i.range: 1000000000 runs exceed"),
    (_BASE + "[axes]\ncement = {linear = [0.5, 3.0, 20]}\n[run]\nmax_runs = 10\n", "20 runs exceed the limit max_runs = 10"),
    ('name = "c"\n[axes]\ncement = [1.0, 2.0]\nh = [4.0, 30.0]\n', "grid point (cement=1.0, h=30.0): run option h=30.0"),
])
def test_campaign_dry_run_refuses(tmp_path, capsys, text, fragment):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(text)
    _refused(capsys, main(["run", str(spec), "--dry-run", "--results", str(tmp_path / "res")]), fragment)
    assert not (tmp_path / "res").exists()


def test_campaign_grid_limit_can_be_raised(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_BASE + "[axes]\ncement = {linear = [0.5, 3.0, 20]}\n[run]\nmax_runs = 10\n")
    assert main(["run", str(spec), "--dry-run", "--results", str(tmp_path), "--max-runs", "20"]) == 0
    assert "20 runs in the grid" in capsys.readouterr().out


def test_campaign_dry_run_warns_of_an_unresolved_interface(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_BASE.replace("h = 4.0\n", "") + "[axes]\nh = [2.0, 4.0]\n")
    assert main(["run", str(spec), "--dry-run", "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    # l_S = 4 mm: resolved at h = 2 mm (l_S = 2 h), not at h = 4 mm
    assert "warning: 1 run(s): parameter l_S = 4 mm is below 2 h = 8 mm" in out


def test_campaign_refuses_an_unwritable_results_folder(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "c.toml"
    spec.write_text(_BASE)
    (tmp_path / "f").write_text("a file")
    _refused(capsys, main(["run", str(spec), "--results", str(tmp_path / "f")]),
             f"--results campaign folder '{tmp_path / 'f'}/c' cannot be written")


# ---------------------------------------------------------------------------
# discrepancy data and spec (dchfrac discrepancy run)
# ---------------------------------------------------------------------------
_SPEC = """
[baseline]
effects_off = ["damage_viscosity"]
[[calibrate]]
name = "kbar"
lower = 5e-4
upper = 5e-3
[holdout]
ids = ["c2"]
[options]
h = 4.0
t_end = 0.3
"""
_COND = "id,w_i\nc1,30\nc2,50\n"
_OBS = ("condition,observable,time,value,uncertainty\n"
        "c1,p_inj,0.1,40,2\nc1,p_inj,0.2,60,2\nc1,front_radius_mean,0.2,9.5,0.2\n"
        "c2,p_inj,0.1,50,2\nc2,p_inj,0.2,70,2\nc2,crack_length,0.2,1.5,0.3\nc2,regime,0.3,uniform_invasion,0\n")


def _pa(obs):
    rows = [r.split(",") for r in obs.splitlines()]
    return "\n".join(",".join(r[:3] + [str(float(r[3]) * 1000)] + r[4:]) if r[1] == "p_inj" else ",".join(r)
                     for r in rows) + "\n"


def _ms(obs):
    rows = [r.split(",") for r in obs.splitlines()]
    return "\n".join(",".join(r[:2] + [str(float(r[2]) * 1000)] + r[3:]) if i else ",".join(r)
                     for i, r in enumerate(rows)) + "\n"


@pytest.fixture
def no_workflow(monkeypatch):
    import sweep.discrepancy.workflow as wf

    class Reached(Exception):
        pass

    def reached(*a, **k):
        raise Reached("the workflow started")

    monkeypatch.setattr(wf, "run_workflow", reached)
    return Reached


def _discrepancy(tmp_path, cond=_COND, obs=_OBS, spec=_SPEC, out=None, cache=None):
    from sweep.discrepancy.cli import main

    data = tmp_path / "data"
    data.mkdir(exist_ok=True)
    (data / "conditions.csv").write_text(cond)
    (data / "observations.csv").write_text(obs)
    (tmp_path / "spec.toml").write_text(spec)
    argv = ["discrepancy", "run", "--measured", str(data), "--model", str(tmp_path / "spec.toml"),
            "--out", out or str(tmp_path / "out"), "--quiet", "--no-figures"]
    return main(argv + (["--cache", cache] if cache else []))


def test_discrepancy_valid_input_reaches_the_workflow(tmp_path, no_workflow):
    with pytest.raises(no_workflow):
        _discrepancy(tmp_path)


@pytest.mark.parametrize("change,fragment", [
    (dict(obs=_pa(_OBS)), "a pressure in Pa? The workflow reads kPa"),
    (dict(obs=_ms(_OBS)), "front_radius_mean time=200 s is after the model's t_end = 0.3 s (allowed: times in [0, t_end] s; were they given in ms?)"),
    (dict(obs=_OBS.replace("c1,front_radius_mean,0.2,9.5,0.2", "c1,front_radius_mean,0.2,-9.5,0.2")),
     "negative front_radius_mean -9.5 mm"),
    (dict(obs=_OBS.replace("c1,front_radius_mean,0.2,9.5,0.2", "c1,front_radius_mean,0.2,2.0,0.2")),
     "front_radius_mean value=2 mm at t = 0.2 s is outside the annulus (allowed: [r_inner = 5"),
    (dict(obs=_OBS.replace("c1,front_radius_mean,0.2,9.5,0.2", "c1,front_radius_mean,0.2,90,0.2")),
     "is outside the annulus"),
    (dict(obs=_OBS.replace("c2,crack_length,0.2,1.5,0.3", "c2,crack_length,0.2,-5,0.3")), "negative crack_length -5.0 mm"),
    (dict(obs=_OBS.replace("uniform_invasion", "fracturingg")), "regime value='fracturingg' is not a label the model gives"),
    (dict(obs=_OBS.replace("c2,regime,0.3,", "c2,regime,300,")), "regime time=300 s is after the model's t_end"),
    (dict(spec=_SPEC.replace('ids = ["c2"]', 'ids = ["c9"]')), "holdout ids ['c9'] are not conditions"),
    (dict(spec=_SPEC.replace('ids = ["c2"]', 'ids = ["c1", "c2"]')), "holds out every condition"),
    (dict(spec=_SPEC.replace("h = 4.0", "h = 8.0"), cond="id,w_i,r_outer\nc1,30,\nc2,50,20\n"),
     "condition 'c2' (r_inner = 5, r_outer = 20 mm) cannot run with the spec's options: run option h=8.0"),
    (dict(spec=_SPEC + "[discretization]\nh = 8.0\n", cond="id,w_i,r_outer\nc1,30,\nc2,50,20\n"), "h=8.0"),
    (dict(spec=_SPEC + "[discretization]\nt_end = 0.1\n"), "after the model's t_end = 0.1 s"),
    (dict(cond="id,w_i,seed\nc1,30,1\nc2,50,1.5\n"), "column 'seed': '1.5' is not an integer"),
    (dict(cond="id,w_i\nc1,30\nc2,-50\n"), "parameter w_i=-50.0"),
    (dict(spec=_SPEC.replace("t_end = 0.3", "t_end = 0.3\nsnapshot_times = \"0.3\"")), "snapshot_times='0.3'"),
    (dict(spec=_SPEC.replace("[options]", "[options\n")), "discrepancy"),
    (dict(out="{file}/out"), "--out"),
    (dict(cache="{file}/cache"), "--cache"),
])
def test_discrepancy_run_refuses(tmp_path, capsys, no_workflow, change, fragment):
    (tmp_path / "f").write_text("a file")
    change = {k: v.replace("{file}", str(tmp_path / "f")) for k, v in change.items()}
    _refused(capsys, _discrepancy(tmp_path, **change), fragment)


@pytest.mark.parametrize("old,new,accepted,fragment", [
    ("c2,crack_length,0.2,1.5,0.3", "c2,crack_length,0.2,-1.4,0.3", True, ""),     # 4.7 sd below 0
    ("c2,crack_length,0.2,1.5,0.3", "c2,crack_length,0.2,-1.6,0.3", False, "negative crack_length -1.6 mm"),
    ("c1,front_radius_mean,0.2,9.5,0.2", "c1,front_radius_mean,0.2,4.1,0.2", True, ""),   # 4.5 sd inside r_inner = 5
    ("c1,front_radius_mean,0.2,9.5,0.2", "c1,front_radius_mean,0.2,3.9,0.2", False, "is outside the annulus"),
])
def test_a_length_within_its_noise_of_the_bounds_is_data(tmp_path, capsys, no_workflow, old, new, accepted, fragment):
    """A measured length near a bound (0 for a crack, r_inner for a front) is data up to 5 uncertainties beyond it
    (data.LENGTH_SIGMAS: every value is tested, so the false alarm per value must be tiny); beyond, a clear error."""
    obs = _OBS.replace(old, new)
    if accepted:
        with pytest.raises(no_workflow):
            _discrepancy(tmp_path, obs=obs)
    else:
        _refused(capsys, _discrepancy(tmp_path, obs=obs), fragment)


def test_discrepancy_missing_measured_folder(tmp_path, capsys):
    from sweep.discrepancy.cli import main

    (tmp_path / "spec.toml").write_text(_SPEC)
    rc = main(["discrepancy", "run", "--measured", str(tmp_path / "none"), "--model", str(tmp_path / "spec.toml"),
               "--out", str(tmp_path / "out")])
    _refused(capsys, rc, "measured-data folder")


# ---------------------------------------------------------------------------
# integer parameters read from conditions.csv stay integers
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("cond", ["id,w_i,seed\nc1,30,1\nc2,50,2\n", "id,w_i,seed\nc1,30,1\nc2,50,\n",
                                  "id,seed\nc1,3\nc2,2.0\n"])
def test_integer_parameters_of_conditions_stay_integers(tmp_path, cond):
    from sweep.discrepancy.data import load_measured

    data = tmp_path / "data"
    data.mkdir()
    (data / "conditions.csv").write_text(cond)
    (data / "observations.csv").write_text(_OBS)
    d = load_measured(data)
    for cid in d.ids:
        p = d.condition_params(cid)
        if "seed" in p:
            assert type(p["seed"]) is int
        Parameters.from_dict(p)  # seed=1.0 would be refused


def test_workflow_runs_on_conditions_with_a_seed_column(tmp_path):
    """The crash on valid data: the seed column (integers) upcast to float and refused by Parameters."""
    from sweep.discrepancy.data import write_measured, load_measured
    from sweep.discrepancy.spec import spec_from_dict
    from sweep.discrepancy.toy import ToyForward
    from sweep.discrepancy.workflow import run_workflow

    import pandas as pd

    truth = ToyForward()
    conds = {"a": {"w_i": 30.0, "seed": 1}, "b": {"w_i": 50.0, "seed": 2}, "c": {"w_i": 70.0, "seed": 3}}
    rows = []
    for cid, c in conds.items():
        t = np.array([0.1, 0.2, 0.3])
        pred = truth.predict_one(c, {"p_inj": t})
        rows += [(cid, "p_inj", ti, v, 1.0) for ti, v in zip(t, pred["p_inj"])]
    folder = write_measured(tmp_path / "data", conds, pd.DataFrame(rows, columns=["condition", "observable", "time",
                                                                                   "value", "uncertainty"]))
    data = load_measured(folder)
    assert [type(data.condition_params(c)["seed"]) for c in "abc"] == [int, int, int]
    spec = spec_from_dict({"baseline": {"effects_off": ["damage_viscosity"]},
                           "calibrate": [{"name": "kbar", "lower": 5e-4, "upper": 5e-3}],
                           "holdout": {"ids": ["c"]}, "fit": {"max_nfev": 3}})
    rep = run_workflow(data, spec, ToyForward(), figures=False)
    assert rep["verdict"] in ("no_missing_effect", "named", "tie", "unexplained_discrepancy")


@pytest.mark.parametrize("option,fragment", [
    ("anderson_depth=-1", "anderson_depth=-1"), ("no_such_option=1", "no_such_option"),
    ("anderson_depth", "--option 'anderson_depth' is not allowed: name=value"), ("first_stagger_rtol=fast", "first_stagger_rtol='fast'"),
])
def test_bench_profile_refuses_bad_run_options_before_any_run(tmp_path, capsys, option, fragment, monkeypatch):
    import sweep.studies.bench
    from sweep.cli import main

    monkeypatch.setattr(sweep.studies.bench, "run_profile", lambda *a, **k: pytest.fail("a run started"))
    _refused(capsys, main(["bench", "--profile", "--out", str(tmp_path / "p.json"), "--option", option]), fragment)


def test_bench_profile_passes_its_run_options(tmp_path, monkeypatch):
    import sweep.studies.bench
    from sweep.cli import main

    seen = {}
    monkeypatch.setattr(sweep.studies.bench, "run_profile",
                        lambda out, sizes, t_end, options=None, compare=None, model=None: seen.update(options=options,
                                                                                                      model=model))
    assert main(["bench", "--profile", "--out", str(tmp_path / "p.json"), "--option", "anderson_depth=3",
                 "--option", "first_stagger_rtol=1e-3"]) == 0
    assert seen["options"] == {"anderson_depth": 3, "first_stagger_rtol": 1e-3} and seen["model"] is None
    assert main(["bench", "--profile", "--out", str(tmp_path / "p.json"), "--preset", "experiment",
                 "--set", "porosity_floor=0.1"]) == 0
    assert seen["model"] == {"preset": "experiment", "changes": {"porosity_floor": 0.1}}


@pytest.mark.parametrize("args, fragment", [
    (["--preset", "nope"], "preset 'nope' is not defined"), (["--set", "foo=1"], "unknown parameter(s) ['foo']"),
    (["--set", "porosity_floor=-1"], "porosity_floor=-1"),
])
def test_bench_profile_refuses_a_bad_model_before_any_run(tmp_path, capsys, monkeypatch, args, fragment):
    import sweep.studies.bench
    from sweep.cli import main

    monkeypatch.setattr(sweep.studies.bench, "run_profile", lambda *a, **k: pytest.fail("a run started"))
    _refused(capsys, main(["bench", "--profile", "--out", str(tmp_path / "p.json"), *args]), fragment)

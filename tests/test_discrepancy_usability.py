"""The discrepancy workflow for a newcomer: the observable registry, the typed option tables, the starting SPEC
written from a data folder (``dchfrac discrepancy init``) and the unit check of the measured pressures.
No solver runs."""
import dataclasses
import re
import tomllib

import numpy as np
import pandas as pd
import pytest

from sweep.discrepancy.data import OBSERVABLES, load_measured
from sweep.discrepancy.forward import observables_from_timeseries
from sweep.discrepancy.observables import REGISTRY, ObservableUnavailable
from sweep.discrepancy.options import OPTION_TABLES, REMOVED_WORKFLOW_KEYS, parse_options
from sweep.discrepancy.spec import load_spec, spec_from_dict

COND = "id,w_i,cement\nw35,35,1.2\nw50,50,\nw65,65,2.0\n"
OBS = ("condition,observable,time,value,uncertainty\n"
       "w35,p_inj,0.1,120,2\nw35,p_inj,0.25,180,2\nw50,p_inj,0.1,150,2\nw50,front_radius_branches,0.2,14.5,0.3\n"
       "w65,p_inj,0.1,160,2\nw65,regime,0.31,invasive_fracturing,0\n")


def _folder(tmp_path, cond=COND, obs=OBS):
    d = tmp_path / "data"
    d.mkdir(parents=True, exist_ok=True)
    (d / "conditions.csv").write_text(cond)
    (d / "observations.csv").write_text(obs)
    return d


# ----------------------------------------------------------------------------- observable registry
def test_registry_is_the_loaders_and_the_forward_models_list(tmp_path):
    """Every registered observable is accepted in observations.csv and read from a time series by its rule;
    the paper's front measure reads its own column, and a run without it names the observable."""
    assert set(OBSERVABLES) == set(REGISTRY)
    assert REGISTRY["front_radius_branches"].unit == "mm" and REGISTRY["crack_length"].unit == "mm"
    assert REGISTRY["p_inj"].unit == "kPa" and REGISTRY["regime"].kind == "label"
    ts = pd.DataFrame({"t": [0.1, 0.2, 0.3], "p_inj": [10.0, 20.0, 40.0], "front_radius_mean": [6.0, 7.0, 8.0],
                       "front_radius_branches": [7.0, 9.0, 13.0], "open_tip_radius": [0.0, 9.0, 15.0]})
    out = observables_from_timeseries(ts, {"front_radius_branches": [0.15, 0.25], "crack_length": [0.1, 0.3],
                                           "regime": [0.3]}, r_inner=5.0)
    np.testing.assert_allclose(out["front_radius_branches"], [8.0, 11.0])       # linear between the steps
    np.testing.assert_allclose(out["crack_length"], [0.0, 10.0])                 # tip radius − r_inner once open
    assert "regime" not in out                                                   # classified from the snapshot
    with pytest.raises(ObservableUnavailable, match="'front_radius_branches' is unavailable.*no column "
                                                    "'front_radius_branches'"):
        observables_from_timeseries(ts.drop(columns="front_radius_branches"), {"front_radius_branches": [0.1]}, 5.0)
    d = load_measured(_folder(tmp_path))
    assert d.times("w50", "front_radius_branches").tolist() == [0.2]
    from sweep.discrepancy.twins import twin_observables

    camp = {"data": {"observables": ["p_inj", "front_radius_branches"]}}
    assert twin_observables(camp, {"name": "t"}) == ("p_inj", "front_radius_branches")
    with pytest.raises(ValueError, match=r"\['front_radius'\] not among the registered"):
        twin_observables({"data": {"observables": ["p_inj", "front_radius"]}}, {"name": "t"})


# ----------------------------------------------------------------------------- option tables
def test_every_option_has_a_rule_and_its_default_passes_it():
    """One declaration per setting: its default validates, and a value of the wrong type is refused naming
    table, key and value."""
    for name, cls in OPTION_TABLES.items():
        for f in dataclasses.fields(cls):
            assert f.metadata["doc"] and f.metadata["kind"] in ("int", "float", "bool", "choice")
            parse_options({name: {f.name: f.default}})
            with pytest.raises(ValueError, match=rf"{name}\.{f.name}='x' is not allowed"):
                parse_options({name: {f.name: "x"}})
    opts = parse_options({})
    assert opts.fit.max_nfev == 20 and opts.profile.fine is True and opts.noise.model_jitter == "none"
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.fit.max_nfev = 3
    with pytest.raises(ValueError, match=r"fit\.max_nfev=0 is not allowed: an integer >= 1"):
        OPTION_TABLES["fit"](max_nfev=0)             # built directly, checked alike
    for key in REMOVED_WORKFLOW_KEYS:            # removed settings exist in no table
        assert all(key not in {f.name for f in dataclasses.fields(c)} for c in OPTION_TABLES.values())


# ----------------------------------------------------------------------------- dchfrac discrepancy init
def test_init_writes_a_commented_spec_that_loads(tmp_path):
    """The starting SPEC lists the folder's conditions and observables, makes every catalogue effect a
    candidate, holds out the last condition, runs to the last observation time and loads as written."""
    from solver.effects import EFFECTS
    from sweep.discrepancy.cli import main

    folder = _folder(tmp_path)
    out = tmp_path / "spec.toml"
    assert main(["discrepancy", "init", "--measured", str(folder), "--out", str(out)]) == 0
    text = out.read_text()
    spec = load_spec(out)
    assert set(spec.candidates) == set(EFFECTS) == set(spec.effects_off)
    assert spec.holdout(["w35", "w50", "w65"]) == ["w65"]
    assert spec.options["t_end"] == pytest.approx(0.31) and [p.name for p in spec.calibrate] == ["E", "kbar"]
    assert spec.fit == parse_options({}).fit                                     # defaults, spelled out
    assert (spec.profile.emulator, spec.profile.emulate_refits) == ("gp", True)  # the solver's starting values
    assert parse_options({}).profile.emulator == "none"                          # the library default
    # the coverage study's calibrated interval: the likelihood's own error terms
    assert (spec.noise.disc_error_fraction, spec.profile.likelihood) == (0.0, "marginal")
    assert (parse_options({}).noise.disc_error_fraction, parse_options({}).profile.likelihood) == (0.5, "weighted")
    # the correction along the profile by the coverage study's recorded rule; the library keeps "point"
    assert (spec.profile.correction, parse_options({}).profile.correction) == ("piecewise", "point")
    line = next(x for x in text.splitlines() if x.startswith("correction = "))
    assert "results/discrepancy/README.md" in line and "library default" in line, line
    for word in ("w35", "front_radius_branches (mm)", "p_inj (kPa)", "regime (label)", "[profile]", "rough_tol"):
        assert word in text
    assert "'w65': 'invasive_fracturing at 0.31 s'" in text                               # each condition's observed label
    parsed = tomllib.loads(text)
    for table, cls in OPTION_TABLES.items():                                      # every setting listed
        assert set(parsed[table]) == {f.name for f in dataclasses.fields(cls)}


def test_init_spec_uses_the_shared_realization_settings_and_the_library_keeps_its_defaults(tmp_path):
    """The starting SPEC parses with [profile] threshold = "f_realizations", [noise] realization_blocks =
    "observable" and lag1 = "mean_ratio" (results/discrepancy/shared_realization/README.md), each line saying
    why; the library defaults stay "chi2", "series", "pooled" (committed twins reproduce)."""
    from sweep.discrepancy.init_spec import starting_spec

    folder = _folder(tmp_path)
    text = starting_spec(load_measured(folder), folder)
    spec = spec_from_dict(tomllib.loads(text))
    assert (spec.profile.threshold, spec.noise.realization_blocks, spec.noise.lag1) == \
        ("f_realizations", "observable", "mean_ratio")
    lib = parse_options({})
    assert (lib.profile.threshold, lib.noise.realization_blocks, lib.noise.lag1) == ("chi2", "series", "pooled")
    for key in ("threshold = \"f_realizations\"", "realization_blocks = \"observable\"", "lag1 = \"mean_ratio\""):
        line = next(x for x in text.splitlines() if x.startswith(key))
        assert "shared_realization/README.md" in line and "library default" in line, line


def test_init_does_not_calibrate_what_the_conditions_set(tmp_path):
    from sweep.discrepancy.init_spec import starting_spec

    folder = _folder(tmp_path, cond="id,w_i,E\na,35,300\nb,50,400\n",
                     obs="condition,observable,time,value,uncertainty\na,p_inj,0.1,1,1\nb,p_inj,0.1,1,1\n")
    spec = spec_from_dict(tomllib.loads(starting_spec(load_measured(folder), folder)))
    assert [p.name for p in spec.calibrate] == ["kbar"]


@pytest.mark.parametrize("obs, match", [
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,180000,2000"), r"observations.csv, row 3, column 'value': "
                                                                         r"p_inj value 180000 .*kPa: a pressure in Pa"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,180,20000"), r"row 3, column 'uncertainty': .*in Pa"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,,2"), r"row 3, column 'value': empty value"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,NaN,2"), r"row 3, column 'value': 'NaN' is not a finite"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,180,0"), r"row 3, column 'uncertainty': zero"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w35,p_inj,0.25,180,-2"), r"row 3, column 'uncertainty': negative"),
    (OBS.replace("w35,p_inj,0.25,180,2", "w99,p_inj,0.25,180,2"), r"row 3, column 'condition': unknown condition"),
    (OBS.replace("uncertainty", "sigma"), r"row 1, column 'uncertainty': missing column"),
])
def test_init_and_run_reject_bad_data_naming_file_row_and_column(tmp_path, capsys, obs, match):
    """Bad measured data stops both commands before anything is written or run: exit 2, one line."""
    from sweep.discrepancy.cli import main

    folder = _folder(tmp_path, obs=obs)
    out = tmp_path / "spec.toml"
    assert main(["discrepancy", "init", "--measured", str(folder), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and re.search(match, err), err
    assert not out.exists()
    good = tmp_path / "good"
    good.mkdir()
    (good / "conditions.csv").write_text(COND)
    (good / "observations.csv").write_text(OBS)
    assert main(["discrepancy", "init", "--measured", str(good), "--out", str(out)]) == 0
    assert main(["discrepancy", "run", "--measured", str(folder), "--model", str(out), "--out",
                 str(tmp_path / "run")]) == 2
    assert not (tmp_path / "run").exists()


def test_init_refuses_to_overwrite_and_says_run_needs_two_conditions(tmp_path, capsys):
    from sweep.discrepancy.cli import main

    folder = _folder(tmp_path)
    out = tmp_path / "spec.toml"
    out.write_text("# mine\n")
    assert main(["discrepancy", "init", "--measured", str(folder), "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == "# mine\n"
    assert main(["discrepancy", "init", "--measured", str(folder), "--out", str(out), "--force"]) == 0
    one = _folder(tmp_path / "one", cond="id,w_i\na,35\n", obs="condition,observable,time,value,uncertainty\na,p_inj,0.1,1,1\n")
    # one condition observing p_inj only: nothing to hold out, refused by init as by run (one validator)
    assert main(["discrepancy", "init", "--measured", str(one), "--out", str(tmp_path / "x.toml")]) == 2
    assert "at least 2 conditions" in capsys.readouterr().err and not (tmp_path / "x.toml").exists()
    two = _folder(tmp_path / "two", cond="id,w_i\na,35\n", obs="condition,observable,time,value,uncertainty\n"
                  "a,p_inj,0.1,1,1\na,front_radius_mean,0.1,10,1\n")
    assert main(["discrepancy", "init", "--measured", str(two), "--out", str(tmp_path / "y.toml")]) == 0
    assert 'observables = ["front_radius_mean"]' in (tmp_path / "y.toml").read_text()  # held out of the fit


def test_init_runs_on_the_readme_example(tmp_path, capsys):
    from pathlib import Path

    from sweep.discrepancy.cli import main

    example = Path(__file__).resolve().parents[1] / "results" / "fidelity" / "experiment"
    assert main(["discrepancy", "init", "--measured", str(example), "--out", str(tmp_path / "s.toml")]) == 0
    assert "p_inj" in (tmp_path / "s.toml").read_text()


def test_random_starts_lie_inside_the_bounds_and_repeat_with_the_seed():
    from sweep.discrepancy.problem import random_starts
    from sweep.discrepancy.spec import CalibParam

    params = (CalibParam("kbar", 5e-4, 5e-3, 1e-3), CalibParam("E", 150.0, 700.0, 331.0, scale="linear"))
    xs = random_starts(params, 50, seed=3)
    lo, hi = np.array([p.x_bounds for p in params]).T
    assert len(xs) == 50 and all(np.all((lo <= x) & (x <= hi)) for x in xs)
    assert np.array_equal(np.vstack(xs), np.vstack(random_starts(params, 50, seed=3)))
    assert random_starts(params, 0, 3) == [] and random_starts(params, -2, 3) == []

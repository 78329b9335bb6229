"""Every input validates or is refused with a one-line error naming a field: never another exception, never a
hang (issue #48).

Two parts:

* ``BAD_INPUTS``: a table of bad inputs, each with the message it must give (parameters, run options,
  campaign specs, discrepancy specs and measured data; units mm, s, kPa);
* property-based fuzzing (hypothesis) of the same parsers: a valid input with some fields replaced by
  arbitrary values (numbers of any size, NaN, infinities, text, booleans, lists, tables, None), or extra
  unknown fields.  Each must parse, or raise ValueError whose message is one line and names a field.  The
  default suite runs a bounded number of examples (seconds); the ``slow`` variant runs many.
"""
import math
from dataclasses import fields

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from solver import Parameters, RunOptions
from solver.options import check_run_inputs

PARAM_NAMES = [f.name for f in fields(Parameters)]
OPTION_NAMES = [f.name for f in fields(RunOptions)]

# ----------------------------------------------------------------------------- values
_numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10, max_value=100),
    st.sampled_from([0, 1, -1, 10**20, 2**63, 10**400, 1e-300, 1e300, 331000.0, 2000.0, 1e9]),
)
_scalars = st.one_of(_numbers, st.booleans(), st.none(), st.text(max_size=12),
                     st.sampled_from(["", "nan", "inf", "1e400", "fracturingg", "random", "os:system", "9**9**9"]))
VALUES = st.one_of(_scalars, st.lists(_scalars, max_size=4), st.dictionaries(st.text(max_size=6), _scalars, max_size=3))
_field_chars = st.characters(min_codepoint=48, max_codepoint=122)
UNKNOWN_NAMES = st.text(alphabet=_field_chars, min_size=1, max_size=10)


def assert_one_line_naming(exc: BaseException, names) -> None:
    """``exc`` is a ValueError with a one-line message that names one of ``names``."""
    assert isinstance(exc, ValueError), f"{type(exc).__name__}: {exc}"
    msg = str(exc)
    assert msg and "\n" not in msg, msg
    assert any(str(n) in msg for n in names), f"no field named in: {msg}"


def _outcome(fn, names):
    """fn() parses, or raises a one-line ValueError naming one of ``names``."""
    try:
        return fn()
    except Exception as exc:  # noqa: BLE001 - what is asserted is the kind of exception and its message
        assert_one_line_naming(exc, names)
        return None


# ----------------------------------------------------------------------------- the table of bad inputs
def _parameters(d):
    return Parameters.from_dict(d)


def _options(d):
    return RunOptions.from_dict(d)


def _run_inputs(d):
    return check_run_inputs(Parameters.from_dict(d.get("p", {})), RunOptions.from_dict(d.get("o", {})))


def _campaign(d):
    from sweep.campaign.spec import spec_from_dict

    return spec_from_dict({"name": "c", "base": {"w_i": 10.0}, "options": {"h": 4.0, "t_end": 0.5}, **d})


def _discrepancy_spec(d):
    from sweep.discrepancy import spec_from_dict

    base = {"baseline": {"effects_off": ["damage_viscosity"]},
            "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
            "candidates": {"effects": ["damage_viscosity"]}, "holdout": {"ids": ["b"]},
            "options": {"h": 8.0, "t_end": 1.0}}
    return spec_from_dict({**base, **d})


def _measured(d, tmp_path):
    from sweep.discrepancy import load_measured

    folder = tmp_path / "data"
    folder.mkdir(exist_ok=True)
    (folder / "conditions.csv").write_text(d.get("conditions", "id,w_i\na,30\nb,50\n"))
    (folder / "observations.csv").write_text(d.get("observations", "condition,observable,time,value,uncertainty\n"
                                                   "a,p_inj,0.1,100,2\nb,p_inj,0.1,100,2\n"))
    return load_measured(folder)


PARSERS = {"parameters": _parameters, "options": _options, "run_inputs": _run_inputs, "campaign": _campaign,
           "discrepancy_spec": _discrepancy_spec, "measured": _measured}
_OBS = "condition,observable,time,value,uncertainty\n"

BAD_INPUTS = [
    ("parameters", {"E": 331000.0}, "parameter E=331000.0 makes the drained bulk modulus"),
    ("parameters", {"E": 331000.0}, "E = 331000 kPa is 331 MPa: did you mean Pa?"),
    ("parameters", {"K_s": 100.0}, "parameter K_s=100.0 is out of range"),
    ("parameters", {"cement": 10**400}, "parameter cement='100000000000... (401 digits)' is out of range"),
    ("parameters", {"cement": math.nan}, "parameter cement=nan is out of range: allowed a finite number"),
    ("parameters", {"cement": "high"}, "parameter cement='high' is out of range: allowed a real number"),
    ("parameters", {"cement": True}, "parameter cement=True is out of range: allowed a real number"),
    ("parameters", {"seed": 99999999999999999999}, "parameter seed=99999999999999999999 is out of range"),
    ("parameters", {"seed": -1}, "parameter seed=-1 is out of range: allowed an integer in [0, 2**63 - 1]"),
    ("parameters", {"seed": 1.5}, "parameter seed=1.5 is out of range"),
    ("parameters", {"nu": 0.5}, "parameter nu=0.5 is out of range: allowed the open interval (-1, 0.5)"),
    ("parameters", {"r_outer": 4.0}, "parameter r_outer=4.0 is out of range: allowed > r_inner = 5.0"),
    ("parameters", {"l_d": 400.0}, "parameter l_d=400.0 is out of range: allowed <= 3 G_c/(8 psi_c)"),
    ("parameters", {"porosity_field": "randm"}, "parameter porosity_field='randm' is out of range: allowed one of"),
    ("parameters", {"cemnt": 1.0}, "unknown parameter(s) ['cemnt'] (did you mean 'cement'?)"),
    ("parameters", {"k_s": 1.0}, "unknown parameter(s) ['k_s'] (did you mean 'K_s'?)"),
    ("parameters", {"eta_w": 0.0}, "parameter eta_w=0.0 is out of range: allowed > 0.0"),
    ("options", {"t_end": 10**400}, "run option t_end='100000000000... (401 digits)' is out of range"),
    ("options", {"t_end": -1.0}, "run option t_end=-1.0 is out of range: allowed > 0.0"),
    ("options", {"h": 30.0}, "run option h=30.0 is out of range: allowed <= 24.0"),
    ("options", {"mesh_seed": 2**63}, "run option mesh_seed=9223372036854775808 is out of range"),
    ("options", {"tend": 2.0}, "unknown run option(s) ['tend'] (did you mean 't_end'?)"),
    ("options", {"snapshot_times": "0.5"}, "run option snapshot_times='0.5' is out of range"),
    ("options", {"write_xdmf": "false"}, "run option write_xdmf='false' is out of range: allowed true or false"),
    ("run_inputs", {"p": {"r_outer": 20.0}, "o": {"h": 8.0}}, "run option h=8.0 is out of range: allowed < (r_outer - r_inner)/2"),
    ("run_inputs", {"o": {"stop_front_radius": 3.0}}, "run option stop_front_radius=3.0 is out of range"),
    ("campaign", {"derived": {"psi_c": "9**9**9"}, "axes": {"cement": [1.0, 2.0]}},
     "derived.psi_c = '9**9**9': expression '9**9**9' overflows a float"),
    ("campaign", {"derived": {"psi_c": "cement + 1e400"}, "axes": {"cement": [1.0]}}, "gives inf (allowed: a finite number)"),
    ("campaign", {"derived": {"psi_c": "+".join(["cement"] * 200)}}, "derived.psi_c: invalid expression: expression of"),
    ("campaign", {"derived": {"psi_c": "__import__('os')"}, "axes": {"cement": [1.0]}}, "derived.psi_c"),
    ("campaign", {"axes": {"seed": [1, 99999999999999999999]}}, "parameter seed=99999999999999999999 is out of range"),
    ("campaign", {"axes": {"cement": {"linear": [0.5, 3.0, 1000]}, "eta_o": {"linear": [0.1, 1.0, 1000]}}},
     "axes: 1000000 runs exceed the limit max_runs = 10000 and the ceiling 100000 of any grid"),
    ("campaign", {"run": {"max_runs": 10**6}}, "run.max_runs: max_runs=1000000 must be at most 100000"),
    ("campaign", {"run": {"runner": "os:system"}}, "run.runner: runner='os:system' is not a runner"),
    ("campaign", {"axes": {"cemnt": [1.0, 2.0]}}, "cemnt"),
    ("campaign", {"axes": {"cement": [1.0, 1.0]}}, "axes.cement: value 1.0 given twice"),
    ("discrepancy_spec", {"options": {"t_end": -1.0}}, "discrepancy spec [options]: run option t_end=-1.0"),
    ("discrepancy_spec", {"holdout": {"ids": "b"}}, "holdout"),
    ("discrepancy_spec", {"calibrate": [{"name": "E", "lower": 700.0, "upper": 150.0}]}, "calibrate"),
    ("discrepancy_spec", {"fit": {"n_jobs": 0}}, "fit.n_jobs"),
    ("measured", {"conditions": "id,w_i\na,30\na,50\n"}, "conditions.csv, row 3, column 'id': duplicated id 'a'"),
    ("measured", {"conditions": "id,cemnt\na,1\nb,2\n"}, "conditions.csv, row 1, column 'cemnt': unknown column"),
    ("measured", {"conditions": "id,w_i\na,1e400\nb,50\n"}, "column 'w_i': '1e400' is not a finite number"),
    ("measured", {"conditions": "id,E\na,331000\nb,331\n"}, "conditions.csv, row 2: invalid parameters: parameter E=331000.0"),
    ("measured", {"observations": _OBS + "a,p_inj,0.1,100,0\nb,p_inj,0.1,100,2\n"}, "column 'uncertainty': zero uncertainty"),
    ("measured", {"observations": _OBS + "a,p_inj,-1,100,2\nb,p_inj,0.1,100,2\n"}, "column 'time': negative time"),
    ("measured", {"observations": _OBS + "a,p_inj,0.1,331000,2\nb,p_inj,0.1,100,2\n"}, "a pressure in Pa?"),
    ("measured", {"observations": _OBS + "a,front_radius_mean,0.1,-1,0.1\nb,p_inj,0.1,100,2\n"},
     "negative front_radius_mean -1.0 mm"),
    ("measured", {"observations": _OBS + "a,p_inj,0.1,100,2\nc,p_inj,0.1,100,2\n"}, "unknown condition 'c'"),
    ("measured", {"observations": _OBS + "a,presure,0.1,100,2\nb,p_inj,0.1,100,2\n"}, "unknown observable 'presure'"),
    ("measured", {"observations": _OBS + "a,p_inj,0.1,100,2\n"}, "condition 'b' has no observations"),
]


@pytest.mark.parametrize("kind,inp,message", BAD_INPUTS, ids=[f"{k}-{i}" for i, (k, _, _) in enumerate(BAD_INPUTS)])
def test_bad_input_is_refused_in_one_line_with_its_message(kind, inp, message, tmp_path):
    args = (inp, tmp_path) if kind == "measured" else (inp,)
    with pytest.raises(ValueError) as e:
        PARSERS[kind](*args)
    assert message in str(e.value) and "\n" not in str(e.value), str(e.value)


# ----------------------------------------------------------------------------- fuzzing
def _mutations(names, extra_names=UNKNOWN_NAMES):
    """A dict of some of ``names`` set to arbitrary values, sometimes with an unknown name."""
    return st.tuples(st.dictionaries(st.sampled_from(names), VALUES, max_size=4),
                     st.dictionaries(extra_names, VALUES, max_size=1), st.booleans()
                     ).map(lambda t: {**t[0], **t[1]} if t[2] else t[0])


def check_parameters(d):
    p = _outcome(lambda: Parameters.from_dict(d), PARAM_NAMES + list(d))
    if p is not None:
        from solver.params import plausibility_warnings

        assert all("\n" not in w for w in plausibility_warnings(p))


def check_options_with_parameters(d):
    opts = {k: v for k, v in d.items() if k in OPTION_NAMES}
    pars = {k: v for k, v in d.items() if k not in OPTION_NAMES}
    names = PARAM_NAMES + OPTION_NAMES + list(d)
    p = _outcome(lambda: Parameters.from_dict(pars), names)
    o = _outcome(lambda: RunOptions.from_dict(opts), names)
    if p is not None and o is not None:
        ws = _outcome(lambda: check_run_inputs(p, o), names)
        assert ws is None or all("\n" not in w for w in ws)


_CAMPAIGN_KEYS = ["name", "base", "derived", "options", "axes", "mode", "zip", "run", "sampler", "classify", "blocks"]
# axis counts stay small (a grid of up to max_runs = 10^4 valid points takes ~20 s to validate: slow, not wrong);
# the huge ones are in _numbers' samples (refused from the counts, before any point is built)
_axis_numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=-3, max_value=12),
                          st.sampled_from([0, 10**20, 2**63, 10**400, 1e-300, 1e300]))
_CAMPAIGN_VALUES = st.one_of(
    VALUES,
    st.dictionaries(st.sampled_from(PARAM_NAMES + ["h", "t_end", "cemnt"]), VALUES, max_size=2),
    st.dictionaries(st.sampled_from(["cement", "seed", "eta_o", "h", "psi_c"]),
                    st.one_of(st.lists(_axis_numbers, max_size=4), st.text(max_size=20),
                              st.fixed_dictionaries({"linear": st.lists(_axis_numbers, min_size=3, max_size=3)})),
                    max_size=2),
)


def check_campaign(d):
    from sweep.campaign.spec import spec_from_dict
    from sweep.campaign.sampler import grid_points

    spec = {"name": "c", "base": {"w_i": 10.0}, "options": {"h": 4.0, "t_end": 0.5}, "axes": {"cement": [1.0, 2.0]}}
    spec.update(d)
    names = _CAMPAIGN_KEYS + PARAM_NAMES + OPTION_NAMES + [str(k) for k in d]
    s = _outcome(lambda: spec_from_dict(spec), names)
    if s is not None:
        _outcome(lambda: grid_points(s), names)


_DISC_KEYS = ["baseline", "calibrate", "alternative", "candidates", "holdout", "options", "discretization", "fit",
              "acceptance", "noise", "profile", "workflow"]


def check_discrepancy_spec(d):
    names = _DISC_KEYS + PARAM_NAMES + OPTION_NAMES + [str(k) for k in d]
    _outcome(lambda: _discrepancy_spec(d), names)


_cells = st.one_of(st.sampled_from(["", "nan", "inf", "-1", "0", "1e400", "331000", "0.1", "50", "a", "b", "c",
                                    "p_inj", "front_radius_mean", "crack_length", "regime", "fracturingg",
                                    "invasive_fracturing", "\ufeffid", "2"]),
                   st.text(alphabet=st.characters(blacklist_characters=",\n\r\"", blacklist_categories=("Cs",)),
                           max_size=6))


def _csv(header, rows):
    return ",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows)


def check_measured(conditions, observations, tmp_path_factory):
    from sweep.discrepancy.checks import check_data_against_model, spec_models

    tmp = tmp_path_factory.mktemp("m")
    names = ["conditions.csv", "observations.csv", "measured-data"]
    data = _outcome(lambda: _measured({"conditions": conditions, "observations": observations}, tmp), names)
    if data is not None:
        spec = _discrepancy_spec({"holdout": {"ids": data.ids[-1:]}})
        _outcome(lambda: check_data_against_model(data, spec, spec_models(spec)),
                 ["condition", "observations.csv", "discrepancy spec", "holdout"])


def _fuzz_cases(max_examples: int):
    common = dict(max_examples=max_examples, deadline=None, derandomize=max_examples <= 100,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

    @settings(**common)
    @given(_mutations(PARAM_NAMES))
    def parameters(d):
        check_parameters(d)

    @settings(**common)
    @given(_mutations(PARAM_NAMES + OPTION_NAMES))
    def options(d):
        check_options_with_parameters(d)

    @settings(**common)
    @given(st.dictionaries(st.sampled_from(_CAMPAIGN_KEYS), _CAMPAIGN_VALUES, max_size=3))
    def campaign(d):
        check_campaign(d)

    @settings(**common)
    @given(st.dictionaries(st.sampled_from(_DISC_KEYS), st.one_of(VALUES, st.dictionaries(
        st.sampled_from(["h", "t_end", "ids", "effects", "n_jobs", "effects_off", "loss", "name"]), VALUES,
        max_size=2)), max_size=2))
    def discrepancy_spec(d):
        check_discrepancy_spec(d)

    return {"parameters": parameters, "options": options, "campaign": campaign, "discrepancy_spec": discrepancy_spec}


def _measured_case(max_examples: int, tmp_path_factory):
    cond_rows = st.lists(st.tuples(_cells, _cells).map(list), min_size=0, max_size=3)
    obs_rows = st.lists(st.tuples(_cells, _cells, _cells, _cells, _cells).map(list), min_size=0, max_size=4)
    headers = st.sampled_from([["id", "w_i"], ["id", "E"], ["id", "seed"], ["id", "porosity_field"], ["idx", "w_i"]])

    @settings(max_examples=max_examples, deadline=None, derandomize=max_examples <= 100,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
    @given(headers, cond_rows, obs_rows)
    def measured(header, crows, orows):
        check_measured(_csv(header, crows), _csv(["condition", "observable", "time", "value", "uncertainty"], orows),
                       tmp_path_factory)

    return measured


@pytest.mark.parametrize("parser,examples", [("parameters", 40), ("options", 40), ("campaign", 25),
                                             ("discrepancy_spec", 40)])
def test_fuzzed_input_parses_or_is_refused_in_one_line_naming_a_field(parser, examples):
    """Bounded: a campaign spec expands and validates its grid, the costliest of the parsers."""
    _fuzz_cases(examples)[parser]()


def test_fuzzed_measured_data_parse_or_are_refused_in_one_line_naming_the_file(tmp_path_factory):
    _measured_case(40, tmp_path_factory)()


@pytest.mark.slow
@pytest.mark.parametrize("parser", ["parameters", "options", "campaign", "discrepancy_spec"])
def test_fuzzed_input_many_examples(parser):
    _fuzz_cases(2000)[parser]()


@pytest.mark.slow
def test_fuzzed_measured_data_many_examples(tmp_path_factory):
    _measured_case(1000, tmp_path_factory)()


def test_the_table_holds_every_parser():
    assert {k for k, _, _ in BAD_INPUTS} == set(PARSERS)


"""Baseline parameters held fixed but uncertain (``[[alternative]]``): the screen's identifiability against them.

A candidate whose signature a change of such a parameter reproduces must not be named (never a confident wrong
name): the screen projects the signature off the alternatives' directions as well as the calibrated ones.
Checked on exact linear algebra and on twins of the closed-form toy (sweep.discrepancy.toy), where the
compliance rescales the pressure exactly as k̄ does (P0/(1 + 2c), P0 ∝ 1/k̄).  Units mm, s, kPa.
"""
import numpy as np
import pytest

from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict, stats
from sweep.discrepancy.problem import Problem

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
TIMES = np.linspace(0.02, 1.0, 50)
CONDS = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}
DATA_BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}
KBAR_ALT = {"name": "kbar", "lower": 5e-4, "upper": 5e-3}


# ----------------------------------------------------------------------------- the projection
def _columns():
    t = np.linspace(0.0, 1.0, 60)
    J = np.column_stack([np.ones_like(t)])                     # the calibrated parameter: an offset
    a1, a2 = t, np.sin(2 * np.pi * t)                          # two alternatives' directions
    return t, J, a1, a2


def test_signature_in_an_alternatives_span_is_confounded_with_it():
    t, J, a1, a2 = _columns()
    sig = {"mimic": 2.0 * a1 + 0.01 * np.cos(7 * np.pi * t), "free": np.exp(-((t - 0.5) / 0.05) ** 2)}
    r = np.zeros_like(t)
    without = stats.signature_table(r, np.ones_like(t), J, sig)
    assert without["mimic"]["identifiable"] and without["mimic"]["alternative_ratio"] is None
    tab = stats.signature_table(r, np.ones_like(t), J, sig, A=np.column_stack([a1, a2]), alternatives=("x1", "x2"))
    m = tab["mimic"]
    assert not m["identifiable"] and m["confounded_with"] == ["x1"] and m["score"] == 0.0
    # exact: the part of the signature outside span{1, t, sin 2πt}, over its norm
    Q = np.linalg.qr(np.column_stack([J, a1, a2]))[0]
    s = sig["mimic"]
    assert m["alternative_ratio"] == pytest.approx(np.linalg.norm(s - Q @ (Q.T @ s)) / np.linalg.norm(s), rel=1e-9)
    assert m["ratio"] == pytest.approx(without["mimic"]["ratio"], rel=1e-12)     # the calibrated-only ratio as before
    assert tab["free"]["identifiable"] and tab["free"]["confounded_with"] == []


def test_confounding_by_alternatives_together_names_them_all():
    t, J, _, _ = _columns()
    u, v, w = (np.sin(2 * k * np.pi * t) for k in (1, 2, 3))
    sig = {"mix": u + v}                                      # neither alone reproduces it, both together do
    A = np.column_stack([u + w, v - w])
    tab = stats.signature_table(np.zeros_like(t), np.ones_like(t), J, sig, A=A, alternatives=("x1", "x2"))
    assert tab["mix"]["alternative_ratio"] < 1e-12 and tab["mix"]["confounded_with"] == ["x1", "x2"]
    with pytest.raises(ValueError, match="alternative columns"):
        stats.signature_table(np.zeros_like(t), np.ones_like(t), J, sig, A=A, alternatives=("x1",))


def test_an_alternative_confounds_only_within_its_range():
    """An alternative at the lower end of its range (c_A >= 0) reproduces a signature along +a1 but not one along
    −a1: the bounded screen (stats.bounded_lstsq) finds −a1 identifiable, with the ratio the calibrated column
    alone leaves (exact: its projection off J), and keeps +a1 confounded as the unbounded screen does."""
    t, J, a1, _ = _columns()
    a1 = a1 - a1.mean()                                        # orthogonal to the calibrated offset
    sig = {"up": 2.0 * a1, "down": -2.0 * a1}
    A = a1[:, None]
    args = (np.zeros_like(t), np.ones_like(t), J, sig)
    free = stats.signature_table(*args, A=A, alternatives=("x1",))
    assert not free["up"]["identifiable"] and not free["down"]["identifiable"]
    bounds = (np.array([-np.inf, 0.0]), np.array([np.inf, np.inf]))
    tab = stats.signature_table(*args, A=A, alternatives=("x1",), bounds=bounds)
    assert not tab["up"]["identifiable"] and tab["up"]["confounded_with"] == ["x1"]
    assert tab["up"]["alternative_ratio"] < 1e-12
    assert tab["down"]["identifiable"] and tab["down"]["confounded_with"] == []
    assert tab["down"]["alternative_ratio"] == pytest.approx(tab["down"]["ratio"], rel=1e-9)
    assert tab["down"]["alternative_ratio"] == pytest.approx(1.0, rel=1e-9)   # a1 ⟂ the offset: nothing absorbed


def test_a_calibrated_parameter_absorbs_a_signature_only_within_its_range():
    """The calibrated offset can move by at most +0.5 (its range's end): a signature of +2 along it keeps the
    share it cannot reach, 1.5/2 = 0.75 of its norm (exact), with the amplitude and score of that share, where
    the unbounded projection absorbed it all (ratio 0, not identifiable); a signature of +0.4 lies within reach
    and is absorbed either way.  With alternatives, the calibrated-only ratio is never below the one off
    [J, A]: one bounded rule for both."""
    t, J, a1, _ = _columns()
    a1 = a1 - a1.mean()
    sig = {"far": 2.0 * J[:, 0], "near": 0.4 * J[:, 0]}
    r = 1.5 * J[:, 0]                                          # the data ask for what the offset cannot give
    free = stats.signature_table(r, np.ones_like(t), J, sig)
    assert free["far"]["ratio"] < 1e-12 and not free["far"]["identifiable"]
    tab = stats.signature_table(r, np.ones_like(t), J, sig, bounds=(np.array([-np.inf]), np.array([0.5])))
    assert tab["far"]["ratio"] == pytest.approx(0.75, rel=1e-9) and tab["far"]["identifiable"]
    assert tab["far"]["amplitude"] == pytest.approx(1.5 / 1.5, rel=1e-9)          # r·s⊥/|s⊥|², s⊥ = 1.5·1
    assert tab["far"]["score"] == pytest.approx(1.5 ** 2 * t.size, rel=1e-9)      # (r·s⊥)²/|s⊥|²
    assert tab["near"]["ratio"] < 1e-9 and not tab["near"]["identifiable"]
    both = stats.signature_table(r, np.ones_like(t), J, {"far": sig["far"] + a1}, A=a1[:, None],
                                 alternatives=("x1",), bounds=(np.array([-np.inf, -np.inf]), np.array([0.5, 0.1])))
    assert both["far"]["ratio"] >= both["far"]["alternative_ratio"] - 1e-12


def test_bounded_least_squares_known_answers():
    """stats.bounded_lstsq: the unbounded solution when it lies within the bounds; otherwise the bounded
    optimum (two orthonormal columns: each coefficient is its projection clipped to its bounds)."""
    M = np.eye(3)[:, :2]
    s = np.array([2.0, -3.0, 1.0])
    assert stats.bounded_lstsq(M, s) == pytest.approx([2.0, -3.0])
    assert stats.bounded_lstsq(M, s, [0.0, 0.0], [1.0, np.inf]) == pytest.approx([1.0, 0.0], abs=1e-12)
    with pytest.raises(ValueError, match="bounded_lstsq: bounds"):
        stats.bounded_lstsq(M, s, [1.0, 0.0], [0.0, 1.0])


# ----------------------------------------------------------------------------- the SPEC
def _spec(alternatives=(), calibrate=("E",), cands=("compliant_boundary", "damage_viscosity"), baseline=None):
    bounds = {"kbar": (5e-4, 5e-3), "E": (150.0, 700.0)}
    return spec_from_dict({"baseline": {"effects_off": OFF, **(baseline or {})},
                           "calibrate": [{"name": n, "lower": bounds[n][0], "upper": bounds[n][1]} for n in calibrate],
                           "alternative": list(alternatives),
                           "candidates": {"effects": list(cands)}, "holdout": {"ids": ["d"]},
                           "options": {"h": 8.0, "t_end": 1.0}})


@pytest.mark.parametrize("alt,message", [
    ({"name": "E", "lower": 150.0, "upper": 700.0}, "alternative.name='E'.*not calibrated"),
    ({**KBAR_ALT, "initial": 0.002}, r"alternative\[kbar\].initial=0.002.*baseline value"),
    ({"name": "no_such", "lower": 1.0, "upper": 2.0}, "alternative.name='no_such'"),
    ({"name": "outer_compliance", "lower": 0.0, "upper": 1.0, "scale": "linear"}, "not an effect strength"),
    ({"name": "kbar", "lower": 2e-3, "upper": 5e-3}, r"alternative\[kbar\].initial=0.0015.*inside"),
    ({**KBAR_ALT, "step": -0.1}, r"alternative\[kbar\].step=-0.1"),
    ({"name": "kbar", "lower": 0.0, "upper": 5e-3}, r"alternative\[kbar\].lower/upper"),
])
def test_bad_alternatives_are_refused_by_name(alt, message):
    with pytest.raises(ValueError, match=message):
        _spec(alternatives=[alt])


def test_a_repeated_alternative_is_refused_and_a_good_one_is_kept():
    with pytest.raises(ValueError, match="alternative.name='kbar'.*once"):
        _spec(alternatives=[KBAR_ALT, KBAR_ALT])
    spec = _spec(alternatives=[KBAR_ALT], baseline={"kbar": 0.002})
    (a,) = spec.alternatives
    assert (a.name, a.initial, a.scale) == ("kbar", 0.002, "log")         # the baseline's value, log by default


def test_a_condition_may_not_set_an_alternative(tmp_path):
    conds = {**CONDS, "d": {"w_i": 40.0, "kbar": 0.002}}
    data = load_measured(make_twin(tmp_path / "data", ToyForward(DATA_BASE, h=2.0), conds, TIMES, {}, seed=1,
                                   observables=("p_inj",)))
    with pytest.raises(ValueError, match=r"condition 'd' sets alternative parameter\(s\) \['kbar'\]"):
        Problem(data, _spec(alternatives=[KBAR_ALT]), ToyForward({}, h=8.0))


# ----------------------------------------------------------------------------- twins
def _twin(tmp_path, hidden):
    fwd = ToyForward(DATA_BASE, h=2.0)
    return load_measured(make_twin(tmp_path / "data", fwd, CONDS, TIMES, hidden, seed=1, observables=("p_inj",)))


def test_a_fixed_parameter_mimicked_by_a_candidate_gives_a_wrong_name_unless_it_is_an_alternative(tmp_path):
    """The truth is k̄ 10 % above the baseline's (not calibrated, not an effect): on pressure data the compliance
    c = 0.05 reproduces it exactly.  Without alternatives the workflow names the compliance (the R3 failure);
    with k̄ declared uncertain it names nothing and says against what the compliance is not identifiable."""
    data = _twin(tmp_path, {"kbar": 0.00165})
    wrong = run_workflow(data, _spec(), ToyForward({}, h=8.0))
    assert wrong["verdict"] == "named" and wrong["named_effect"] == "compliant_boundary"
    assert wrong["strength"] == pytest.approx(0.05, rel=0.1)
    rep = run_workflow(data, _spec(alternatives=[KBAR_ALT]), ToyForward({}, h=8.0), out_dir=tmp_path / "out",
                       figures=False)
    assert rep["named_effect"] is None and rep["verdict"] == "unexplained_discrepancy"
    rows = {c["effect"]: c for c in rep["candidates"]}
    assert rows["compliant_boundary"]["confounded_with"] == ["kbar"]
    assert rows["compliant_boundary"]["alternative_ratio"] < 0.15 <= rows["compliant_boundary"]["signature_ratio"]
    assert "compliant_boundary" in rep["not_identifiable"]
    assert rows["damage_viscosity"]["confounded_with"] == []
    assert "not identifiable against ['kbar']" in (tmp_path / "out" / "report.md").read_text()


def test_an_alternative_does_not_block_an_effect_it_cannot_mimic(tmp_path):
    """Hidden β = 40: its pressure bump (∝ w_i, decaying in 0.2 s) is not a change of k̄, so with k̄ declared
    uncertain the damage viscosity is still named with the truth inside its interval."""
    rep = run_workflow(_twin(tmp_path, {"beta": 40.0}), _spec(alternatives=[KBAR_ALT]), ToyForward({}, h=8.0))
    assert rep["verdict"] == "named" and rep["named_effect"] == "damage_viscosity"
    lo, hi = rep["strength_interval"]
    assert lo <= 40.0 <= hi
    row = {c["effect"]: c for c in rep["candidates"]}["damage_viscosity"]
    assert row["identifiable"] and row["alternative_ratio"] >= 0.15 and row["confounded_with"] == []


def test_the_real_solver_campaign_declares_k_s_uncertain():
    """campaigns/discrepancy/discrepancy_twins_alternatives_k6.toml: the k6 twins with K_s as an alternative, on emulators."""
    from pathlib import Path

    from sweep.discrepancy.twins import load_twin_campaign

    camp = load_twin_campaign(Path(__file__).resolve().parents[1] / "campaigns" / "discrepancy" / "discrepancy_twins_alternatives_k6.toml")
    spec = spec_from_dict(camp["spec"])
    assert [(a.name, a.initial) for a in spec.alternatives] == [("K_s", 1600.0)]
    assert spec.profile.emulator == "gp" and spec.profile.emulate_refits
    assert {t["name"]: t["expect"] for t in camp["twin"]} == {
        "outside_catalogue_k6": "unexplained_discrepancy", "damage_viscosity_k6": "damage_viscosity",
        "compliant_boundary_k6": "not_identifiable"}


# ----------------------------------------------------------------------------- rival refits
def _prepared(data, spec):
    from sweep.discrepancy.evidence import refit, screen
    from sweep.discrepancy.workflow import calibrate, prepare

    run = prepare(data, spec, ToyForward({}, h=8.0), None)
    calibrate(run)
    scr = screen(run.problem, run.current, ["compliant_boundary"], run.train)
    best = refit(run.problem, run.current, "compliant_boundary", scr["compliant_boundary"], run.train, run.holdout,
                 run.gap_cur)
    return run, best


def test_a_rival_that_reproduces_the_candidate_ties_with_it(tmp_path):
    """k̄ 10 % high on pressure data: the compliance's refit passes, and k̄ freed as a rival of it reaches the
    truth 0.00165 with a BIC no worse (the two models are the same curves: P0/(1 + 2c) = 0.05 w η/k̄')."""
    from sweep.discrepancy.evidence import rival_refits

    run, best = _prepared(_twin(tmp_path, {"kbar": 0.00165}), _spec(alternatives=[KBAR_ALT]))
    assert best["passed"] and best["strength"] == pytest.approx(0.05, rel=0.1)
    (row,) = rival_refits(run.problem, best, run.current, run.train, run.holdout)
    assert row["alternative"] == "kbar" and row["value"] == pytest.approx(0.00165, rel=0.02)
    # same curves, same parameter count: the BICs agree to the fits' tolerance, far inside tie_bic = 10
    assert abs(row["delta_bic"]) < 1.0 and row["ties"]


def test_a_rival_that_cannot_reproduce_the_candidate_does_not_tie(tmp_path):
    """Hidden compliance c = 0.05 with the front measured too: the compliance also speeds the front by
    1 + 20 c, which no k̄ does, so k̄ freed is far worse and the compliance is named with k̄ declared uncertain."""
    fwd = ToyForward(DATA_BASE, h=2.0)
    data = load_measured(make_twin(tmp_path / "data", fwd, CONDS, TIMES, {"outer_compliance": 0.05}, seed=1,
                                   observables=("p_inj", "front_radius_mean")))
    rep = run_workflow(data, _spec(alternatives=[KBAR_ALT]), ToyForward({}, h=8.0), out_dir=tmp_path / "out",
                       figures=False)
    assert rep["verdict"] == "named" and rep["named_effect"] == "compliant_boundary"
    lo, hi = rep["strength_interval"]
    assert lo <= 0.05 <= hi
    (row,) = rep["rivals"]
    assert row["alternative"] == "kbar" and not row["ties"] and row["delta_bic"] > 10.0
    assert "Rival of compliant_boundary" in (tmp_path / "out" / "report.md").read_text()


def test_a_tying_rival_makes_the_verdict_a_tie_not_a_name(tmp_path):
    """The accept step: with the screen's threshold at 0 (so the linear screen lets the compliance through, as
    it does on the solver when the alternative's book value is far from the truth), k̄ 10 % high on pressure
    data gives a passing compliance and a k̄ rival that ties with it: verdict "tie", never the name."""
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "alternative": [KBAR_ALT], "candidates": {"effects": ["compliant_boundary", "damage_viscosity"]},
         "holdout": {"ids": ["d"]}, "options": {"h": 8.0, "t_end": 1.0}, "acceptance": {"min_ratio": 0.0}}
    rep = run_workflow(_twin(tmp_path, {"kbar": 0.00165}), spec_from_dict(d), ToyForward({}, h=8.0),
                       out_dir=tmp_path / "out", figures=False)
    assert rep["verdict"] == "tie" and rep["named_effect"] is None
    assert rep["tie"] == ["compliant_boundary", "alternative:kbar"]
    (row,) = rep["rivals"]
    assert row["ties"] and row["value"] == pytest.approx(0.00165, rel=0.02)
    assert "it ties" in (tmp_path / "out" / "report.md").read_text()

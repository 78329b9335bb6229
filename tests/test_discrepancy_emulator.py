"""The Gaussian-process emulator of the profile likelihood ([profile] emulator = "gp", emulator.py): the
process against known functions, its covariance in the likelihood, and the toy workflow's interval with the
emulator against the one from real runs (sweep.discrepancy.toy; never the solver)."""
import math

import numpy as np
import pytest

from sweep.discrepancy import ToyForward, load_measured, make_twin, run_workflow, spec_from_dict
from sweep.discrepancy.emulator import GaussianProcess, space_filling

OFF = ["damage_viscosity", "compliant_boundary", "crack_permeability", "volumetric_coupling"]
TIMES = np.linspace(0.02, 1.0, 15)
CONDS = {"a": {"w_i": 30.0}, "b": {"w_i": 50.0}, "c": {"w_i": 70.0}, "d": {"w_i": 40.0}}
DATA_BASE = {"beta": 0.0, "outer_compliance": 0.0, "crack_permeability": 0.0, "volumetric_coupling": 0.0}


def _smooth(u):
    """Three smooth outputs of two inputs on [0, 1]², on scales 1000 apart (kPa beside mm)."""
    return np.column_stack([1e3 * (np.sin(3 * u[:, 0]) + u[:, 1] ** 2), np.exp(-u[:, 0]) * np.cos(2 * u[:, 1]),
                            0.3 * u[:, 0] * u[:, 1]])


# ----------------------------------------------------------------------------- the process
def test_gp_interpolates_its_design_and_its_sd_grows_away_from_it():
    u = np.linspace(0.0, 1.0, 7)[:, None]
    z = np.column_stack([np.sin(4 * u[:, 0]) + u[:, 0], 10 * np.cos(3 * u[:, 0])])
    gp = GaussianProcess(u, z)
    mean, c = gp.predict(u)
    scale = np.sqrt(np.diag(gp.out_cov))
    # at its design: the data to its nugget (the smooth part's variance there is O(nugget))
    assert np.all(np.abs(mean - z) <= 3 * math.sqrt(gp.nugget) * scale + 1e-9 * np.abs(z).max())
    assert np.all(c <= 3 * gp.nugget + 1e-10)
    # between design points and beyond them its sd is larger, growing with the distance outside
    mid = (u[:-1] + u[1:]) / 2
    assert np.all(gp.sd(mid) > 2 * gp.sd(u).max(axis=0))
    out = gp.sd(np.array([[1.0], [1.1], [1.3], [1.6], [2.0]]))[:, 0]
    assert np.all(np.diff(out) > 0)


@pytest.mark.parametrize("n", [10, 16])
def test_gp_error_is_within_its_predictive_sd_at_held_out_points(n):
    """On a known smooth function the standardized errors z = (f − mean)/sd at held-out points have
    E z² <= 1 if the sd is right (or conservative): by Chebyshev at least 3/4 of them lie within 2 sd, and
    their mean square is near 1 or below (not above 4: the error twice the stated sd)."""
    U = space_filling(n, np.zeros(2), np.ones(2), seed=3)
    gp = GaussianProcess(U, _smooth(U))
    V = np.random.default_rng(9).random((400, 2))
    z = (_smooth(V) - gp.predict(V)[0]) / gp.sd(V)
    assert np.mean(np.abs(z) <= 2.0) >= 0.75
    assert np.mean(z**2) <= 4.0


def test_gp_needs_enough_design_points():
    with pytest.raises(ValueError, match=r"4 design points for 2 parameters; needs >= 6"):
        GaussianProcess(np.random.default_rng(0).random((4, 2)), np.zeros((4, 1)))


# ----------------------------------------------------------------------------- the covariance in the likelihood
def test_added_covariance_whitens_to_the_generalized_least_squares_residual(tmp_path):
    """With a realization covariance C and an added X: r·r = diffᵀ (D + C + sX)⁻¹ diff, the log-determinant
    term is ln det(D + C + sX) − ln det(D + C), and at s = 0 the residuals are the noise model's own."""
    from sweep.discrepancy.problem import Problem

    prob = Problem(_twin(tmp_path), _spec(), ToyForward({}, h=8.0))
    rng = np.random.default_rng(2)
    n = prob.y.size
    prob.noise.set_discretization(np.zeros(n), prob.y + rng.normal(0, 2.0, (3, n)), 0.5)
    mask = prob.mask(["a", "b"])
    sel = np.flatnonzero(mask)
    A = rng.normal(size=(sel.size, 4)) * prob.sig_diag[sel][:, None]
    X = A @ A.T                                         # rank 4, like an emulator's from few points
    diff = rng.normal(size=sel.size) * prob.sig_diag[sel]
    sc = prob.noise.with_scaled(mask, X)
    S = np.diag(prob.sig_diag[sel] ** 2) + prob.noise.real_cov.dense(sel)
    for s in (0.0, 0.3, 2.0):
        r, logdet = sc.standardize(diff, s)
        assert r @ r == pytest.approx(diff @ np.linalg.solve(S + s * X, diff), rel=1e-9)
        assert logdet == pytest.approx(np.linalg.slogdet(S + s * X)[1] - np.linalg.slogdet(S)[1], abs=1e-9)
    np.testing.assert_allclose(sc.standardize(diff, 0.0)[0], prob.noise.standardize(diff, mask, 0.0), atol=1e-9)
    assert sc.sd_norm(0.5) == pytest.approx(math.sqrt(0.5 * np.trace(np.linalg.solve(S, X))), rel=1e-9)


def test_emulator_leaves_failed_runs_out_and_waits_for_enough_points(tmp_path):
    """A design run that failed (NaN anywhere) is counted and left out; the process is fitted only once the
    design has parameters + 4 finite points, and then reproduces the runs it was given."""
    from sweep.discrepancy.emulator import CurveEmulator
    from sweep.discrepancy.problem import Problem

    spec = _spec()
    prob = Problem(_twin(tmp_path), spec, ToyForward({}, h=8.0))
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    lo, hi = np.array([p.x_bounds[0] for p in params]), np.array([p.x_bounds[1] for p in params])
    em = CurveEmulator(prob, params, ["a", "b"], (lo, hi))
    xs = space_filling(7, lo, hi, seed=1)
    ms = em.model_vectors(list(xs))
    assert em.runs == 7 * 2                                       # one run per condition and point
    ms[1, 3] = np.nan
    em.add(list(xs[:5]), ms[:5])
    assert em.failed == 1 and len(em.X) == 4 and em.gp is None   # 4 < 2 + 4: no process yet
    em.add(list(xs[5:]), ms[5:])
    assert len(em.X) == 6 and em.gp is not None
    mean, s = em.predict(xs[6])
    assert np.allclose(mean, ms[6], atol=1e-3 * np.abs(ms[6]).max()) and s < 1e-3


# ----------------------------------------------------------------------------- the toy workflow
def _twin(tmp_path, hidden=None):
    fwd = ToyForward(DATA_BASE, h=2.0)
    return load_measured(make_twin(tmp_path / "data", fwd, CONDS, TIMES, hidden or {"beta": 40.0}, seed=1,
                                   observables=("p_inj", "front_radius_mean")))


def _spec(profile=None, calibrate=("E",)):
    bounds = {"kbar": (5e-4, 5e-3), "E": (150.0, 700.0)}
    return spec_from_dict({"baseline": {"effects_off": OFF},
                           "calibrate": [{"name": n, "lower": bounds[n][0], "upper": bounds[n][1]} for n in calibrate],
                           "candidates": {"effects": ["damage_viscosity", "compliant_boundary"]},
                           "holdout": {"ids": ["d"]}, "options": {"h": 8.0, "t_end": 1.0},
                           "fit": {"max_nfev": 50}, "profile": profile or {}})


def test_emulated_profile_ends_are_crossings_of_the_real_profile(tmp_path):
    """The emulated interval's ends, each confirmed by a real run, lie where the real profile (the others
    refitted with real runs) crosses the threshold: within the refinement's stopping tolerance plus the
    emulator's error in χ², bounded by Cauchy–Schwarz as 2 |r| |d| + |d|² (|d| the whitened deviation of the
    real run from the emulator at the end, |r| the residuals' norm there)."""
    from sweep.discrepancy.problem import Problem
    from sweep.discrepancy.profile import _Profile, emulator_for, profile_interval

    spec = _spec({"emulator": "gp", "refine": 10, "refine_tol": 0.01}, calibrate=("kbar", "E"))
    fwd = ToyForward({}, h=8.0)
    prob = Problem(_twin(tmp_path), spec, fwd)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    train = ["a", "b", "c"]
    fit = prob.fit(params, [np.array([p.to_x(p.initial) for p in spec.calibrate] + [30.0])], train)
    before = fwd.n_runs
    pr = profile_interval(prob, fit, 2, train, emulator=emulator_for(prob, fit, train))
    emulated_runs = fwd.n_runs - before
    assert pr["emulator"]["confirmed"] and pr["lower"] < 40.0 < pr["upper"]
    real = _Profile(prob, fit, 2, train, 3.841, None)               # the same profile on real runs
    for c in [c for c in pr["emulator"]["checks"] if c["agrees"]]:
        d = c["deviation"]
        norm_r = math.sqrt(real.chi2_hat + c["delta_chi2_real"] + 1.0)
        tol = 0.01 * pr["threshold"] + 2 * norm_r * d + d * d
        assert abs(real.dchi2(params[2].to_x(c["value"])) - pr["threshold"]) <= tol
    # the same profile on real runs costs more
    before = fwd.n_runs
    exact = profile_interval(prob, fit, 2, train)
    assert emulated_runs < fwd.n_runs - before
    assert exact["lower"] == pytest.approx(pr["lower"], rel=1e-2) and exact["upper"] == pytest.approx(pr["upper"], rel=1e-2)


def _mesh_dependent_toy_fit(tmp_path, profile: dict, corrected_at_beta: float | None = None):
    """The toy whose mesh error grows with β (β → β (1 + 0.1 h)): data at h = 2 with β = 40, the model at
    h = 8 fitted with kbar, E and β, the correction from one h = 2 realization estimated at the first fit (at
    β = ``corrected_at_beta`` when given) and the model refitted under it.  Returns (problem, fine, fit, train)."""
    from sweep.discrepancy.noise import add_discretization_error
    from sweep.discrepancy.problem import Problem

    spec = _spec(profile, calibrate=("kbar", "E"))
    data = load_measured(make_twin(tmp_path / "data", ToyForward(DATA_BASE, h=2.0, beta_mesh=0.1), CONDS, TIMES,
                                   {"beta": 40.0}, seed=1, observables=("p_inj", "front_radius_mean")))
    prob = Problem(data, spec, ToyForward({}, h=8.0, beta_mesh=0.1))
    fine = ToyForward({}, h=2.0, beta_mesh=0.1)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    train = ["a", "b", "c"]
    fit = prob.fit(params, [np.array([p.to_x(p.initial) for p in spec.calibrate] + [30.0])], train)
    at = fit.values() if corrected_at_beta is None else {**fit.values(), "effect:damage_viscosity": corrected_at_beta}
    add_discretization_error(prob, fine, at)
    return prob, fine, prob.fit(params, [fit.x], train), train


def test_an_end_check_takes_the_real_delta_chi2_under_the_points_own_correction(tmp_path):
    """With fine models each profile point is compared under the correction re-estimated there; an end's
    check records the real run's Δχ² under that same correction, so on an agreeing check it differs from the
    emulated Δχ² by at most the emulator's error, 2 |r| |d| + |d|² (Cauchy–Schwarz, as above).  The toy's
    mesh error depends strongly on β (β → β (1 + 0.1 h)), so the fit's correction would put the real Δχ²
    off by far more."""
    from sweep.discrepancy.profile import emulator_for, profile_interval

    prob, fine, fit, train = _mesh_dependent_toy_fit(tmp_path, {"emulator": "gp", "fine": True, "refine": 10,
                                                                 "refine_tol": 0.01})
    pr = profile_interval(prob, fit, 2, train, fine_forward=fine, emulator=emulator_for(prob, fit, train))
    agreeing = [c for c in pr["emulator"]["checks"] if c["agrees"]]
    assert len(agreeing) == 2 and pr["lower"] < 40.0 < pr["upper"]
    for c in agreeing:
        d = c["deviation"]
        norm_r = math.sqrt(float(fit.r @ fit.r) + max(c["delta_chi2_emulated"], c["delta_chi2_real"]) + 1.0)
        assert abs(c["delta_chi2_real"] - c["delta_chi2_emulated"]) <= 2 * norm_r * d + d * d + 1e-9


def test_with_fine_models_the_fit_is_its_own_profile_point_whatever_correction_it_was_made_under(tmp_path):
    """With fine models Δχ² is measured from the fit's own point taken as every profile point is (the
    correction re-estimated there, the others refitted under it), so Δχ² at the fit's strength is 0 up to the
    refit's tolerance even when the fit was made under a correction estimated elsewhere (here at β = 20, the
    truth being 40: the toy's mesh error grows with β).  The stale correction's χ² differs from that
    reference by more than the threshold: measured from it, every point would carry that offset."""
    from sweep.discrepancy.profile import _Profile

    prob, fine, fit, train = _mesh_dependent_toy_fit(tmp_path, {"fine": True}, corrected_at_beta=20.0)
    pf = _Profile(prob, fit, 2, train, 3.841, fine)
    assert abs(pf.chi2_hat - pf.chi2_fit) > pf.thr
    assert abs(pf.dchi2(float(fit.x[2]))) <= 0.01 * pf.thr


def test_workflow_with_the_emulator_names_the_effect_with_the_exact_interval_for_fewer_runs(tmp_path):
    """The toy workflow with and without the emulator: the same verdict and named effect, fewer forward runs
    in the profile stage, and the interval's ends apart by at most what each end's stopping rule allows:
    both stop within refine_tol·threshold of it in Δχ², which for a quadratic profile (slope 4·thr/width at
    an end) is refine_tol/4 of the width per end, twice that between two ends, plus the emulator's own
    error (confirmed below emulator_tol in the whitened norm, so below 2·|r|·tol in Δχ²)."""
    data = _twin(tmp_path)
    reps = {}
    for emu in ("none", "gp"):
        reps[emu] = run_workflow(data, _spec({"emulator": emu}), ToyForward({}, h=8.0), out_dir=tmp_path / emu,
                                 figures=False)
    off, on = reps["none"], reps["gp"]
    assert off["verdict"] == on["verdict"] == "named" and off["named_effect"] == on["named_effect"] == "damage_viscosity"
    runs = {k: r["forward_runs_by_stage"]["profile_likelihood"]["coarse"] for k, r in reps.items()}
    assert 0 < runs["gp"] < runs["none"]
    pr = on["profiles"]["damage_viscosity"]
    assert pr["emulator"]["confirmed"] and pr["emulator"]["forward_runs"] <= runs["gp"]
    (lo0, hi0), (lo1, hi1) = off["strength_interval"], on["strength_interval"]
    width = hi0 - lo0
    chi = math.sqrt(len(TIMES) * 2 * 3 + pr["threshold"])       # |r| at an end: ~ √(rows + threshold)
    tol = (2 * 0.15 * pr["threshold"] + 2 * chi * 0.1) / (4 * pr["threshold"]) * width
    assert abs(lo1 - lo0) <= tol and abs(hi1 - hi0) <= tol
    assert lo1 < 40.0 < hi1
    md = (tmp_path / "gp" / "report.md").read_text()
    assert "Emulated profile" in md and "| lower |" in md and "Emulated profile" not in (tmp_path / "none" / "report.md").read_text()


class _JitteryToy(ToyForward):
    """The toy with outputs that jitter in the parameters as a coarse mesh's do: a pseudo-random offset,
    fixed for each parameter set (a hash of E, β and the rate), of sd 0.2 kPa in p_inj and 0.02 mm in the
    front, smooth in time (a fraction 1 − e^(−t/0.1) of it)."""

    def predict_one(self, overrides, times):
        from solver import Parameters

        out = super().predict_one(overrides, times)
        p = Parameters.from_dict({**self.base, **overrides})
        rng = np.random.default_rng([int(abs(hash((round(p.E, 9), round(p.damage_viscosity, 9), p.w_i)))) % 2**32])
        a, b = rng.standard_normal(2)
        for obs, amp in (("p_inj", 0.2 * a), ("front_radius_mean", 0.02 * b)):
            out[obs] = out[obs] + amp * (1 - np.exp(-np.asarray(times[obs], float) / 0.1))
        return out


def test_emulator_of_a_jittery_model_carries_the_jitter_and_confirms_its_ends(tmp_path):
    """A coarse model that jitters in its parameters: the emulator cannot follow the jitter, so its
    predictive sd for a real run must cover it.  Each interval end's last real-run check agrees with the
    emulator within AGREE_SD of that sd (or emulator_tol), the interval holds the truth, and the profile
    costs fewer runs than on the real model."""
    data = _twin(tmp_path)
    reps = {emu: run_workflow(data, _spec({"emulator": emu}), _JitteryToy({}, h=8.0), figures=False)
            for emu in ("none", "gp")}
    on = reps["gp"]
    assert on["verdict"] == "named" and on["named_effect"] == "damage_viscosity"
    em = on["profiles"]["damage_viscosity"]["emulator"]
    assert em["confirmed"]
    lo, hi = on["strength_interval"]
    assert lo < 40.0 < hi
    runs = {k: r["forward_runs_by_stage"]["profile_likelihood"]["coarse"] for k, r in reps.items()}
    assert runs["gp"] < runs["none"]


# ----------------------------------------------------------------------------- emulated refits
def _robust(r, f_scale=3.0):
    """Σρ(r²) of the soft_l1 loss the spec's [fit] uses (twice scipy's cost)."""
    return float(np.sum(2 * f_scale**2 * (np.sqrt(1 + (np.asarray(r) / f_scale) ** 2) - 1)))


def test_emulated_refit_reaches_the_real_optimum_within_its_stated_error(tmp_path):
    """A candidate's joint refit on its emulator against the same refit on real runs (smooth toy): each
    parameter of the emulated optimum (before the real polish) within its stated error of the real optimum,
    the real robust cost there above the real optimum's by at most ε² (ε = AGREE_SD × the emulator's sd for
    a run at the checked optimum: an error δ moves the optimum by J⁺δ, raising Σρ by at most |δ|²), the
    optimum confirmed by a real run, and fewer runs."""
    from sweep.discrepancy.emulated import EmulatedRefits
    from sweep.discrepancy.emulator import AGREE_SD
    from sweep.discrepancy.problem import Problem

    spec = _spec({"emulator": "gp", "emulate_refits": True}, calibrate=("kbar", "E"))
    fwd = ToyForward({}, h=8.0)
    prob = Problem(_twin(tmp_path), spec, fwd)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    train = ["a", "b", "c"]
    base = prob.fit(tuple(spec.calibrate), [np.array([p.to_x(p.initial) for p in spec.calibrate])], train)
    starts = [np.append(base.x, 30.0)]
    before = fwd.n_runs
    refits = EmulatedRefits(prob, train)
    refits.fit(params, starts, base, "refits")
    emulated_runs, before = fwd.n_runs - before, fwd.n_runs
    real = prob.fit(params, starts, train)
    assert emulated_runs < fwd.n_runs - before
    rec = refits.records[0]
    assert rec["confirmed"] and rec["checks"][-1]["agrees"] and rec["stage"] == "refits"
    x_em = np.array([p.to_x(rec["emulated"][p.name]) for p in params])
    assert np.all(np.abs(x_em - real.x) <= np.array(rec["emulated_error_x"]))
    assert np.all(np.array(rec["emulated_error_x"]) > 0)
    eps = AGREE_SD * rec["checks"][-1]["emulator_sd"]
    r_at_em = prob.residual_batch(params, [x_em], train)[0]
    assert _robust(r_at_em) <= _robust(real.r) + eps**2 + 1e-9 * _robust(real.r)


class _FailingToy(ToyForward):
    """The toy whose every run with the effect on fails (NaN curves)."""

    def predict_one(self, overrides, times):
        from solver import Parameters

        out = super().predict_one(overrides, times)
        if Parameters.from_dict({**self.base, **overrides}).damage_viscosity > 0.0:
            out = {k: (np.full(np.shape(v), np.nan) if k in times else v) for k, v in out.items()}
        return out


def test_refit_emulator_whose_design_runs_fail_says_how_to_do_without_it(tmp_path):
    from sweep.discrepancy.emulated import EmulatedRefits
    from sweep.discrepancy.problem import Problem

    spec = _spec({"emulator": "gp", "emulate_refits": True})
    prob = Problem(_twin(tmp_path), spec, _FailingToy({}, h=8.0))
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    base = prob.fit(tuple(spec.calibrate), [np.array([spec.calibrate[0].to_x(331.0)])], ["a", "b", "c"])
    with pytest.raises(RuntimeError, match=r"refit emulator: \d+ of its design runs failed.*emulate_refits = false"):
        EmulatedRefits(prob, ["a", "b", "c"]).fit(params, [np.append(base.x, 30.0)], base, "refits")


def _runs(report, stage):
    return report["forward_runs_by_stage"].get(stage, {}).get("coarse", 0)


@pytest.mark.parametrize("hidden,verdict", [({"beta": 40.0}, "named"), ({"beta": 0.0}, "no_missing_effect")])
def test_workflow_with_emulated_refits_keeps_verdict_and_truth_for_fewer_runs(tmp_path, hidden, verdict):
    """The toy workflow with real refits and with emulated ones: the same verdict (an effect named, or none
    when none is hidden), the truth inside the interval, every emulated refit confirmed by a real run and
    recorded in the report, and fewer refit runs and fewer runs in all (booked under the stage asking)."""
    data = _twin(tmp_path, hidden)
    reps = {k: run_workflow(data, _spec(prof), ToyForward({}, h=8.0), out_dir=tmp_path / k, figures=False)
            for k, prof in (("real", {"emulator": "gp"}), ("emu", {"emulator": "gp", "emulate_refits": True}))}
    real, emu = reps["real"], reps["emu"]
    assert real["verdict"] == emu["verdict"] == verdict
    assert real.get("named_effect") == emu.get("named_effect")
    assert sum(map(lambda s: _runs(emu, s), emu["forward_runs_by_stage"])) < sum(
        map(lambda s: _runs(real, s), real["forward_runs_by_stage"]))
    if verdict != "named":
        return
    assert 0 < _runs(emu, "refits") < _runs(real, "refits")
    lo, hi = emu["strength_interval"]
    assert lo < 40.0 < hi
    recs = emu["emulated_refits"]["refits"]
    assert {r["stage"] for r in recs} >= {"refits"} and all(r["confirmed"] for r in recs)
    assert "emulated_refits" not in real
    assert "## Emulated refits" in (tmp_path / "emu" / "report.md").read_text()


def test_workflow_with_emulated_refits_on_a_jittery_model_confirms_and_covers(tmp_path):
    """A coarse model that jitters in its parameters: the emulated refits' optima are confirmed by real runs
    (the jitter within the emulator's sd for a run), the effect is named with the truth inside its
    interval, and the refits cost fewer runs than on the real model."""
    data = _twin(tmp_path)
    reps = {k: run_workflow(data, _spec(prof), _JitteryToy({}, h=8.0), figures=False)
            for k, prof in (("real", {"emulator": "gp"}), ("emu", {"emulator": "gp", "emulate_refits": True}))}
    emu = reps["emu"]
    assert emu["verdict"] == reps["real"]["verdict"] == "named" and emu["named_effect"] == "damage_viscosity"
    lo, hi = emu["strength_interval"]
    assert lo < 40.0 < hi
    assert all(r["confirmed"] for r in emu["emulated_refits"]["refits"])
    assert _runs(emu, "refits") < _runs(reps["real"], "refits")


# ----------------------------------------------------------------------------- options
@pytest.mark.parametrize("key,value,allowed", [
    ("emulator", "kriging", r'"none" or "gp"'),
    ("emulator", True, r'"none" or "gp"'),
    ("emulator_design", 2, r"an integer in \[3, 200\]"),
    ("emulator_design", 8.0, r"an integer in \[3, 200\]"),
    ("emulator_tol", 0.0, r"a number in \(0, 10\]"),
    ("emulator_tol", float("nan"), r"a number in \(0, 10\]"),
    ("emulator_checks", 0, r"an integer in \[1, 20\]"),
    ("emulate_refits", 1, "true or false"),
    ("emulator_polish", 0, r"an integer in \[1, 50\]"),
])
def test_spec_refuses_bad_emulator_settings(key, value, allowed):
    with pytest.raises(ValueError, match=rf"profile\.{key}=.* is not allowed: {allowed}"):
        _spec({key: value})


def test_spec_refuses_emulated_refits_without_the_emulator():
    with pytest.raises(ValueError, match=r'profile\.emulate_refits=true is not allowed with profile\.emulator="none"'):
        _spec({"emulate_refits": True})


# ----------------------------------------------------------------------------- the marginal likelihood with it
def _noise_with_series(k, n_series=1, n=12, jitter=False, seed=0):
    """A NoiseModel of ``n_series`` series of ``n`` points (σ_diag 1.5 kPa) with an exponentially correlated
    realization covariance from ``k`` realizations (none for k < 2) and, with ``jitter``, a known jitter term."""
    from sweep.discrepancy.layout import CurveLayout
    from sweep.discrepancy.noise import NoiseModel
    from sweep.discrepancy.realizations import RealizationCovariance

    rng = np.random.default_rng(seed)
    t = np.tile(np.linspace(0.02, 0.3, n), n_series)
    lay = CurveLayout(np.repeat(np.arange(n_series), n), np.array(["p_inj"] * (n * n_series)), t)
    nm = NoiseModel(np.zeros(t.size), np.full(t.size, 1.5), lay)
    if k >= 2:
        blocks, jit = {}, {}
        for s, rows in lay.series_rows().items():
            v = rng.uniform(1.0, 4.0, rows.size)
            blocks[s] = (rows, np.sqrt(np.outer(v, v)) * np.exp(-np.abs(np.subtract.outer(t[rows], t[rows])) / 0.1))
            jit[s] = (rows, 0.3 * np.exp(-np.abs(np.subtract.outer(t[rows], t[rows])) / 0.05))
        nm.real_cov = RealizationCovariance(blocks, {"p_inj": 0.1}, {"p_inj": 0.8}, k, lay)
        nm.jitter = None
        if jitter:
            nm.real_cov = nm.real_cov.with_jitter(jit)
        nm._changed(covariance=True)
    return nm, rng


def _emulator_cov(rng, n):
    """A rank-3 added covariance over all rows (cross-series terms included), kPa², like an emulator's."""
    A = rng.normal(size=(n, 3))
    return A @ A.T


def test_marginal_deviance_with_the_emulator_is_the_marginal_one_without_its_covariance():
    """V = 0 (s = 0, or X = 0): the marginal deviance with the emulator's covariance is
    NoiseModel.marginal_deviance of the same residuals (two series, jitter term included)."""
    nm, rng = _noise_with_series(3, n_series=2, jitter=True)
    n = nm.y.size
    mask = np.ones(n, bool)
    X = _emulator_cov(rng, n)
    for _ in range(3):
        diff = rng.normal(size=n) * 3.0
        ref = nm.marginal_deviance(nm.standardize(diff, mask, 0.0), mask)
        assert nm.with_scaled_mixture(mask, X).deviance(diff, 0.0) == pytest.approx(ref, rel=1e-10)
        assert nm.with_scaled_mixture(mask, 0.0 * X).deviance(diff, 2.0) == pytest.approx(ref, rel=1e-10)


def test_marginal_deviance_with_the_emulator_is_gaussian_without_an_estimated_scale():
    """k < 2 (no realization covariance): the deviance is diffᵀ (D + sX)⁻¹ diff, the Gaussian χ² with Σ + V."""
    nm, rng = _noise_with_series(1, n_series=2)
    n = nm.y.size
    mask = np.ones(n, bool)
    X = _emulator_cov(rng, n)
    diff = rng.normal(size=n) * 3.0
    for s in (0.0, 0.4, 3.0):
        exact = diff @ np.linalg.solve(np.diag(nm.sig_diag**2) + s * X, diff)
        assert nm.with_scaled_mixture(mask, X).deviance(diff, s) == pytest.approx(exact, rel=1e-10)


def test_marginal_deviance_with_the_emulator_is_the_dense_two_member_mixture():
    """One series, a two-member mixture (λ at the mid quantiles 1/4 and 3/4 of ν/χ²_ν): the deviance is
    −2 ln(½ Σ_m N(diff; 0, Σ_m + sX)) − ln det(2π(Σ + sX)), Σ_m = D + λ_m C + C_jitter, computed densely."""
    from scipy.stats import chi2, multivariate_normal

    from sweep.discrepancy.noise import ScaledMixture

    nm, rng = _noise_with_series(3, jitter=True)
    n = nm.y.size
    mask = np.ones(n, bool)
    X = _emulator_cov(rng, n)
    rows, C = nm.real_cov.blocks[0]
    nu = nm.real_cov.scale_dof(rows)
    lam = nu / chi2.ppf([0.75, 0.25], nu)
    D, Cj = np.diag(nm.sig_diag**2), nm.real_cov.jitter[0][1]
    mix = ScaledMixture(nm.with_scaled(mask, X), nm.real_cov.mixture_members(mask, nm.sig_diag, n_nodes=2), X)
    for s in (0.0, 0.7, 3.0):
        diff = rng.normal(size=n) * 4.0
        dens = [multivariate_normal(np.zeros(n), D + lm * C + Cj + s * X).logpdf(diff) for lm in lam]
        brute = -2.0 * (np.logaddexp(*dens) - np.log(2.0)) - np.linalg.slogdet(2 * np.pi * (D + C + Cj + s * X))[1]
        assert mix.deviance(diff, s) == pytest.approx(brute, rel=1e-9)


def test_toy_twin_with_the_marginal_likelihood_and_the_emulator_keeps_verdict_and_truth_for_fewer_runs():
    """A toy coverage twin (MeshToy, wander deviations, three check realizations) with [profile] likelihood =
    "marginal" with and without the emulator (the spec accepts both together): the same verdict, the truth
    inside both intervals, every emulated end confirmed and fewer profile runs with the emulator.  Both
    profiles start from the same fit and brackets, so their ends differ by the emulator's error in Δχ², within
    one end's stopping tolerance (refine_tol · threshold in Δχ², refine_tol/4 of the width for a quadratic
    profile); each point's deviance is taken under the correction re-estimated there, as the real one's."""
    from sweep.discrepancy.coverage import SETUPS, VARIANTS, one_draw

    su = SETUPS[1]                                       # kbar calibrated, cement axis, hidden β
    rows = {v: one_draw(su, 0, VARIANTS[v]) for v in ("wander_remedy_marginal", "wander_remedy_marginal_emulator")}
    off, on = rows["wander_remedy_marginal"], rows["wander_remedy_marginal_emulator"]
    assert off["verdict"] == on["verdict"] == "named"
    assert off["covered"] and on["covered"]
    assert on["profile_emulator"]["confirmed"]
    runs = {k: r["runs_by_stage"]["profile_likelihood"]["coarse"] for k, r in rows.items()}
    assert 0 < runs["wander_remedy_marginal_emulator"] < runs["wander_remedy_marginal"]
    tol = 0.15 / 4 * (off["upper"] - off["lower"])
    assert on["lower"] == pytest.approx(off["lower"], abs=tol) and on["upper"] == pytest.approx(off["upper"], abs=tol)


# ----------------------------------------------------------------------------- the cost comparison
def _study(variant, rows):
    return {"variant": variant, "rows": rows}


def _row(draw, lower, upper, profile_runs, covered=True, verdict="named"):
    return {"setup": "s", "draw": draw, "verdict": verdict, "lower": lower, "upper": upper, "covered": covered,
            "runs_by_stage": {"refits": {"coarse": 10, "fine": 0}, "profile_likelihood": {"coarse": profile_runs, "fine": 2}}}


def test_cost_comparison_pairs_draws_and_books_runs_by_stage(tmp_path):
    import json

    from sweep.discrepancy.cost import compare_studies, main, markdown

    ref = _study("off", [_row(0, 1.0, 3.0, 100), _row(1, 2.0, 4.0, 80), _row(2, 0.0, 1.0, 50)])
    cand = _study("on", [_row(0, 1.2, 3.0, 10), _row(1, 2.0, 3.9, 20, covered=False), _row(3, 0.0, 1.0, 5)])
    c = compare_studies(ref, cand)
    assert c["draws"] == 2 and c["both_named"] == 2 and c["verdicts_differ"] == []
    assert c["stages"]["reference"]["profile_likelihood"] == (90.0, 2.0)
    assert c["stages"]["candidate"]["profile_likelihood"] == (15.0, 2.0)
    assert c["total_runs"] == {"reference": 102.0, "candidate": 27.0}
    assert c["end_difference_over_width"]["lower"]["max"] == pytest.approx(0.1)
    assert c["end_difference_over_width"]["upper"]["max"] == pytest.approx(0.05)
    assert c["coverage"] == {"reference": 2, "candidate": 1}
    assert "| profile_likelihood | 90.0 + 2.0 | 15.0 + 2.0 |" in markdown(c)
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(ref))
    b.write_text(json.dumps(_study("on", [_row(7, 0.0, 1.0, 1)])))
    assert main([str(a), str(b)]) == 2                 # no shared draw: refused, exit code 2
    b.write_text(json.dumps(cand))
    assert main([str(a), str(b), "--out", str(tmp_path / "t.md")]) == 0
    assert (tmp_path / "t.md").read_text() == markdown(c)


def test_only_multi_start_refits_go_to_the_emulator():
    """``WorkflowRun.refit`` sends a refit with several starts to the emulated refits and a single-start one
    (a refresh pass, the jitter refit) to real least squares, whatever the stage asking."""
    from sweep.discrepancy.workflow import WorkflowRun

    calls = []

    class _Problem:
        def fit(self, params, starts, ids):
            calls.append(("real", len(starts), tuple(ids)))
            return "real"

    class _Emulated:
        def fit(self, params, starts, ref, stage):
            calls.append(("emulated", len(starts), stage))
            return "emulated"

    run = WorkflowRun.__new__(WorkflowRun)
    run.problem, run.emulated, run.train = _Problem(), _Emulated(), ["a", "b"]
    assert run.refit((), [np.zeros(2)], None, "discretization_refresh") == "real"
    assert run.refit((), [np.zeros(2), np.ones(2)], None, "refits") == "emulated"
    run.emulated = None
    assert run.refit((), [np.zeros(2), np.ones(2)], None, "refits") == "real"
    assert calls == [("real", 1, ("a", "b")), ("emulated", 2, "refits"), ("real", 2, ("a", "b"))]


def test_an_emulated_refit_never_ends_above_the_model_it_nests(tmp_path, monkeypatch):
    """The guard of EmulatedRefits: when the emulated, polished optimum's χ² exceeds that of the nested
    model (the baseline's values with the strength off), the refit is redone on real runs from both points,
    ends no higher than the nested model, and the record says so.  The emulated refit is made to stop far off
    (one real evaluation at a wrong strength) to stand for an emulator led astray."""
    import sweep.discrepancy.emulated as emulated
    from sweep.discrepancy.emulated import EmulatedRefits
    from sweep.discrepancy.problem import Problem

    spec = _spec({"emulator": "gp", "emulate_refits": True})
    prob = Problem(_twin(tmp_path, {"beta": 0.0}), spec, ToyForward({}, h=8.0))   # nothing hidden: off is best
    train = ["a", "b", "c"]
    base = prob.fit(tuple(spec.calibrate), [np.array([spec.calibrate[0].to_x(331.0)])], train)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)

    def astray(em, starts):
        bad = prob.fit(params, [np.append(base.x, 250.0)], train, max_nfev=1)
        return bad, {"chi2_real": float(bad.r @ bad.r), "polished": bad.values()}

    monkeypatch.setattr(emulated, "emulated_fit", astray)
    refits = EmulatedRefits(prob, train)
    monkeypatch.setattr(refits, "build", lambda params, starts, ref: None)
    nested_chi2 = float(base.r @ base.r)
    f = refits.fit(params, [np.append(base.x, 30.0), np.append(base.x, 40.0)], base, "refits")
    rec = refits.records[-1]
    assert rec["chi2_real"] == pytest.approx(float(f.r @ f.r)) and float(f.r @ f.r) <= nested_chi2 * (1 + 1e-9)
    assert "above the nested model" in rec["fallback"] and f.values()["effect:damage_viscosity"] < 250.0
    # a refit already below its nested model is kept as it is
    good = prob.fit(params, [np.append(base.x, 0.0)], train)
    monkeypatch.setattr(emulated, "emulated_fit", lambda em, starts: (good, {"chi2_real": float(good.r @ good.r)}))
    f2 = refits.fit(params, [np.append(base.x, 30.0), np.append(base.x, 40.0)], base, "refits")
    assert f2 is good and "fallback" not in refits.records[-1]



class _GrowingSdEmulator:
    """An emulator stand-in with a known predictive distribution: mean a·x of one free parameter x (the
    held strength is the second parameter), covariance s(x)·I with s(x) = 0.01 + (x − 1)² growing away from
    its design at x = 1, whitened with a unit noise covariance.  The data are a·x* + m with a misfit m the
    model cannot remove (|m|² > |a|²): residuals whitened alone fall toward |a|² far from the design."""

    def __init__(self):
        from types import SimpleNamespace

        from sweep.discrepancy.noise import ScaledCovariance
        from sweep.discrepancy.options import FitOptions
        from sweep.discrepancy.spec import CalibParam

        n = 6
        self.a = np.array([1.0, 0.5, -0.5, 0.2, 0.0, 0.0])
        m = np.array([0.0, 0.0, 0.0, 0.0, 2.0, -2.0])
        self.params = (CalibParam(name="E", lower=-3.0, upper=5.0, initial=1.0, scale="linear"),
                       CalibParam(name="effect:x", lower=0.0, upper=1.0, initial=0.5, scale="linear"))
        self.mask = np.ones(n, bool)
        y = self.a * 1.2 + m
        self.problem = SimpleNamespace(y=y, data_at=lambda params, x: y, spec=SimpleNamespace(fit=FitOptions(loss="linear")))
        self._w = ScaledCovariance(np.ones(n), np.eye(n), np.eye(n))

    def s(self, x):
        return 0.01 + (x - 1.0) ** 2

    def predict(self, x):
        return self.a * float(x[0]), self.s(float(x[0]))

    def whitener(self):
        return self._w


def test_a_profile_refit_on_the_emulator_is_the_optimum_of_its_predictive_likelihood():
    """The profile's refit of the others at a held strength (fit_on_emulator) minimizes −2 ln L of the data
    under the emulator's predictive distribution, r·r + ln det(Σ + V)/det Σ (the known answer: its minimum on
    a fine grid), not the whitened residuals alone, which on this emulator fall away from its design (V grows
    there) and would send the refit to the parameter's bound."""
    from sweep.discrepancy.emulator import fit_on_emulator

    em = _GrowingSdEmulator()
    grid = np.linspace(-3.0, 5.0, 80001)
    rr = np.array([float(np.sum((em.problem.y - em.a * g) ** 2)) / (1.0 + em.s(g)) for g in grid])
    dev = rr + len(em.a) * np.log1p(em.s(grid))
    for start in (-2.5, 1.0, 4.5):
        f = fit_on_emulator(em, 1, 0.5, np.array([start]))
        assert f.x[0] == pytest.approx(grid[np.argmin(dev)], abs=1e-3)
        assert f.logdet == pytest.approx(len(em.a) * math.log1p(em.s(f.x[0])), rel=1e-9)
        assert float(f.r @ f.r) == pytest.approx(float(np.sum((em.problem.y - em.a * f.x[0]) ** 2)) / (1 + em.s(f.x[0])),
                                                 rel=1e-9)
    assert grid[np.argmin(rr)] in (grid[0], grid[-1])          # the residuals alone: the refit at a bound



def test_the_named_model_after_an_emulated_linear_profile_is_a_real_fit_under_its_own_correction(tmp_path):
    """With ``[profile] correction = "linear"`` the profile measures every Δχ² from the model at the fit's
    strength under the modelled correction c(x̂) (StrengthCorrection) with the others refitted.  The model the
    workflow then reports (residual test, held-out gap: recentre.settled_fit) is that one, from real runs, also
    when the others' refit ran on the emulator: the correction in use is the line through the anchors' real
    corrections (fine − real coarse) at x̂, the others are the real refit's at x̂ under it (the known answer:
    real least squares to convergence, to its tolerance, from the emulated refit's point) and the residuals
    are the real model's there.  The toy's mesh error grows with β, so the fit's own correction (made at
    β = 20) is not c(x̂)."""
    from sweep.discrepancy.noise import correction_at
    from sweep.discrepancy.profile import StrengthCorrection, emulator_for
    from sweep.discrepancy.recentre import settled_fit
    from sweep.discrepancy.emulator import fit_on_emulator

    prob, fine, fit, train = _mesh_dependent_toy_fit(tmp_path, {"emulator": "gp", "fine": True,
                                                                 "correction": "linear", "emulator_polish": 3},
                                                      corrected_at_beta=20.0)
    em = emulator_for(prob, fit, train)
    params, xj = fit.params, float(fit.x[2])
    xs = [xj - 3.0, xj + 3.0]
    real = [correction_at(prob, fine, {**fit.values(), "effect:damage_viscosity": x}) for x in xs]
    cm = StrengthCorrection(xs, real, params=(params[2],))
    held = fit_on_emulator(em, 2, xj, np.asarray(fit.x[:2], float))
    final = settled_fit(prob, params, 2, xj, held.x, train, cm, em)
    assert np.allclose(prob.noise.y_measured - prob.noise.y, cm.real_at(xj)) and final.x[2] == xj
    assert not np.allclose(cm.real_at(xj), correction_at(prob, fine, {**fit.values(), "effect:damage_viscosity": 20.0}))
    prob.fixed = {params[2].name: params[2].from_x(xj)}
    exact = prob.fit(params[:2], [held.x], train, max_nfev=50)
    prob.fixed = {}
    span = np.ptp(np.array([p.x_bounds for p in params[:2]]), axis=1)
    assert np.all(np.abs(final.x[:2] - exact.x) <= 1e-3 * span)
    assert np.array_equal(prob.residual_batch(params, [final.x], train)[0], final.r)


def test_an_emulated_refit_reaches_an_optimum_outside_the_baselines_box(tmp_path):
    """The toy with the outer compliance hidden (c = 0.05 mm/kPa: the early pressure over 1 + 2c) and k̄
    calibrated: the baseline, without the effect, raises k̄ by 1 + 2c to mimic it, far outside its own Wald
    box from the truth (the premise).  The candidate's refit starts also from the spec's initial k̄; its
    emulator's design box holds every start (EmulatedRefits._box), so the emulated optimum is the real joint
    optimum (the known answer: the same refit on real runs) within its stated error."""
    from sweep.discrepancy.emulated import EmulatedRefits
    from sweep.discrepancy.emulator import wald_box
    from sweep.discrepancy.problem import Problem

    data = load_measured(make_twin(tmp_path / "data", ToyForward(DATA_BASE, h=2.0), CONDS, TIMES,
                                   {"outer_compliance": 0.05, "kbar": 0.0015}, seed=1,
                                   observables=("p_inj", "front_radius_mean")))
    spec = _spec({"emulator": "gp", "emulate_refits": True}, calibrate=("kbar",))
    prob = Problem(data, spec, ToyForward({}, h=8.0))
    train = ["a", "b", "c"]
    base = prob.fit(tuple(spec.calibrate), [np.array([spec.calibrate[0].to_x(0.0015)])], train)
    cp = spec.candidate_param("compliant_boundary")
    params = tuple(spec.calibrate) + (cp,)
    starts = [np.append(base.x, cp.initial), np.array([spec.calibrate[0].to_x(0.0015), cp.initial])]
    real = prob.fit(params, starts, train)
    lo, hi = wald_box(prob, base, train)
    assert not lo[0] <= real.x[0] <= hi[0]                       # the premise: the optimum is outside
    refits = EmulatedRefits(prob, train)
    refits.fit(params, starts, base, "refits")
    rec, em = refits.records[0], refits.emulators[("kbar", "effect:compliant_boundary")]
    assert all(np.all(em.lo <= s) and np.all(s <= em.hi) for s in starts)
    x_em = np.array([p.to_x(rec["emulated"][p.name]) for p in params])
    assert np.all(np.abs(x_em - real.x) <= np.array(rec["emulated_error_x"]))

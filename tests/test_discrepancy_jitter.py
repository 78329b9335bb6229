"""The coarse model's jitter in its parameters as an error term (sweep/discrepancy/jitter.py).

Known answers: a forward model with a pseudo-random jitter of known variance in the strength gives that
variance back (to its sampling error); a smooth one gives none (to the quadratic's remainder); the covariance
with the jitter added whitens to the generalized least-squares χ²; the null-calibration mixture reduces to the
closed form when the jitter term is absent; on the toy whose injection pressure jitters with β, the profile
interval that excluded the truth contains it once the jitter is in the likelihood.
"""
import numpy as np
import pytest

from sweep.discrepancy import ToyForward, run_workflow, spec_from_dict, stats
from sweep.discrepancy.jitter import step_values
from sweep.discrepancy.noise import model_jitter_at as estimate_model_jitter
from sweep.discrepancy.realizations import RealizationCovariance, _mixture_with_jitter
from test_discrepancy_workflow import OFF, _JitteryToy, _spec_with, _twin

A = 1.5   # kPa: the sd of the pseudo-random jitter below


class _NoisyToy(ToyForward):
    """The toy plus a jitter in β of sd A kPa in p_inj: a deterministic pseudo-random draw per (β, w_i),
    independent between β values however close (a correlation length below any step).  ``white``: a draw
    per time point (τ = 0); otherwise one offset per (β, w_i) over the whole curve, as the solver's front
    jumps persist (τ = ∞)."""

    def __init__(self, *a, white=True, **kw):
        super().__init__(*a, **kw)
        self.white = white

    def predict_one(self, overrides, times):
        from solver import Parameters

        out = super().predict_one(overrides, times)
        p = Parameters.from_dict({**self.base, **overrides})
        if "p_inj" in out:
            rng = np.random.default_rng([int(round(p.damage_viscosity * 1e6)), int(round(p.w_i))])
            n = np.size(out["p_inj"])
            out["p_inj"] = out["p_inj"] + A * (rng.standard_normal(n) if self.white else rng.standard_normal() * np.ones(n))
        return out


def _problem(tmp_path, fwd, observables=("p_inj", "front_radius_mean")):
    from sweep.discrepancy.problem import Problem

    data = _twin(tmp_path, {"beta": 40.0}, observables=observables)
    spec = _spec_with({"fit": {"max_nfev": 50}}, cands=["damage_viscosity"], calibrate=("E",))
    prob = Problem(data, spec, fwd)
    params = tuple(spec.calibrate) + (spec.candidate_param("damage_viscosity"),)
    return prob, params


def test_step_values_and_their_checks():
    assert np.allclose(step_values(40.0, 5, 0.05), [36, 38, 40, 42, 44])
    assert np.allclose(step_values(10.0, 5, 0.1, lower=9.0), [9, 10, 11, 12, 13])       # shifted inside
    assert np.allclose(step_values(10.0, 5, 0.1, upper=11.0), [7, 8, 9, 10, 11])
    with pytest.raises(ValueError, match="model_jitter_steps = 6"):
        step_values(1.0, 6, 0.05)
    with pytest.raises(ValueError, match="model_jitter_rel_step = 0.7"):
        step_values(1.0, 7, 0.7)


def test_jitter_of_known_variance_is_recovered(tmp_path):
    """v = A² in p_inj to the estimate's sampling error: per point RSS/(m − 3) has m − 3 = 4 degrees of freedom;
    over the 4 × 50 independent p_inj points the mean has relative sd √(2/(4·200)) = 0.05 (bound: 4 sd).
    E moves nothing of the jitter (stepping E at fixed β leaves the draws the same): its direction gives the
    smooth toy's remainder exactly, so the max over the two directions is β's; no jitter in the front radius;
    τ = 0 within the lag-1's sampling error."""
    prob, params = _problem(tmp_path, _NoisyToy({}, h=8.0))
    vals = {"E": 331.0, "effect:damage_viscosity": 40.0}
    mj = estimate_model_jitter(prob, vals, params)
    p = prob.obs == "p_inj"
    assert np.mean(mj.variance[p]) == pytest.approx(A**2, rel=4 * np.sqrt(2 / (4 * 200)))
    smooth, _ = _problem(tmp_path / "smooth", ToyForward({}, h=8.0))
    assert mj.per_parameter_rms["E"] == pytest.approx(
        estimate_model_jitter(smooth, vals, params[:1]).per_parameter_rms["E"], rel=1e-9)
    assert np.all(mj.variance[~p] < 1e-12)
    assert mj.rho["p_inj"] < 4 / np.sqrt(4 * 200)
    assert mj.steps["effect:damage_viscosity"] == pytest.approx([34, 36, 38, 40, 42, 44, 46])
    assert mj.runs == 2 * 7 * 4            # 7 runs per condition and parameter (the toy caches nothing)
    # an effect at its off value (0) is not stepped; nothing to step gives None
    assert estimate_model_jitter(prob, {"E": 331.0, "effect:damage_viscosity": 0.0}, params[1:]) is None


def test_smooth_model_has_only_the_quadratics_remainder(tmp_path):
    """The closed-form toy is smooth in E and β: what the estimate sees is the quadratic's remainder, O(δ³) in
    the step δ (halving δ divides its RMS by 8, ±10 % for the next order), below 0.05 of the measurement σ
    (2 kPa) at δ = 0.05; p_inj is linear in β and the front radius depends on neither (rounding only)."""
    prob, params = _problem(tmp_path, ToyForward({}, h=8.0))
    vals = {"E": 331.0, "effect:damage_viscosity": 40.0}
    r1 = estimate_model_jitter(prob, vals, params, rel_step=0.05).per_parameter_rms
    r2 = estimate_model_jitter(prob, vals, params, rel_step=0.025).per_parameter_rms
    assert r1["E"]["p_inj"] / r2["E"]["p_inj"] == pytest.approx(8.0, rel=0.1)
    assert r1["E"]["p_inj"] < 0.05 * 2.0
    assert r1["effect:damage_viscosity"]["p_inj"] < 1e-9 and r1["E"]["front_radius_mean"] < 1e-9


def test_covariance_with_jitter_whitens_to_the_gls_chi2(tmp_path):
    """r·r = diffᵀ (D + C_real + C_jitter)⁻¹ diff per series, D = σ_diag²; variance() is the sum's diagonal."""
    from sweep.discrepancy.jitter import ModelJitter

    prob, _ = _problem(tmp_path, ToyForward({}, h=8.0))
    n = prob.y.size
    rng = np.random.default_rng(5)
    fines = prob.y[None, :] + rng.normal(scale=0.5, size=(4, n)).cumsum(axis=1) * 0.1
    rc = RealizationCovariance.estimate(fines, prob.layout)
    mj = ModelJitter(variance=rng.uniform(0.5, 2.0, n), tau={"p_inj": 0.05, "front_radius_mean": 0.0},
                     rho={}, per_parameter_rms={}, at={})
    prob.noise.set_discretization(np.zeros(n), fines, 0.5)     # the realization covariance rc, no correction
    prob.noise.set_jitter(mj)
    diff = rng.normal(size=n)
    mask = np.ones(n, bool)
    r = prob.standardize(diff, mask, 50.0)
    sel = np.arange(n)
    S = np.diag(prob.sig_diag**2) + prob.real_cov.dense(sel)
    assert r @ r == pytest.approx(diff @ np.linalg.solve(S, diff), rel=1e-9)
    assert np.allclose(prob.real_cov.variance(n), rc.variance(n) + mj.variance)
    with pytest.raises(ValueError, match="rows differ"):
        rc.with_jitter({0: (np.arange(3), np.eye(3))})


def test_null_mixture_with_jitter_reduces_to_the_closed_form():
    """J = 0: R^(−1/2) (I + λA)^(1/2) ξ = U diag(√((1 + λa)/(1 + a))) Uᵀ ξ (A = U diag(a) Uᵀ); λ = 1 with
    any J gives ξ back (the estimate exact)."""
    rng = np.random.default_rng(2)
    n = 12
    B = rng.normal(size=(n, n))
    A = B @ B.T / n
    Jm = np.diag(rng.uniform(0.2, 1.0, n))
    xi = rng.standard_normal((300, n))
    lam = np.full(300, 1.7)
    a, U = np.linalg.eigh(A)
    closed = ((xi @ U) * np.sqrt((1.0 + 1.7 * a) / (1.0 + a))) @ U.T
    assert np.allclose(_mixture_with_jitter(xi, lam, A, np.zeros((n, n))), closed, atol=1e-10)
    assert np.allclose(_mixture_with_jitter(xi, np.ones(300), A, Jm), xi, atol=1e-10)


def test_jitter_in_the_likelihood_brings_the_truth_back_into_the_profile_interval(tmp_path):
    """The toy whose p_inj jitters with β (amplitude 2 kPa, period 3 kPa·s): without the jitter term the
    profile interval is falsely narrow and misses β = 40 (and is flagged rough); with it, the interval
    contains 40 and is wider."""
    from sweep.discrepancy.profile import profile_interval

    out = {}
    for mode in ("none", "estimated"):
        prob, params = _problem(tmp_path / mode, _JitteryToy({}, h=2.0), observables=("p_inj",))
        train = ["a", "b", "c"]
        x0 = np.array([params[0].to_x(params[0].initial), 40.0])
        if mode == "estimated":
            prob.noise.set_jitter(estimate_model_jitter(prob, {"E": 331.0, "effect:damage_viscosity": 40.0}, params))
        fit = prob.fit(params, [x0], train)
        out[mode] = profile_interval(prob, fit, 1, train)
    lo0, hi0 = out["none"]["lower"], out["none"]["upper"]
    lo1, hi1 = out["estimated"]["lower"], out["estimated"]["upper"]
    assert not (lo0 <= 40.0 <= hi0) and out["none"]["rough"]           # the premise (test above)
    assert lo1 <= 40.0 <= hi1 and (hi1 - lo1) > 3 * (hi0 - lo0)


def test_workflow_reports_the_jitter_and_the_spec_checks_its_options(tmp_path):
    """A jitter that shifts a whole curve (as the solver's front jumps do): estimated at the baseline (E only:
    β is off there, and stepping E leaves the draws alone, so only the smooth remainder) and again at the named
    fit (β too).  Without the term the profile is rough and its interval a sliver set by one lucky draw; with
    it the profile is no longer flagged and the interval is many times wider."""
    data = _twin(tmp_path, {"beta": 40.0}, observables=("p_inj", "front_radius_mean"))
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "candidates": {"effects": ["damage_viscosity", "compliant_boundary"]}, "holdout": {"ids": ["d"]},
         "options": {"h": 8.0, "t_end": 1.0}}
    reps = {mode: run_workflow(data, spec_from_dict({**d, "noise": {"model_jitter": mode}}),
                               _NoisyToy({}, h=8.0, white=False), figures=False) for mode in ("none", "estimated")}
    for rep in reps.values():
        assert rep["verdict"] == "named" and rep["named_effect"] == "damage_viscosity"
    w = {m: r["strength_interval"][1] - r["strength_interval"][0] for m, r in reps.items()}
    assert reps["none"]["strength_interval_rough"] and not reps["estimated"]["strength_interval_rough"]
    assert w["estimated"] > 5 * w["none"]
    assert reps["none"]["model_jitter"] is None
    mj = reps["estimated"]["model_jitter"]
    assert mj["baseline"]["steps"].keys() == {"E"}                          # β off at the baseline
    assert mj["named"]["steps"].keys() == {"E", "effect:damage_viscosity"}
    # one offset per series: 4 series × 4 dof, the estimate's relative sd ~ 1/√8 on v (bound: 3 sd on √v)
    assert mj["named"]["rms"]["p_inj"] == pytest.approx(A, rel=3 * 0.5 / np.sqrt(8))
    assert mj["named"]["lag1"]["p_inj"] > 0.9                               # a curve, not points
    assert reps["estimated"]["forward_runs_by_stage"]["model_jitter"]["coarse"] > 0
    for key, bad, msg in [("model_jitter", "yes", '"none" or "estimated"'), ("model_jitter_steps", 6, "odd integer"),
                          ("model_jitter_rel_step", 0.0, r"\(0, 0.5\)")]:
        with pytest.raises(ValueError, match=msg):
            spec_from_dict({**d, "noise": {key: bad}})


# ----------------------------------------------------------------------------- smoothed (MCAP) profile
def test_quadratic_profile_of_an_exact_parabola_is_the_raw_interval():
    """Noise-free points of Δχ² = s (v − v0)²/σ² (s the misfit scale): centre v0, no Monte-Carlo term,
    bounds v0 ± σ √level — the raw profile's exact crossings."""
    v0, sd, scale = 2.5, 0.4, 1.7
    v = np.array([1.2, 1.9, 2.2, 2.5, 2.9, 3.1, 3.6])
    q = stats.quadratic_profile_interval(v, scale * (v - v0) ** 2 / sd**2, 3.841 * scale)
    assert q["center"] == pytest.approx(v0, abs=1e-12) and q["se_mc"] == pytest.approx(0.0, abs=1e-9)
    assert q["lower"] == pytest.approx(v0 - sd * np.sqrt(3.841)) and q["upper"] == pytest.approx(v0 + sd * np.sqrt(3.841))
    # a concave run of points has no minimum: the smoothed profile excludes none of them
    flat = stats.quadratic_profile_interval(v, 5.0 - (v - v0) ** 2, 3.841)
    assert flat["unbounded"] and (flat["lower"], flat["upper"]) == (v.min(), v.max())
    assert stats.quadratic_profile_interval(v[:4], (v[:4] - v0) ** 2, 3.841) is None     # too few points


def test_quadratic_profile_covers_the_smooth_minimum_that_raw_crossings_miss():
    """Profile points with independent jitter (sd 3 in Δχ², as measured around the solver's named fits) about a
    parabola of curvature 1/σ², measured from the luckiest point as the workflow does: over 400 replications
    the smoothed interval covers the smooth minimum v0 at least at its nominal 95 % (binomial: 3 sd below)
    without being inflated (median width within 25 % of the noise-free 2·1.96 σ; measured 1.0 and 4.06 against
    3.92), while the raw crossings, set by whichever point was luckiest, fall below nominal (measured 0.89)."""
    rng = np.random.default_rng(11)
    v0, sd, thr = 0.0, 1.0, 3.841
    v = np.linspace(-3.0, 3.0, 9)
    cover_q = cover_raw = 0
    widths = []
    n = 400
    for _ in range(n):
        d = (v - v0) ** 2 / sd**2 + rng.normal(scale=3.0, size=v.size)
        d = d - d.min()
        q = stats.quadratic_profile_interval(v, d, thr, cap=np.inf)
        cover_q += bool(q["lower"] <= v0 <= q["upper"])
        widths.append(q["upper"] - q["lower"])
        i = int(np.argmin(d))               # raw: the crossings either side of the lucky point (linear in √Δχ²)
        lo = next((v[k] for k in range(i, -1, -1) if d[k] >= thr), v[0])
        hi = next((v[k] for k in range(i, v.size) if d[k] >= thr), v[-1])
        cover_raw += bool(lo <= v0 <= hi)
    p = 0.95
    floor = p - 3 * np.sqrt(p * (1 - p) / n)
    assert cover_q / n >= floor and np.median(widths) <= 1.25 * 2 * 1.96 * sd
    assert cover_raw / n < floor


def test_smoothed_profile_in_the_workflow(tmp_path):
    """With profile_smoothing = "quadratic" the profile gets ``profile_grid`` more points per side (out to twice
    the raw bound's distance), the reported interval is the MCAP quadratic through the points (clipped to the
    strength's bounds), the raw crossings are kept, and report.md says so.  (Coverage is the unit test's above:
    one noisy realization is not evidence.)"""
    from sweep.discrepancy.spec import spec_from_dict as sfd

    data = _twin(tmp_path, {"beta": 40.0}, observables=("p_inj", "front_radius_mean"))
    d = {"baseline": {"effects_off": OFF}, "calibrate": [{"name": "E", "lower": 150.0, "upper": 700.0}],
         "candidates": {"effects": ["damage_viscosity", "compliant_boundary"]}, "holdout": {"ids": ["d"]},
         "options": {"h": 8.0, "t_end": 1.0},
         "noise": {"model_jitter": "estimated"}, "profile": {"smoothing": "quadratic", "grid": 3}}
    rep = run_workflow(data, sfd(d), _NoisyToy({}, h=8.0, white=False), out_dir=tmp_path / "out", figures=False)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "Smoothed profile (quadratic" in md and "Coarse model's jitter in its parameters (named" in md
    pr = rep["profiles"]["damage_viscosity"]
    fit = rep["strength"]
    lo_raw, hi_raw = pr["raw"]
    for side, b in ((-1, lo_raw), (1, hi_raw)):
        for k in (1, 2, 3):
            target = fit + side * 2 * abs(b - fit) * k / 3
            assert min(abs(q["value"] - target) for q in pr["points"]) < 1e-6 * max(1.0, abs(target))
    q = stats.quadratic_profile_interval([r["value"] for r in pr["points"]], [r["delta_chi2"] for r in pr["points"]],
                                         pr["threshold"], cap=6.0)
    assert q is not None and not q["unbounded"] and q["se_mc"] > 0
    lo, hi = rep["strength_interval"]
    assert (lo, hi) == (pr["lower"], pr["upper"]) == (pytest.approx(max(q["lower"], 0.0)), pytest.approx(q["upper"]))
    assert rep["accepted"][0]["strength_interval_raw"] == pr["raw"]
    for key, bad in (("smoothing", "loess"), ("grid", 1)):
        with pytest.raises(ValueError, match=f"profile.{key}"):
            sfd({**d, "profile": {key: bad}})


def test_passing_candidates_are_compared_under_common_weights():
    """Two refits with the same χ² whose residuals differ only in autocorrelation: under each one's own series
    weights (n_eff/n from the lag-1) their BICs differ by tens, a "margin" made by the weighting alone; under
    the common (per-series minimum) weights they are equal to rounding, so the tie rule sees a tie."""
    from types import SimpleNamespace

    from sweep.discrepancy.evidence import compare_passing

    rng = np.random.default_rng(4)
    n = 60
    white = rng.standard_normal(n)
    smooth = np.sort(white)                                  # the same values, strongly autocorrelated
    series = np.zeros(n, int)
    prob = SimpleNamespace(series=series, mask=lambda ids: np.ones(n, bool))
    mk = lambda r: {"fit": SimpleNamespace(r=r, params=(1, 2)), "effect": "x"}
    a, b = mk(white), mk(smooth)
    own = {k: stats.bic(p["fit"].r, stats.series_weights(p["fit"].r, series), 2) for k, p in (("a", a), ("b", b))}
    assert abs(own["a"] - own["b"]) > 10                     # the premise: weighting alone makes a margin
    ranked = compare_passing([a, b], prob, ["t"])
    assert abs(a["bic_common"] - b["bic_common"]) < 1e-9
    assert len(ranked) == 2 and compare_passing([], prob, ["t"]) == []


def test_recentring_ignores_a_dip_within_the_profiles_scatter():
    """A smoothed profile whose lowest point lies below the fit by less than twice the points' scatter about
    the quadratic is noise: no re-centring.  The same dip without smoothing, or a dip deeper than the scatter,
    re-centres."""
    from sweep.discrepancy.recentre import recentre_target

    v = np.linspace(0.6, 1.1, 11)
    d = 40.0 * (v - 0.85) ** 2 + np.array([0.0, 0.5, -0.5, 0.5, -0.5, 0.5, -0.5, 0.5, -0.5, 0.5, 0.0])
    pts = [{"value": float(a), "delta_chi2": float(b)} for a, b in zip(v, d)]
    pts.append({"value": 0.86, "delta_chi2": 0.0})                  # the fit
    q = stats.quadratic_profile_interval(v, d, 4.0)
    assert 0.3 < q["residual_sd"] < 0.6                              # the premise: scatter about 0.5 in Δχ²
    pts[5]["delta_chi2"] = -0.6                                      # a dip of ~1.2 sd
    raw = {"points": pts, "threshold": 4.0}
    assert recentre_target(raw) is pts[5]                            # no smoothing: re-centre on it
    assert recentre_target({**raw, "quadratic": q}) is None          # smoothed: within 2 × the scatter
    pts[5]["delta_chi2"] = -3.0 * q["residual_sd"]                   # a dip beyond the scatter
    assert recentre_target({**raw, "quadratic": q}) is pts[5]
    tiny = [{"value": 1.0, "delta_chi2": 0.0}, {"value": 1.1, "delta_chi2": -0.001}, {"value": 0.9, "delta_chi2": 2.0}]
    assert recentre_target({"points": tiny, "threshold": 4.0}) is None   # below the fit by < tol × threshold


def test_on_the_emulator_a_profile_points_correction_makes_its_model_the_fine_model_there(tmp_path):
    """With fine models and the emulator, the profile compares the data at a point with the emulator's mean
    plus the correction re-estimated there.  The correction is taken against that mean (fine − mean), so the
    two together are the fine model at the point, whatever the emulator's error; the real run's correction
    (fine − run) would leave the run's jitter about the emulator's smooth part in the residuals (here the
    coarse toy's white p_inj jitter of sd A kPa, which the emulator's nugget smooths)."""
    from sweep.discrepancy.noise import correction_at
    from sweep.discrepancy.problem import Problem
    from sweep.discrepancy.profile import _Profile, emulator_for

    prob, params = _problem(tmp_path, _NoisyToy({}, h=8.0))
    fine = ToyForward({}, h=2.0)
    train = ["a", "b", "c"]
    fit = prob.fit(params, [np.array([params[0].to_x(params[0].initial), 30.0])], train)
    em = emulator_for(prob, fit, train)
    pf = _Profile(prob, fit, 1, train, 3.841, fine, em)
    x = np.array(fit.x, float)
    x[1] = params[1].to_x(1.03 * params[1].from_x(fit.x[1]))
    corr = correction_at(prob, fine, {q.name: q.from_x(v) for q, v in zip(params, x)})
    on_fine = Problem(prob.data, prob.spec, fine)
    fine_vec = on_fine.model_vector(on_fine.prediction(params, x, train), em.mask)
    mean = em.predict(x)[0]
    ok = np.isfinite(fine_vec)
    assert ok.sum() > 10
    assert np.allclose((pf.model_correction(corr, x)[em.mask] + mean)[ok], fine_vec[ok], rtol=0, atol=1e-9)
    off = (corr[em.mask] + mean - fine_vec)[ok]          # the run's own correction: the jitter stays
    assert np.sqrt(np.mean(off ** 2)) > 0.3 * A

"""Probabilistic boundaries (sweep.regimes.probability): Wilson intervals, replicate grouping, the separatrix band
against the profile intervals it generalizes, its significance test, and the diagram's refusal to draw an
insignificant separatrix."""
import math

import numpy as np
import pandas as pd
import pytest

from sweep.regimes.separatrix import separatrix_profile_interval
from sweep.regimes.probability import (plot_probability_diagram, replicate_points, separatrix_band,
                                       separatrix_significance, wilson_interval)

A_TRUE, B_TRUE, S_TRUE = 1e7, 1.5, 2.0  # Ca*_c = A exp(B C); sharpness per unit of ln Ca*


def draw(seed, n=200, s=S_TRUE):
    rng = np.random.default_rng(seed)
    C = rng.uniform(0.0, 3.0, n)
    L = rng.uniform(math.log(1e6), math.log(1e10), n)
    y = rng.random(n) < 1 / (1 + np.exp(-s * (L - math.log(A_TRUE) - B_TRUE * C)))
    return C, np.exp(L), y


def test_wilson_interval_known_values():
    z2 = 1.959963984540054 ** 2
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(z2 / (10 + z2), rel=1e-9)       # k = 0: (0, z^2/(n + z^2))
    lo, hi = wilson_interval([5, 3], [10, 3])
    assert lo[0] == pytest.approx(1 - hi[0], rel=1e-12)                          # symmetric about 1/2
    assert (lo[0], hi[0]) == pytest.approx((0.236593, 0.763407), abs=1e-6)      # textbook value
    assert hi[1] == 1.0 and lo[1] == pytest.approx(3 / (3 + z2), rel=1e-9)
    lo, hi = wilson_interval(0, 0)
    assert (float(lo), float(hi)) == (0.0, 1.0)
    with pytest.raises(ValueError, match="k="):
        wilson_interval(4, 3)


def test_replicate_points_groups_runs():
    x = [1.0, 1.0, 1.0, 2.0, 2.0, 1.0000000000001]
    y = [5.0, 5.0, 5.0, 5.0, 5.0, 5.0]
    pts = replicate_points(x, y, [True, False, True, False, False, True])
    assert list(pts["n"]) == [4, 2] and list(pts["k"]) == [3, 0]
    assert list(pts["mixed"]) == [True, False] and pts["p"][0] == 0.75


def test_pointwise_band_at_zero_is_the_profile_interval_of_A():
    """At C = 0 the line is ln A: the pointwise band there is separatrix_profile_interval's interval of A."""
    C, cs, y = draw(1)
    band = separatrix_band(C, cs, y, simultaneous=False, at=[0.0, 1.5])
    ref = separatrix_profile_interval(C, cs, y)
    assert band.A == pytest.approx(ref.A, rel=1e-5) and band.B == pytest.approx(ref.B, rel=1e-5)
    assert np.exp(band.lo[0]) == pytest.approx(ref.A_interval[0], rel=0.02)
    assert np.exp(band.hi[0]) == pytest.approx(ref.A_interval[1], rel=0.02)
    wide = separatrix_band(C, cs, y, simultaneous=True, at=[0.0, 1.5])
    assert np.all(wide.lo < band.lo) and np.all(wide.hi > band.hi)    # chi2_2 > chi2_1


@pytest.mark.slow
def test_simultaneous_band_covers_the_true_line():
    """20 draws: the whole true line inside the simultaneous 95 % band in >= 17 (a 95 % method fails this with
    probability 0.016)."""
    at = np.linspace(0.0, 3.0, 5)
    truth = math.log(A_TRUE) + B_TRUE * at
    hits = sum(separatrix_band(*draw(seed, n=120), at=at).covers(truth) for seed in range(20))
    assert hits >= 17


def test_significance_detects_order_and_its_absence():
    C, cs, y = draw(2)
    lr, p = separatrix_significance(C, cs, y)
    assert p < 1e-6 and lr > 30
    rng = np.random.default_rng(5)
    y0 = rng.random(C.size) < 0.5           # labels independent of the plane (this draw: p = 0.66)
    lr0, p0 = separatrix_significance(C, cs, y0)
    assert p0 > 0.2
    assert separatrix_significance(C, cs, np.ones(C.size, bool)) == (0.0, 1.0)


def test_diagram_draws_only_a_significant_separatrix(tmp_path):
    C, cs, _ = draw(3, n=20)
    C, cs = np.repeat(C, 3), np.repeat(cs, 3)
    p = 1 / (1 + np.exp(-S_TRUE * (np.log(cs) - math.log(A_TRUE) - B_TRUE * C)))
    reps = pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": np.random.default_rng(3).random(60) < p})
    out = plot_probability_diagram(reps, tmp_path / "sig", formats=())
    assert out["band"] is not None and out["band"].significant and out["no_fit_reason"] is None
    assert out["points"]["n"].tolist() == [3] * 20
    assert out["paths"][0].exists()
    rng = np.random.default_rng(5)
    noise = reps.assign(fracturing=rng.random(len(reps)) < 0.5)
    out = plot_probability_diagram(noise, tmp_path / "noise", formats=(), smooth=False)
    assert out["band"] is None and "not significant" in out["no_fit_reason"]


# the first 38 runs of results/ca_star_band_h2 (C %, Ca*, fracturing): a significant separatrix whose
# simultaneous band is open at both ends (ln Ca* beyond exp's range)
BAND_C = [1.77962, 2.09153, 1.20656, 2.42641, 1.55996, 2.72298, 2.68261, 0.509329, 0.98046, 0.536988, 2.99239,
          2.09153, 2.99007, 0.536988, 0.50711, 0.50711, 0.526332, 0.50711, 2.99816, 2.99007, 2.99552, 0.50711, 0.5181,
          0.536988, 2.99787, 0.645567, 0.508804, 0.508804, 2.99512, 2.99813, 1.20656, 1.77962, 2.99706, 1.77962,
          1.77962, 0.508804, 0.509329, 2.99787]
BAND_CA = [1.37126e+08, 8.63422e+07, 6.84559e+07, 1.45726e+07, 5.15259e+08, 3.54342e+07, 1.04495e+09, 2.88338e+07,
           3.20179e+08, 2.17443e+07, 4.49852e+07, 8.63422e+07, 4.98165e+08, 2.17443e+07, 1.30132e+07, 1.30132e+07,
           7.79425e+07, 1.30132e+07, 2.95502e+07, 4.98165e+08, 7.54111e+07, 1.30132e+07, 4.0776e+07, 2.17443e+07,
           2.21916e+08, 5.88921e+07, 5.73315e+07, 5.73315e+07, 1.06322e+08, 8.04283e+08, 6.84559e+07, 1.37126e+08,
           1.44655e+08, 1.37126e+08, 1.37126e+08, 5.73315e+07, 2.88338e+07, 2.21916e+08]
BAND_Y = [0, 0, 1, 0, 1, 0, 1, 0, 1, 1, 0, 0, 1, 0, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 1, 1, 1, 1, 0, 1, 0, 0, 1, 1, 0, 1,
          1, 0]


def test_diagram_clips_a_band_open_beyond_the_plot(tmp_path):
    """A significant separatrix on few runs can have a band whose ends reach ln Ca* of hundreds (exp overflows):
    the diagram clips the band to the plotted range and says so in its legend, instead of failing on infinite
    axis limits under the smooth classifier's shading (as this campaign's report did)."""
    df = pd.DataFrame({"cement": BAND_C, "Ca_star": BAND_CA, "fracturing": np.array(BAND_Y, bool)})
    out = plot_probability_diagram(df, tmp_path / "open", formats=())
    band = out["band"]
    assert band is not None and band.significant and np.max(band.hi) > 709.0 and np.min(band.lo) < -745.0
    assert out["paths"][0].exists()


def test_nf_vs_nb_probabilities_groups_replicates(tmp_path):
    from sweep.regimes.probability import plot_nf_vs_nb_probabilities

    df = pd.DataFrame({"N_b": [0.1] * 3 + [10.0] * 3 + [5.0], "N_f": [2.0] * 3 + [0.5] * 3 + [-1.0],
                       "regime": ["invasive_fracturing", "invasive_fracturing", "viscous_fingering"]
                       + ["uniform_invasion"] * 3 + ["uniform_invasion"]})
    out = plot_nf_vs_nb_probabilities(df, tmp_path / "nfnb", dp_cri=1e4, formats=())
    pts = out["points"].set_index("N_b")
    assert out["n_dropped"] == 1 and out["paths"][0].exists()
    assert pts.loc[0.1, "top"] == "invasive_fracturing" and pts.loc[0.1, "p_top"] == pytest.approx(2 / 3)
    assert bool(pts.loc[0.1, "mixed"]) and not bool(pts.loc[10.0, "mixed"]) and pts.loc[10.0, "n"] == 3


def test_the_separatrix_summary_states_the_fit_its_intervals_and_the_band_or_why_there_is_none():
    """separatrix_summary (what a campaign report states): on labels from a known increasing boundary the
    separatrix is significant, B > 0 at 95 %, the intervals hold the truth (one seeded draw of 200 runs) and are
    the profile fit's own; labels independent of the axes, or one regime only, give no separatrix with the reason."""
    from sweep.regimes.probability import separatrix_summary

    C, cs, y = draw(0)
    s = separatrix_summary(C, cs, y)
    iv = separatrix_profile_interval(C, cs, y)
    assert s["significant"] and s["reason"] is None and s["B_positive"]
    assert (s["A"], s["B"], tuple(s["B_interval"])) == (iv.A, iv.B, iv.B_interval)
    assert s["B_interval"][0] <= B_TRUE <= s["B_interval"][1] and s["A_interval"][0] <= A_TRUE <= s["A_interval"][1]
    band = separatrix_band(C, cs, y, at=[C.min(), C.max()])
    assert s["band_half_width_decades"] == pytest.approx(list(band.half_width_decades))
    rng = np.random.default_rng(3)
    flat = separatrix_summary(C, cs, rng.random(C.size) < 0.5)
    assert not flat["significant"] and "not significant" in flat["reason"] and flat["p_value"] >= 0.05
    assert "both regimes" in separatrix_summary(C, cs, np.ones(C.size, bool))["reason"]


def test_a_campaign_report_with_a_ca_star_diagram_states_the_separatrix():
    from types import SimpleNamespace

    from sweep.campaign.report import _separatrix_lines

    C, cs, y = draw(0)
    table = pd.DataFrame({"status": "ok", "cement": C, "Ca_star": cs, "fracturing": y})
    text = "\n".join(_separatrix_lines(SimpleNamespace(diagrams=[{"kind": "ca_star_vs_cement"}]), table))
    assert "## The separatrix" in text and "200 finished runs" in text and "B > 0 at 95 %" in text
    assert "simultaneous 95 % band of Ca*_c: [10^" in text and "decades) at C" in text
    assert _separatrix_lines(SimpleNamespace(diagrams=[{"kind": "nf_vs_nb"}]), table) == []


def test_a_band_the_labels_do_not_bound_is_unbounded_never_the_searchs_reach():
    """Few, weakly ordered labels (20 runs, sharpness 0.7, seed 2): the separatrix is significant, but at the ends
    of C the profile never reaches its threshold on one side.  That side is unbounded: the half-width is inf, the
    summary's edge is infinite, any line beyond it is covered; the finite lo/hi there are only the search's reach
    (reach_half_width_decades, for a sampler's ranking)."""
    from sweep.regimes.probability import separatrix_summary

    C, cs, y = draw(2, n=20, s=0.7)
    band = separatrix_band(C, cs, y, at=[C.min(), C.max()])
    assert band.significant and not band.bounded.all()
    assert np.all(np.isinf(band.half_width_decades[~band.bounded]))
    assert np.all(np.isfinite(band.reach_half_width_decades))
    far = np.where(band.lo_bounded, band.center, band.lo - 50.0)       # 50 e-folds below the reach where unbounded
    assert band.covers(far)
    s = separatrix_summary(C, cs, y)
    assert any(math.isinf(h) for h in s["band_half_width_decades"])
    assert all((lo == -math.inf) == (not lb) for (lo, _), lb in zip(s["band_log10"], band.lo_bounded))


def test_a_replicated_campaigns_report_counts_its_points_replicates_and_disagreements():
    from types import SimpleNamespace

    from sweep.campaign.report import _replicate_lines

    rows = [(1.0, 0.1, "invasive_fracturing", True), (1.0, 0.1, "viscous_fingering", False),
            (1.0, 0.1, "invasive_fracturing", True), (2.0, 0.3, "viscous_fingering", False),
            (3.0, 1.0, "fracturing_fingering", True), (3.0, 1.0, "invasive_fracturing", True)]
    table = pd.DataFrame([{"status": "ok", "cement": c, "eta_o": e, "regime": r, "fracturing": f} for c, e, r, f in rows])
    spec = SimpleNamespace(replicates={"porosity_seed": 3}, axis_names=("cement", "eta_o"), diagrams=[])
    text = "\n".join(_replicate_lines(spec, table))
    assert "3 points (1 with 1 run, 1 with 2 runs, 1 with 3 runs;" in text
    # regimes differ at both replicated points; the fracturing label only at the first
    assert "regimes disagree at 2 of the 2 points with two or more; their fracturing labels at 1." in text
    assert "67 % of the 6 finished runs with a label fracture." in text
    assert _replicate_lines(SimpleNamespace(replicates={}, axis_names=("cement", "eta_o"), diagrams=[]), table) == []


def test_a_band_edge_the_labels_do_not_bound_is_named_open_on_its_sides():
    from sweep.campaign.report import _band_text

    inf = float("inf")
    assert _band_text([6.5, 7.5], 0.5) == "[10^6.5, 10^7.5] (±0.5 decades)"
    assert _band_text([-inf, 7.24], inf) == "[0, 10^7.24] (unbounded on one side)"
    assert _band_text([6.0, inf], inf) == "[10^6, ∞] (unbounded on one side)"
    assert _band_text([-inf, inf], inf) == "[0, ∞] (unbounded on both sides)"


def test_distinct_points_at_the_same_nf_nb_are_not_pooled_as_replicates(tmp_path, monkeypatch):
    """N_f ~ eta_o / kbar and N_b ~ eta_w / (eta_o kbar): on decade grids of eta_o, eta_w and kbar (the campaign
    nf_vs_nb_probabilities_h2) distinct points share (N_b, N_f) (there: 20 of its 80 points).  Their runs are not
    replicates of one point: grouped by the campaign's axes, each point keeps its own n and its own regimes."""
    from types import SimpleNamespace

    from sweep.campaign.plot import _phase_diagram
    from sweep.regimes import probability as pr

    rows = [(1e-3, 1e-6, 1e-3, "invasive_fracturing")] * 3 + [(1e-2, 1e-4, 1e-2, "uniform_invasion")] * 3
    df = pd.DataFrame([{"status": "ok", "eta_o": eo, "eta_w": ew, "kbar": kb, "regime": r, "N_b": 7.5, "N_f": 2.0,
                        "dp_cri": 1e3} for eo, ew, kb, r in rows])
    spec = SimpleNamespace(name="t", replicates={"porosity_seed": 3}, axis_names=("eta_o", "eta_w", "kbar"))
    seen, real = {}, pr.plot_nf_vs_nb_probabilities
    monkeypatch.setattr(pr, "plot_nf_vs_nb_probabilities", lambda *a, **kw: seen.setdefault("out", real(*a, **kw)))
    _phase_diagram(spec, df, {"kind": "nf_vs_nb", "formats": []}, tmp_path / "nfnb.png")
    pts = seen["out"]["points"]
    assert sorted(pts["n"]) == [3, 3] and not pts["mixed"].any()
    assert sorted(pts["top"]) == ["invasive_fracturing", "uniform_invasion"]


def test_distinct_points_at_the_same_ca_star_and_cement_are_not_pooled(tmp_path):
    """Ca* ~ eta_o w_i: a campaign over eta_o and w_i at one C has distinct points at one (C, Ca*); with ``by`` (the
    campaign's axes) each keeps its own replicates."""
    rows = [(1.0, 0.1, 20.0, True)] * 3 + [(1.0, 0.2, 10.0, False)] * 3 + [(2.0, 0.1, 10.0, False)] * 2
    df = pd.DataFrame([{"cement": c, "eta_o": e, "w_i": w, "Ca_star": 1e7 * e * w, "fracturing": f}
                       for c, e, w, f in rows])
    out = plot_probability_diagram(df, tmp_path / "p", formats=(), smooth=False, by=["cement", "eta_o", "w_i"])
    assert sorted(out["points"]["n"].tolist()) == [2, 3, 3] and not out["points"]["mixed"].any()


@pytest.mark.parametrize("missing", [None, math.nan])
def test_a_finished_run_without_a_label_is_neither_a_replicate_nor_fracturing(missing):
    """A run whose solver finished but whose classification failed (status ok, no regime, no fracturing: the
    campaign runner keeps it to reclassify later) carries no label: the report's share of fracturing runs and its
    replicate counts leave it out (it was counted as fracturing: NaN is truthy), as do points.csv's n_ok and p_*."""
    from types import SimpleNamespace

    from sweep.campaign.replicates import point_table
    from sweep.campaign.report import _replicate_lines

    table = pd.DataFrame({"status": ["ok", "ok", "ok", "ok"], "cement": [1.0, 1.0, 1.0, 2.0], "eta_o": 0.1,
                          "regime": ["invasive_fracturing", "uniform_invasion", None, "uniform_invasion"],
                          "fracturing": [True, False, missing, False]})
    spec = SimpleNamespace(replicates={"porosity_seed": 3}, axis_names=("cement", "eta_o"), diagrams=[])
    text = "\n".join(_replicate_lines(spec, table))
    assert "33 % of the 3 finished runs with a label fracture" in text           # 1 of the 3 labelled runs
    assert "2 points (1 with 1 run, 1 with 2 runs;" in text
    p = point_table(table, ["cement", "eta_o"]).set_index("cement")
    assert p.loc[1.0, "n_ok"] == 2 and p.loc[1.0, "p_fracturing"] == 0.5 and p.loc[1.0, "n_runs"] == 3


def test_a_band_side_the_labels_do_not_bound_is_drawn_to_the_plots_edge(tmp_path, monkeypatch):
    """Where the labels do not bound the band, its lo / hi hold only the profile search's reach, which can lie
    inside the plotted range: the figure draws such a side to the plot's edge (it drew a finite edge there)."""
    from sweep.regimes import diagrams
    from sweep.regimes import probability as pr

    C, cs, _ = draw(3, n=20)
    fr = np.log(cs) > math.log(A_TRUE) + B_TRUE * C
    real = pr.separatrix_band

    def reach_inside(*a, **kw):        # the true band, its lower side made unbounded with a reach inside the plot
        b = real(*a, **kw)
        return b._replace(lo=b.center - 0.5, lo_bounded=np.zeros(b.C.size, bool))

    figs = {}
    monkeypatch.setattr(pr, "separatrix_band", reach_inside)
    monkeypatch.setattr(diagrams, "_save", lambda fig, path, formats: figs.setdefault("fig", fig) and [])
    pr.plot_probability_diagram(pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": fr}), tmp_path / "d",
                                smooth=False, formats=())
    ax = figs["fig"].axes[0]
    band = next(c for c in ax.collections if c.get_label().startswith("95% band"))
    assert band.get_paths()[0].vertices[:, 1].min() == pytest.approx(ax.get_ylim()[0], rel=1e-9)
    assert "beyond the plot" in band.get_label()


@pytest.mark.parametrize("which", ["C", "Ca_star"])
def test_a_design_that_cannot_locate_the_line_gives_no_separatrix_and_no_fake_significance(which):
    """Every run at one C (an N_f-N_b campaign at C = 1.2 %) or at one Ca* (results/nucleation_length_h2): the
    design cannot identify A exp(B C), yet the penalized likelihood ratio came out infinite (p = 0: 'significant')
    and the band failed inside its root search.  Now a clear reason, no p-value."""
    from sweep.regimes.probability import separatrix_summary

    C, cs, y = draw(4, n=40)
    C = np.full_like(C, 1.2) if which == "C" else C
    cs = np.full_like(cs, 8.6e7) if which == "Ca_star" else cs
    with pytest.raises(ValueError, match="not identifiable"):
        separatrix_significance(C, cs, y)
    with pytest.raises(ValueError, match="not identifiable"):
        separatrix_band(C, cs, y)
    s = separatrix_summary(C, cs, y)
    assert not s["significant"] and "not identifiable" in s["reason"] and "p_value" not in s


# two Ca*-C label sets of 16 runs drawn from P = expit(ln10 (log10 Ca* - 4.5 - 0.3 C)): the separatrix test's p
# just above 0.05 (0.053; the ridge likelihood-ratio test the one-run diagram used gave 0.012) and just below (0.044)
NEAR_C = {"above": [2.02, 2.37, 2.45, 1.22, 2.23, 2.82, 1.78, 2.68, 2.57, 1.09, 2.57, 0.55, 1.04, 1.27, 0.8, 1.6],
          "below": [2.09, 1.17, 0.6, 0.54, 2.53, 2.78, 2.02, 2.32, 1.86, 2.84, 2.54, 0.51, 2.64, 0.58, 2.32, 0.94]}
NEAR_CA = {"above": [79070.0, 19880.0, 312900.0, 81950.0, 356500.0, 9260.0, 68480.0, 1190.0, 2160.0, 49060.0,
                     74020.0, 20570.0, 3730.0, 134200.0, 281800.0, 250900.0],
           "below": [388600.0, 42110.0, 7930.0, 18540.0, 1220.0, 2360.0, 102800.0, 87410.0, 70170.0, 14160.0,
                     980900.0, 876000.0, 113900.0, 89410.0, 116200.0, 14680.0]}
NEAR_Y = {"above": [0, 0, 1, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 1, 1, 1],
          "below": [1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1, 1, 1, 0, 1, 0]}


def _firth_lr_p(C, cs, y):
    """The penalized likelihood-ratio test written out independently: -log L + (-1/2) log det(X' W X) of the
    logistic model z = s ln Ca* - s B C - s ln A (X = [ln Ca*, -C, -1]), minimized by Nelder-Mead over the three
    coefficients and over a constant z; chi2 with 2 degrees of freedom."""
    from scipy.optimize import minimize
    from scipy.stats import chi2

    X = np.c_[np.log(cs), -np.asarray(C), -np.ones(len(C))]
    y = np.asarray(y, float)

    def nll(theta):
        z = X @ theta
        w = 1.0 / (2.0 + 2.0 * np.cosh(z))
        return np.sum(np.logaddexp(0.0, z) - y * z) - 0.5 * np.linalg.slogdet((X * w[:, None]).T @ X)[1]

    opts = {"xatol": 1e-10, "fatol": 1e-12, "maxiter": 40000, "maxfev": 40000}
    full = min(minimize(nll, t0, method="Nelder-Mead", options=opts).fun
               for t0 in ([1.0, 0.0, 11.0], [2.0, 1.0, 20.0], [0.5, 0.2, 5.0]))
    null = minimize(lambda c: nll(np.array([0.0, 0.0, c[0]])), [0.0], method="Nelder-Mead", options=opts).fun
    return chi2.sf(2.0 * (null - full), 2)


@pytest.mark.parametrize("case, significant", [("above", False), ("below", True)])
def test_both_ca_star_diagrams_decide_a_separatrix_by_one_test(tmp_path, case, significant):
    """The one-run Ca*-C diagram and the replicated (probability) diagram draw the separatrix by one rule,
    sweep.regimes.separatrix.separatrix_test (the penalized likelihood-ratio test at p < 0.05), here on label sets
    whose p lies on either side of 0.05 (checked against the test written out independently).  The one-run diagram
    used a ridge-penalized test (p = 0.012 on 'above') and drew a line the replicated diagram refused."""
    from sweep.regimes.diagrams import plot_ca_star_vs_cement
    from sweep.regimes.separatrix import SEPARATRIX_P_MAX, separatrix_test

    C, cs, y = np.array(NEAR_C[case]), np.array(NEAR_CA[case]), np.array(NEAR_Y[case], bool)
    test = separatrix_test(C, cs, y)
    assert test.p_value == pytest.approx(_firth_lr_p(C, cs, y), rel=1e-4)
    assert 0.03 < test.p_value < 0.06 and test.significant == significant and SEPARATRIX_P_MAX == 0.05
    df = pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": y})
    one = plot_ca_star_vs_cement(df, tmp_path / "one", formats=())
    rep = plot_probability_diagram(df, tmp_path / "rep", formats=(), smooth=False)
    assert (one["fit"] is not None) == (rep["band"] is not None) == significant
    if not significant:
        assert "not significant" in one["no_fit_reason"] and "not significant" in rep["no_fit_reason"]
        assert f"p = {test.p_value:.2g}" in one["no_fit_reason"] and f"p = {test.p_value:.2g}" in rep["no_fit_reason"]

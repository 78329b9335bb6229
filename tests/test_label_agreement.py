"""sweep.studies.label_agreement: labels of the same Ca*-C points over realizations, against hand-counted answers."""
import numpy as np
import pandas as pd
import pytest

from sweep.studies import label_agreement as la


def _runs(lengths_by_real):
    """Three points (C %, eta_o kPa s, Ca*) with the crack lengths (mm) given per realization."""
    pts = [(1.0, 0.1, 1e7), (2.0, 0.3, 1e8), (3.0, 1.0, 1e9)]
    rows = [{"mesh_seed": r, "cement": c, "eta_o": e, "Ca_star": ca, "crack_length": L}
            for r, lengths in lengths_by_real.items() for (c, e, ca), L in zip(pts, lengths)]
    return pd.DataFrame(rows)


def test_rule_one_is_strict_at_the_threshold():
    df = pd.DataFrame({"crack_length": [3.99, 4.0, 4.01]})
    assert la.fracturing(df, 4.0).tolist() == [False, False, True]


def test_agreement_counts_points_spread_and_shares():
    # point 1 agrees (both fracture), point 2 disagrees, point 3 agrees (neither): 2 of 3
    df = _runs({0: [5.0, 4.5, 1.0], 1: [6.5, 3.0, 2.0]})
    a = la.agreement(df, "mesh_seed", 4.0)
    assert a["points_with_every_realization"] == 3 and a["points_all_agree"] == 2
    assert a["share_agree"] == pytest.approx(2 / 3)
    assert a["crack_spread_mm"]["median"] == pytest.approx(1.5) and a["crack_spread_mm"]["max"] == pytest.approx(1.5)
    assert a["fracturing_share"] == {0: pytest.approx(2 / 3), 1: pytest.approx(1 / 3)}


def test_agreement_leaves_out_points_missing_a_realization():
    df = _runs({0: [5.0, 4.5, 1.0], 1: [6.5, 3.0, 2.0]}).iloc[:-1]   # point 3 lacks realization 1
    a = la.agreement(df, "mesh_seed", 4.0)
    assert a["points_with_every_realization"] == 2 and a["points_all_agree"] == 1


def test_separatrix_recovers_a_rising_boundary_and_reports_one_outcome():
    rng = np.random.default_rng(0)
    C = rng.uniform(0.5, 3.0, 400)
    ca = np.exp(rng.uniform(np.log(1e6), np.log(1e10), 400))
    B_true, A_true = 2.0, 1e6
    frac = np.log(ca) > np.log(A_true) + B_true * C      # a sharp separatrix rising with C
    df = pd.DataFrame({"cement": C, "Ca_star": ca, "crack_length": np.where(frac, 8.0, 1.0)})
    fit = la.separatrix(df, 4.0)
    assert fit["B_positive_at_95"] and fit["B_interval"][0] <= B_true <= fit["B_interval"][1]
    none = la.separatrix(df.assign(crack_length=1.0), 4.0)
    assert "error" in none and none["fracturing"] == 0


def test_judge_keys_follow_the_realization_column_and_the_scan():
    df = _runs({0: [5.0, 4.5, 1.0], 1: [6.5, 3.0, 2.0]})
    out = la.judge(df, "mesh_seed", 4.0, (3.0, 5.0))
    assert set(out) == {"agreement_at_L4", "per_mesh_seed_at_L4", "pooled_at_L4", "pooled_L_scan"}
    assert set(out["per_mesh_seed_at_L4"]) == {0, 1} and set(out["pooled_L_scan"]) == {"3.0", "5.0"}


def test_longest_crack_is_the_larger_of_the_judged_and_the_recorded_peak():
    df = pd.DataFrame({"crack_length": [5.0, 3.0, 0.0], "open_tip_radius_max": [9.0, 12.5, 4.0], "r_inner": 5.0})
    assert la.longest(df)["crack_length"].tolist() == [5.0, 7.5, 0.0]   # a peak below the cavity counts as no crack


def test_crack_summary_and_rank_correlations():
    df = pd.DataFrame({"crack_length": [1.0, 2.0, 2.004, 4.0, 5.0], "cement": [5, 4, 3, 2, 1],
                       "Ca_star": [1e7, 2e7, 3e7, 4e7, 5e7]})
    s = la.crack_summary(df)
    assert s["quantiles_0_25_50_75_100"] == [1.0, 2.0, 2.004, 4.0, 5.0] and s["distinct_values"] == [1.0, 2.0, 4.0, 5.0]
    assert la.rank_correlations(df) == {"cement": pytest.approx(-1.0), "Ca_star": pytest.approx(1.0)}


def test_an_interval_side_the_labels_do_not_bound_is_written_open():
    import math

    from sweep.regimes.separatrix import interval_text

    assert interval_text(0.262, math.inf) == "[0.26, ∞)"
    assert interval_text(-math.inf, math.inf) == "(−∞, ∞)"
    assert interval_text(-0.331, 1.594) == "[-0.33, 1.59]"

"""sweep.studies.experiment_lines / `dchfrac judge experiment_lines`: the experiment model's Ca*-C lines judged by
their declared protocol (issue #47 item 7).  Known answers: labels drawn from a known rising separatrix give
B > 0 at 2 sigma with the true B inside its interval; labels equal along Ca* at every C give the named evidence of
no separatrix; a failed run is listed with its reason and never labelled."""
import json

import numpy as np
import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies import experiment_lines as el

CEMENT = (0.5, 1.2, 2.0, 3.0)  # %
CA_STAR = np.logspace(6.0, 8.5, 7)  # -


def _line(crack, cement=CEMENT, ca_star=CA_STAR, **fixed) -> pd.DataFrame:
    """Every (C, Ca*) of a line, ok, with crack_length = crack(C, Ca*) (mm)."""
    rows = [dict(cement=c, Ca_star=a, eta_o=0.29, w_i=27.07, t_reached=4.0, front_radius_max=30.0,
                 crack_length=float(crack(c, a)), status="ok", reason=pd.NA) for c in cement for a in ca_star]
    return pd.DataFrame(rows).assign(**fixed)


def _rising(B=1.5, A=2e5):
    """Cracks of 10 mm above Ca*_c = A exp(B C) and 1 mm below: a separatrix rising with C."""
    return lambda c, a: 10.0 if a > A * np.exp(B * c) else 1.0


def test_labels_from_a_rising_separatrix_give_B_positive_at_2_sigma():
    out = el.judge({"eta": _line(_rising()), "rate": _line(_rising(), ca_star=CA_STAR * 1.3)})
    fit = out["pooled"]["at_L4"]
    assert out["verdict"] == "B > 0 at 2 sigma"
    assert fit["runs"] == 2 * len(CEMENT) * len(CA_STAR)
    assert fit["B_interval"][0] > 0 and fit["B_interval"][0] <= 1.5 <= fit["B_interval"][1]
    assert out["pooled"]["labels_along_ca_star"]["every_cement_unmixed"] is False


def test_every_label_equal_along_ca_star_is_the_named_evidence_of_no_separatrix():
    out = el.judge({"eta": _line(lambda c, a: 30.0)})
    line = out["lines"]["eta"]
    assert out["verdict"] == line["verdict"] == "no separatrix: every label equal along Ca* at each C"
    assert set(line["labels_along_ca_star"]["per_cement"].values()) == {"fracturing"}
    assert "error" in line["at_L4"]  # no fit with one outcome


def test_an_interval_of_B_containing_zero_is_said_so():
    # labels independent of C: a threshold flat in C at Ca* = 1e7
    out = el.judge({"eta": _line(lambda c, a: 10.0 if a > 1e7 else 1.0)})
    lo, hi = out["lines"]["eta"]["at_L4"]["B_interval"]
    assert lo < 0 < hi
    assert out["verdict"].startswith("B > 0 not shown: the 95 % interval of B")


def test_one_run_at_a_cement_ratio_is_no_line_to_read():
    along = el.labels_along_ca_star(_line(lambda c, a: 30.0, cement=(0.5,), ca_star=(1e7,)))
    assert along == {"per_cement": {"0.5": "one run: fracturing"}, "every_cement_unmixed": False}


def test_a_failed_run_is_listed_with_its_reason_and_carries_no_label():
    ok = _line(_rising())
    failed = ok.iloc[[0]].assign(status="failed", crack_length=np.nan, t_reached=2.32,
                                 reason="time step below dt_min=1e-07 at t = 2.32084 s")
    line = el.judge_line(pd.concat([ok, failed], ignore_index=True))
    assert (line["runs"], line["labelled"], line["failed_or_unlabelled"]) == (len(ok) + 1, len(ok), 1)
    assert line["at_L4"]["runs"] == len(ok)
    bad = [r for r in line["run_rows"] if r["status"] == "failed"]
    assert len(bad) == 1 and "fracturing_at_L4" not in bad[0]
    assert bad[0]["reason"].startswith("time step below") and bad[0]["t_reached"] == 2.32


def test_cli_judges_two_lines_pooled_with_a_figure(tmp_path, table_folder, capsys):
    eta = table_folder("eta_line", _line(_rising()))
    rate = table_folder("rate_line", _line(_rising(), ca_star=CA_STAR * 1.3))
    out, fig = tmp_path / "summary.json", tmp_path / "lines.png"
    assert main(["judge", "experiment_lines", str(eta), str(rate), "--out", str(out), "--figure", str(fig)]) == 0
    s = json.loads(out.read_text())
    assert set(s["lines"]) == {"eta_line", "rate_line"} and s["verdict"] == s["pooled"]["verdict"]
    assert fig.stat().st_size > 0


def test_no_line_is_refused():
    with pytest.raises(ValueError, match="no line given"):
        el.judge({})


@pytest.mark.parametrize("t_reached, front, kind", [
    (4.0, 32.0, "t_end"), (2.78, 45.3, "front"), (2.78, 44.2, "front"), (2.78, 29.5, "front_jump"),
])
def test_stop_kind_tells_the_front_s_arrival_from_a_jump(t_reached, front, kind):
    assert el.stop_kind(t_reached, front) == kind


@pytest.mark.parametrize("t_reached, front, last_step, kind", [
    (1.81, 45.7, 15.2, "front_jump"),   # the eta line's C = 2 %, eta_o = 0.29 run: 26.4 -> 41.6 mm in one step
    (2.78, 45.3, 0.3, "front"),         # an arrival the steps follow: less than an element a step
    (2.78, 45.3, 2.0, "front"),         # one element exactly is still resolved
    (2.78, 29.5, 0.1, "front_jump"),    # the classifier's front short of 45 mm decides alone
    (4.0, 46.0, 20.0, "t_end"),         # a run that reached t_end was not stopped by its front
])
def test_stop_kind_calls_an_arrival_in_one_step_of_more_than_an_element_a_jump(t_reached, front, last_step, kind):
    assert el.stop_kind(t_reached, front, last_step, 2.0) == kind
    assert el.stop_kind(t_reached, front, None, 2.0) == el.stop_kind(t_reached, front)   # not recorded: as before


def test_the_stops_are_counted_beside_the_verdict():
    df = _line(_rising())
    df.loc[:2, "t_reached"] = 2.5  # three runs stopped early, one with its front at 45 mm
    df.loc[0, "front_radius_max"] = 46.0
    assert el.judge_line(df)["stops"] == {"t_end": len(df) - 3, "front": 1, "front_jump": 2}


def test_an_interval_of_B_below_zero_is_not_said_to_contain_it():
    along = {"per_cement": {}, "every_cement_unmixed": False}
    assert el.verdict({"B_interval": [-5.0, -1.0], "B_positive_at_95": False}, along).endswith("lies below 0")
    assert el.verdict({"error": "need both outcomes"}, along) == "no separatrix: need both outcomes"


def test_a_line_without_a_labelled_run_is_judged_without_a_fit():
    failed = _line(_rising()).assign(status="failed", crack_length=np.nan, reason="max_wall_time exceeded")
    line = el.judge_line(failed)
    assert line["labelled"] == 0 and line["at_L4"]["error"] == "no labelled run"
    assert line["judged_time_s_quantiles_0_25_50_75_100"] is None and line["stops"]["t_end"] == 0
    assert line["verdict"] == "no separatrix: no labelled run"


def _failed_at(df: pd.DataFrame, rows) -> pd.DataFrame:
    """``df`` with the runs at ``rows`` failed (no crack length, stopped at 2.3 s)."""
    out = df.copy()
    out.loc[rows, ["status", "crack_length", "t_reached", "reason"]] = ["failed", np.nan, 2.3, "dt_min"]
    return out


def test_the_fallback_fills_the_failed_points_only_and_keeps_the_primary_verdict():
    full = _line(_rising())
    line = _failed_at(full, [3, 4, 5])  # C = 0.5 %: the three highest Ca*, fracturing in the full line
    fallback = full.loc[[3, 4, 5]].assign(t_reached=2.5, front_radius_max=30.0)  # rerun, stopped by a jump
    out = el.judge({"eta": line}, {"eta": fallback})
    primary, secondary = out["lines"]["eta"], out["secondary"]["lines"]["eta"]
    assert primary["labelled"] == len(full) - 3 and secondary["labelled"] == len(full)
    assert out["secondary"]["fallback_runs"] == {"eta": 3}
    assert out["verdict"] == primary["verdict"]  # the primary verdict is the headers' answer
    rows = [r for r in secondary["run_rows"] if r.get("fallback")]
    assert len(rows) == 3 and {r["stop"] for r in rows} == {"front_jump"}
    assert all(r["fracturing_at_L4"] for r in rows)
    # the secondary judgement is the full line's: the rows reordered walk the same brackets, and only the inner
    # minimum (trust-exact, gtol 1e-8) moves with the summation order, far inside 1e-6
    assert secondary["at_L4"]["B_interval"] == pytest.approx(el.judge_line(full)["at_L4"]["B_interval"], rel=1e-6)


def test_a_fallback_run_where_the_line_did_not_fail_is_refused():
    full = _line(_rising())
    with pytest.raises(ValueError, match="no failed run there"):
        el.judge({"eta": _failed_at(full, [3])}, {"eta": full.loc[[3, 4]]})
    with pytest.raises(ValueError, match="no such line"):
        el.judge({"eta": full}, {"rate": full.loc[[3]]})


def test_cli_takes_a_fallback_folder_named_for_its_line(tmp_path, table_folder, capsys):
    full = _line(_rising())
    eta = table_folder("eta_line", _failed_at(full, [3]))
    fb = table_folder("eta_line_upwind_fallback", full.loc[[3]])
    out, fig = tmp_path / "summary.json", tmp_path / "lines.png"
    assert main(["judge", "experiment_lines", str(eta), "--fallback", str(fb), "--out", str(out),
                 "--figure", str(fig)]) == 0
    assert json.loads(out.read_text())["secondary"]["fallback_runs"] == {"eta_line": 1}
    assert fig.stat().st_size > 0
    wrong = table_folder("other_upwind_fallback", full.loc[[3]])
    assert main(["judge", "experiment_lines", str(eta), "--fallback", str(wrong)]) == 2
    assert "must be named <line>_upwind_fallback" in capsys.readouterr().err
    assert main(["judge", "draws", str(eta), "--fallback", str(fb)]) == 2

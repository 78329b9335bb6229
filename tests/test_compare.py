"""Comparing two campaigns point by point (sweep.campaign.compare, ``dchfrac campaign compare``).

Two toy campaigns with known outcomes: ``a`` fractures iff eta_o > 0.2 (crack 12.5 mm) and fails at C = 3;
``b`` fractures iff eta_o > 0.3 (crack 12.5 + C mm), never fails, and has one more cement value.  Every count
and change below follows from those rules.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sweep.campaign.run import run_campaign
from sweep.campaign.cli import main as cli_main
from sweep.campaign.compare import compare_campaigns
from sweep.campaign.spec import spec_from_dict

VERSION = "test-compare"


def _write_series(run_dir):
    pd.DataFrame({"t": [0.0, 1.0], "p_inj": [0.0, 1.0]}).to_csv(Path(run_dir) / "timeseries.csv", index=False)


def runner_a(params, options, run_dir):
    """Fracturing iff eta_o > 0.2, crack 12.5 mm; fails at C = 3."""
    _write_series(run_dir)
    if params["cement"] == 3.0:
        return {"status": "failed", "reason": "Newton did not converge"}
    frac = params["eta_o"] > 0.2
    return {"status": "ok", "classification": {"regime": "invasive_fracturing" if frac else "viscous_fingering",
                                               "fracturing": frac, "crack_length": 12.5 if frac else 0.0}}


def runner_b(params, options, run_dir):
    """Fracturing iff eta_o > 0.3, crack 12.5 + C mm; never fails."""
    _write_series(run_dir)
    frac = params["eta_o"] > 0.3
    return {"status": "ok", "classification": {"regime": "invasive_fracturing" if frac else "viscous_fingering",
                                               "fracturing": frac,
                                               "crack_length": 12.5 + params["cement"] if frac else 0.0}}


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("compare")
    opts = {"h": 4.0, "snapshot_times": [0.5, 1.0]}
    a = spec_from_dict({"name": "a", "base": {"w_i": 10.0}, "options": opts,
                        "axes": {"cement": [1.0, 2.0, 3.0], "eta_o": [0.1, 0.25, 0.5]}})
    # the same eta_o values written differently (a last-digit difference, as from another log spacing)
    b = spec_from_dict({"name": "b", "base": {"w_i": 10.0}, "options": opts,
                        "axes": {"cement": [1.0, 2.0, 3.0, 4.0], "eta_o": [0.1 * (1 + 1e-15), 0.25, 0.5]}})
    run_campaign(a, root, runner=runner_a, jobs=1, code_hash=VERSION, progress=None)
    run_campaign(b, root, runner=runner_b, jobs=1, code_hash=VERSION, progress=None)
    return root


def test_points_are_matched_on_the_shared_swept_values(root):
    c = compare_campaigns(root / "a", root / "b", label="regime", columns=("crack_length",))
    assert set(c.on) == {"cement", "eta_o"}
    assert len(c.pairs) == 9 and len(c.only_a) == 0
    assert sorted(c.only_b["cement"].tolist()) == [4.0, 4.0, 4.0]


def test_statuses_and_labels_are_cross_tabulated(root):
    c = compare_campaigns(root / "a", root / "b")
    st = c.status_table
    assert st.loc["failed", "ok"] == 3 and st.loc["ok", "ok"] == 6
    # both ok: C = 1, 2 x eta_o = 0.1, 0.25, 0.5; eta_o = 0.25 fractures in a only
    assert c.agreement() == (4, 6)
    lt = c.label_table
    assert lt.loc["invasive_fracturing", "viscous_fingering"] == 2
    assert lt.loc["invasive_fracturing", "invasive_fracturing"] == 2
    assert lt.loc["viscous_fingering", "viscous_fingering"] == 2


def test_column_changes(root):
    ch = compare_campaigns(root / "a", root / "b", columns=("crack_length",)).column_changes()
    # |b - a| over both-ok points: 0, 0 (eta 0.1), 12.5, 12.5 (eta 0.25), 1, 2 (eta 0.5, C = 1, 2)
    assert ch.loc["crack_length", "n"] == 6
    assert ch.loc["crack_length", "max_abs_change"] == pytest.approx(12.5)
    assert ch.loc["crack_length", "median_abs_change"] == pytest.approx(np.median([0, 0, 12.5, 12.5, 1, 2]))


def test_markdown_names_both_campaigns_and_the_agreement(root):
    text = compare_campaigns(root / "a", root / "b", columns=("crack_length",)).markdown()
    assert "`a` against `b`" in text and "4 of 6 labels agree" in text and "| crack_length |" in text


def test_unknown_column_is_refused(root):
    with pytest.raises(ValueError, match="no column 'crak_length'"):
        compare_campaigns(root / "a", root / "b", columns=("crak_length",))


def test_cli_writes_the_summary_and_refuses_bad_columns(root, tmp_path, capsys):
    out = tmp_path / "cmp.md"
    assert cli_main(["compare", str(root / "a"), str(root / "b"), "--results", str(root),
                     "--columns", "crack_length", "--out", str(out)]) == 0
    assert "4 of 6 labels agree" in out.read_text()
    assert cli_main(["compare", str(root / "a"), str(root / "b"), "--results", str(root),
                     "--label", "regme"]) == 2
    assert "no column 'regme'" in capsys.readouterr().err


def runner_seed(params, options, run_dir):
    """Fracturing iff the porosity draw's seed is odd: the label of a run is its seed's, in either campaign."""
    _write_series(run_dir)
    frac = int(params["seed"]) % 2 == 1
    return {"status": "ok", "classification": {"regime": "invasive_fracturing" if frac else "viscous_fingering",
                                               "fracturing": frac}}


@pytest.fixture(scope="module")
def replicated(tmp_path_factory):
    """Two campaigns of 2 points x 2 porosity draws (seeds 0, 1) with identical labels run by run, and a third
    that sweeps eta_o where the first two hold it at 0.29 kPa s."""
    root = tmp_path_factory.mktemp("compare_rep")
    opts = {"h": 4.0, "snapshot_times": [0.5, 1.0]}
    for name in ("ra", "rb"):
        s = spec_from_dict({"name": name, "base": {"w_i": 10.0}, "options": opts, "axes": {"cement": [1.0, 2.0]},
                            "replicates": {"porosity_seed": 2}})
        run_campaign(s, root, runner=runner_seed, jobs=1, code_hash=VERSION, progress=None)
    s = spec_from_dict({"name": "rc", "base": {"w_i": 10.0}, "options": opts,
                        "axes": {"cement": [1.0, 2.0], "eta_o": [0.29, 0.5]}})
    run_campaign(s, root, runner=runner_seed, jobs=1, code_hash=VERSION, progress=None)
    return root


def test_replicates_are_matched_draw_by_draw(replicated):
    # 2 points x 2 draws: 4 runs in each campaign, each with the same label in both; matching on the swept values
    # alone would pair every draw of a point with every draw of the other campaign's point (8 pairs, 4 agreeing)
    c = compare_campaigns(replicated / "ra", replicated / "rb")
    assert len(c.pairs) == 4 and len(c.only_a) == 0 and len(c.only_b) == 0
    assert c.agreement() == (4, 4)


def test_a_parameter_swept_in_one_campaign_is_matched_on_the_others_value(replicated):
    # rc sweeps eta_o over 0.29 and 0.5; ra holds it at 0.29 (2 draws): the rc runs at eta_o = 0.5 have no
    # counterpart, and each rc run at 0.29 (seed 0) matches ra's run of seed 0 only
    c = compare_campaigns(replicated / "rc", replicated / "ra")
    assert len(c.pairs) == 2 and len(c.only_a) == 2 and len(c.only_b) == 2
    assert c.agreement() == (2, 2)

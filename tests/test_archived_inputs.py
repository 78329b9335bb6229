"""An archived row (a committed table's row whose run folder is not here) stands for a point of the spec only when
the inputs the spec writes agree with the row's (sweep.campaign.archived.match_committed).

A toy campaign of two points (C = 1, 2 %) at w_i = 10 mm/s is run and its run folders removed; its committed
rows are then read by specs that differ from it in known ways."""
from __future__ import annotations

import shutil

import pandas as pd

from sweep.campaign.plan import plan_campaign
from sweep.campaign.run import run_campaign
from sweep.campaign.spec import spec_from_dict
from sweep.campaign.table import build_table

VERSION = "test-archived-inputs"


def runner(params, options, run_dir):
    """Fracturing iff w_i > 15 mm/s: a row made at another w_i has another label."""
    return {"status": "ok", "classification": {"fracturing": params["w_i"] > 15.0}}


def _spec(w_i: float):
    return spec_from_dict({"name": "arch", "base": {"w_i": w_i}, "axes": {"cement": [1.0, 2.0]}})


def _committed(tmp_path, *, old_keys: bool):
    """Run the campaign at w_i = 10 mm/s, keep its table and remove its run folders; ``old_keys``: the rows' keys
    are those of an older model (a parameter added to the model changes every key)."""
    run_campaign(_spec(10.0), tmp_path, runner=runner, jobs=1, code_hash=VERSION, progress=None)
    d = tmp_path / "arch"
    t = pd.read_csv(d / "table.csv")
    if old_keys:
        t = t.assign(key="old-" + t["key"])
    t.to_csv(d / "table.csv", index=False)
    (d / "table.parquet").unlink()
    shutil.rmtree(d / "runs")
    return d


def test_a_row_made_at_another_written_value_is_not_the_points_result(tmp_path):
    # the spec now asks for w_i = 20 mm/s: the rows made at 10 mm/s (keys of an older model, so matched by their
    # swept values) are not its results; both points are pending, and the table shows no run at w_i = 10
    _committed(tmp_path, old_keys=True)
    plan = plan_campaign(_spec(20.0), tmp_path, code_hash=VERSION)
    assert len(plan.pending) == 2 and not plan.archived
    assert len(plan.unmatched_rows) == 2
    assert build_table(_spec(20.0), tmp_path, plan=plan).empty


def test_a_row_of_an_older_model_at_the_written_values_is_archived(tmp_path):
    # the same spec (w_i = 10 mm/s) over rows of an older model: matched by swept values, as before
    _committed(tmp_path, old_keys=True)
    plan = plan_campaign(_spec(10.0), tmp_path, code_hash=VERSION)
    assert len(plan.archived) == 2 and not plan.pending
    assert list(build_table(_spec(10.0), tmp_path, plan=plan)["fracturing"]) == [False, False]


def test_a_default_the_spec_does_not_write_is_not_compared(tmp_path):
    # a row made when a run option's default was other (newton_rtol 1e-7; the spec writes none): still archived
    d = _committed(tmp_path, old_keys=True)
    t = pd.read_csv(d / "table.csv")
    t.assign(newton_rtol=1e-7).to_csv(d / "table.csv", index=False)
    plan = plan_campaign(_spec(10.0), tmp_path, code_hash=VERSION)
    assert len(plan.archived) == 2 and not plan.pending


def test_a_row_without_the_column_of_a_written_value_is_matched(tmp_path):
    # a table written before the model had the field: nothing to compare, the swept values decide
    d = _committed(tmp_path, old_keys=True)
    pd.read_csv(d / "table.csv").drop(columns=["w_i"]).to_csv(d / "table.csv", index=False)
    plan = plan_campaign(_spec(10.0), tmp_path, code_hash=VERSION)
    assert len(plan.archived) == 2

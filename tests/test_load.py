"""Loading campaign results: typed table (nullable types, real lists), Parquet schema, column
dictionary with units from their declarations, long time-series frame, ``campaign columns``.

The runner below writes a known time series (p_inj = 10 C t kPa) and a known classification, and
fails for C = 3, so the table holds failed runs with NA outcomes.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sweep import load_campaign, load_timeseries
from sweep.campaign.run import run_campaign
from sweep.campaign.cli import main as cli_main
from sweep.campaign.spec import spec_from_dict

VERSION = "test-load"


def classified_runner(params, options, run_dir):
    """Fracturing iff eta_o > 0.2; two crack tips at 10 and -20.5 deg; fails at C = 3."""
    c = params["cement"]
    t = np.linspace(0.0, 1.0, 5 + int(c))
    pd.DataFrame({"t": t, "p_inj": 10.0 * c * t, "newton_its": np.arange(len(t))}).to_csv(
        Path(run_dir) / "timeseries.csv", index=False)
    if c == 3.0:
        return {"status": "failed", "reason": "Newton did not converge"}
    frac = params["eta_o"] > 0.2
    cls = {"regime": "invasive_fracturing" if frac else "viscous_fingering", "fracturing": frac,
           "n_cracks": 2 if frac else 0, "crack_tip_angles_deg": "10.0;-20.5" if frac else "",
           "crack_length": 12.5 if frac else 0.0}
    return {"status": "ok", "classification": cls, "metrics": {"n_steps": len(t)}}


def _spec(tmp_path):
    d = {"name": "toy", "base": {"w_i": 10.0}, "options": {"h": 4.0, "snapshot_times": [0.5, 1.0]},
         "axes": {"cement": [1.0, 2.0, 3.0], "eta_o": [0.1, 0.5]}}
    spec = spec_from_dict(d)
    run_campaign(spec, tmp_path, runner=classified_runner, jobs=1, code_hash=VERSION, progress=None)
    return spec


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("load")
    return _spec(root), root


def test_typed_table_with_failed_runs(campaign, monkeypatch):
    spec, root = campaign
    monkeypatch.setattr("solver.codehash.code_hash", lambda: VERSION)
    d = load_campaign(root / "toy")
    assert len(d) == 6 and d.attrs["campaign_dir"] == str(root / "toy")
    assert str(d["fracturing"].dtype) == "boolean" and d["fracturing"].isna().sum() == 2  # C = 3 failed
    frac = d[d.fracturing]
    assert sorted(zip(frac.cement, frac.eta_o)) == [(1.0, 0.5), (2.0, 0.5)]
    assert str(d["n_cracks"].dtype) == "Int64" and list(frac.n_cracks) == [2, 2]
    assert str(d["Gc"].dtype) == "Float64" and d["Gc"].isna().all()  # follows its law of C: None
    assert str(d["cement"].dtype) == "Float64" and str(d["status"].dtype) == "string"
    assert list(frac.crack_tip_angles_deg) == [[10.0, -20.5]] * 2
    assert d.loc[(d.cement == 1.0) & (d.eta_o == 0.1), "crack_tip_angles_deg"].item() == []
    assert all(v == [0.5, 1.0] for v in d.snapshot_times)
    for rd, key in zip(d.run_dir, d.key):
        assert not os.path.isabs(rd) and rd == f"runs/{key}"
        assert (root / "toy" / rd / "record.json").is_file()
    by_spec = load_campaign(spec, root)  # a spec gives the same table
    pd.testing.assert_frame_equal(by_spec, d)


def test_parquet_types_every_column_and_csv_reads_back_the_same(campaign, tmp_path):
    spec, root = campaign
    schema = pq.read_schema(root / "toy" / "table.parquet")
    assert not [f.name for f in schema if pa.types.is_null(f.type)]
    assert schema.field("Gc").type == pa.float64() and schema.field("fracturing").type == pa.bool_()
    assert schema.field("crack_tip_angles_deg").type == pa.list_(pa.float64())
    assert schema.field("snapshot_times").type == pa.list_(pa.float64())
    assert schema.field("n_cracks").type == pa.int64()
    # the CSV alone (list cells as JSON text) loads to the same frame as the Parquet
    only_csv = tmp_path / "toy"
    only_csv.mkdir()
    for f in ("table.csv", "columns.csv"):
        (only_csv / f).write_bytes((root / "toy" / f).read_bytes())
    a, b = load_campaign(root / "toy"), load_campaign(only_csv)
    pd.testing.assert_frame_equal(a.drop(columns=[]), b, check_like=False)
    assert json.loads(pd.read_csv(only_csv / "table.csv")["crack_tip_angles_deg"].dropna().iloc[-1]) in ([], [10.0, -20.5])


def test_column_dictionary_units_come_from_the_declarations(campaign):
    from solver.options import OPTION_UNITS
    from solver.params import field_unit

    _, root = campaign
    cols = pd.read_csv(root / "toy" / "columns.csv", keep_default_na=False).set_index("name")
    table = pd.read_csv(root / "toy" / "table.csv")
    assert list(cols.index) == list(table.columns)
    for name in ("eta_w", "kbar", "E", "gamma", "Gc", "r_outer"):
        assert cols.loc[name, "unit"] == field_unit(name)
    for name in ("h", "t_end", "dt_max"):
        assert cols.loc[name, "unit"] == OPTION_UNITS[name]
    assert cols.loc["crack_length", "unit"] == "mm" and cols.loc["crack_tip_angles_deg", "unit"] == "deg"
    assert cols.loc["fracturing", "dtype"] == "boolean"
    assert all(cols["meaning"].str.len() > 0)


def test_timeseries_long_frame_keyed_by_run_and_swept_values(campaign):
    spec, root = campaign
    ts = load_timeseries(root / "toy")
    assert list(ts.columns[:4]) == ["key", "cement", "eta_o", "status"]
    # every run wrote its series, the failed ones too: 2 runs each of 6, 7, 8 rows
    assert len(ts) == 2 * (6 + 7 + 8)
    assert ts.groupby("key").size().sort_values().tolist() == [6, 6, 7, 7, 8, 8]
    np.testing.assert_allclose(ts["p_inj"], 10.0 * ts["cement"].astype(float) * ts["t"], rtol=1e-12)
    ok = load_timeseries(root / "toy", status="ok")
    assert set(ok["status"]) == {"ok"} and len(ok) == 2 * (6 + 7)


def test_campaign_columns_command(campaign, tmp_path, capsys):
    spec, root = campaign
    path = tmp_path / "toy.toml"
    path.write_text('name = "toy"\n[base]\nw_i = 10.0\n[options]\nh = 4.0\nsnapshot_times = [0.5, 1.0]\n'
                    '[axes]\ncement = [1.0, 2.0, 3.0]\neta_o = [0.1, 0.5]\n')
    assert cli_main(["columns", str(path), "--results", str(root)]) == 0
    lines = {ln.split()[0]: ln.split()[1] for ln in capsys.readouterr().out.splitlines()}
    assert lines["w_i"] == "mm/s" and lines["crack_length"] == "mm"
    assert cli_main(["columns", str(path), "--results", str(root), "--timeseries"]) == 0
    out = capsys.readouterr().out
    assert any(ln.split()[:2] == ["p_inj", "kPa"] for ln in out.splitlines())


def test_spec_without_a_written_table_builds_it_from_the_records(campaign, tmp_path, monkeypatch):
    import shutil

    spec, root = campaign
    monkeypatch.setattr("solver.codehash.code_hash", lambda: VERSION)
    copy = tmp_path / "toy"
    shutil.copytree(root / "toy", copy)
    for f in ("table.csv", "table.parquet", "columns.csv"):
        (copy / f).unlink()
    with pytest.raises(FileNotFoundError, match="no table"):
        load_campaign(copy)  # a folder alone cannot say which grid it holds
    built = load_campaign(spec, tmp_path)
    written = load_campaign(root / "toy")
    pd.testing.assert_frame_equal(built, written)

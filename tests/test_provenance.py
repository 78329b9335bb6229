"""sweep.campaign.provenance / `dchfrac provenance`: results/PROVENANCE.md is written from the campaign tables' code
hashes, counted run by run on a made-up results folder, and the committed file is what the committed tables give."""
from pathlib import Path

import pandas as pd

from sweep.campaign import provenance as pv
from sweep.cli import main

RESULTS = Path(__file__).resolve().parents[1] / "results"


def _results(tmp_path) -> Path:
    root = tmp_path / "results"
    a = root / "grid_a"
    a.mkdir(parents=True)
    pd.DataFrame({"status": ["ok", "ok", "failed"], "code_hash": ["aaa", "bbb", "aaa"],
                  "classifier_hash": ["ccc", "ccc", ""],
                  "finished_at": ["2026-11-27T23:59:00", "2026-11-28T00:01:00", "2026-11-28T01:00:00"]}
                 ).to_csv(a / "table.csv", index=False)
    (a / "runs" / "k1").mkdir(parents=True)
    pd.DataFrame({"status": ["ok"]}).to_csv(a / "runs" / "k1" / "table.csv", index=False)  # a run's, not a campaign's
    old = root / "archive" / "old_grid"
    old.mkdir(parents=True)
    pd.DataFrame({"status": ["ok", "ok"]}).to_csv(old / "table.csv", index=False)
    (root / pv.NOTES).write_text("## By hand\n\n`old_grid/`: committed by abc1234.\n")
    return root


def test_each_campaign_table_gives_its_hashes_run_by_run(tmp_path):
    rows = pv.provenance_rows(_results(tmp_path))
    assert [r["folder"] for r in rows] == ["archive/old_grid/", "grid_a/"]
    old, grid = rows
    assert (old["runs"], old["code"], old["classifier"], old["finished"]) == (2, None, None, None)
    assert grid["runs"] == 3 and grid["code"] == "`aaa` (2), `bbb` (1)"
    assert grid["classifier"] == "`ccc` (2), failed, no label (1)"
    assert grid["finished"] == "2026-11-27 – 2026-11-28"


def test_cli_writes_then_checks_and_names_a_missing_notes_file(tmp_path, capsys):
    root = _results(tmp_path)
    assert main(["provenance", "--results", str(root), "--check"]) == 1  # not written yet
    assert main(["provenance", "--results", str(root)]) == 0
    text = (root / pv.OUT).read_text()
    assert "| `grid_a/` | 3 | `aaa` (2), `bbb` (1) |" in text and text.rstrip().endswith("committed by abc1234.")
    assert main(["provenance", "--results", str(root), "--check"]) == 0
    pd.DataFrame({"status": ["ok"], "code_hash": ["ddd"]}).to_csv(root / "grid_a" / "table.csv", index=False)
    assert main(["provenance", "--results", str(root), "--check"]) == 1  # a table changed: out of date
    (root / pv.NOTES).unlink()
    capsys.readouterr()
    assert main(["provenance", "--results", str(root)]) == 2
    assert "no provenance_notes.md" in capsys.readouterr().err


def test_committed_provenance_is_what_the_committed_tables_give():
    """After committing a campaign's table, `dchfrac provenance` rewrites results/PROVENANCE.md."""
    expected = pv.render(pv.provenance_rows(RESULTS), (RESULTS / pv.NOTES).read_text(encoding="utf-8"))
    assert (RESULTS / pv.OUT).read_text(encoding="utf-8") == expected, "run: dchfrac provenance"

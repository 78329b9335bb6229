"""Done-when of issue #52: on a fresh clone (``git clone`` of this checkout: committed files only, no run
folders but the committed pruned ones), ``status``, ``plot`` and ``report`` work on every committed campaign
without the solver, each showing its committed counts, and the loaders return non-empty typed frames with units.

The default suite checks every campaign's loader and a representative pair of campaigns through the CLI (a grid
with a field map it cannot redraw, an adaptive boundary campaign); ``-m slow`` runs the CLI on every campaign."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from sweep.campaign.cli import committed_specs
from sweep.campaign.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
REPRESENTATIVE = ("campaigns/examples/demo.toml", "campaigns/studies/ca_star_boundary_h4.toml")


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    dst = tmp_path_factory.mktemp("fresh") / "dchfrac"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(dst)], check=True)
    return dst


@pytest.fixture
def no_solver(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("the solver ran")

    import solver

    monkeypatch.setattr(solver, "simulate", refuse)
    monkeypatch.setattr("sweep.campaign.run._execute", refuse)


def _counts(table) -> tuple[int, int]:
    ok = int((table["status"] == "ok").sum())
    return ok, len(table) - ok


def _finished(text: str, done: str, failed: str) -> tuple[int, int]:
    """(ok, failed) a status line or report states: its done and failed runs (patterns ``done``, ``failed``)
    plus the ok and failed rows of its archived line (committed rows whose run folders are not here)."""
    import re

    m_done, m_failed = re.search(done, text), re.search(failed, text)
    arch = re.search(r"archived \(rows of the committed table, run folders not here\): \d+ \((\d+) ok, (\d+) failed", text)
    ok = int(m_done[1]) if m_done else 0
    bad = int(m_failed[1]) if m_failed else 0
    return (ok + int(arch[1]), bad + int(arch[2])) if arch else (ok, bad)


def _check_cli(clone: Path, rel: str, capsys) -> None:
    from sweep import load_campaign

    spec = clone / rel
    table = load_campaign(spec)
    ok, failed = _counts(table)
    assert cli_main(["status", str(spec)]) == 0
    out = capsys.readouterr().out
    # the committed table's finished runs, as run folders here (done) and committed rows (archived); a campaign
    # committed part-way (a long study resumed across sessions) lists the rest of its grid as pending
    assert _finished(out, r" runs: (\d+) done", r" done, (\d+) failed") == (ok, failed), out
    assert cli_main(["plot", str(spec)]) == 0
    out = capsys.readouterr()
    from sweep.campaign.spec import load_spec

    if load_spec(spec).diagrams:  # a spec without diagrams has nothing to plot, and says so
        assert "figure:" in out.out or "kept as it is" in out.err, out
    else:
        assert "nothing to plot" in out.out, out
    assert cli_main(["report", str(spec)]) == 0
    capsys.readouterr()
    report = (table.attrs["campaign_dir"] + "/report.md")
    text = Path(report).read_text()
    assert _finished(text, r"- done: (\d+)", r"- failed: (\d+)") == (ok, failed), text[:800]


def test_every_committed_campaign_loads_typed_with_units(clone):
    from sweep import load_campaign

    specs = committed_specs(clone)
    assert len(specs) >= 30, specs
    for s in specs:
        d = load_campaign(s)
        assert len(d) > 0 and Path(d.attrs["campaign_dir"]).parent == clone / "results", s
        assert str(d["status"].dtype) == "string" and "key" in d.attrs["units"], s
        f = Path(d.attrs["campaign_dir"])
        assert (f / "table.parquet").is_file() and (f / "columns.csv").is_file(), f"{f}: table.parquet or columns.csv"
        import pyarrow.parquet as pq

        assert b"unit" in pq.read_schema(f / "table.parquet").field("key").metadata, f


@pytest.mark.parametrize("rel", REPRESENTATIVE)
def test_status_plot_report_on_a_fresh_clone(clone, rel, capsys, no_solver):
    _check_cli(clone, rel, capsys)


@pytest.mark.slow
def test_status_plot_report_on_every_committed_campaign_of_a_fresh_clone(clone, capsys, no_solver):
    for s in committed_specs(clone):
        _check_cli(clone, str(s.relative_to(clone)), capsys)

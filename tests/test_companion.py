"""A companion campaign (sweep.campaign.companion): a campaign's failed points, and only those, rerun with changed
options, every other value the campaign's; written from its run records or, on a fresh clone, its committed table.

The runner below fails by its parameters alone, so which points failed is known before the campaign runs."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from solver.tomlio import tomllib
from sweep.campaign.cli import main as cli_main
from sweep.campaign.companion import _toml_text, companion_text, write_companion
from sweep.campaign.plan import plan_campaign
from sweep.campaign.spec import load_spec, samplers


def failing_at_c2_runner(params, options, run_dir):
    """Fails at cement = 2 % unless the transport of S is upwind; a known label otherwise."""
    if params["cement"] == 2.0 and options["transport"] != "upwind":
        return {"status": "failed", "reason": f"Newton diverged at eta_o = {params['eta_o']}: time step below dt_min "
                                              "at t = 2.32084 s (last: Newton did not converge in 25 iterations)"}
    Path(run_dir, "out.json").write_text(json.dumps({"eta_o": params["eta_o"]}))
    return {"status": "ok", "regime": "fracturing" if params["eta_o"] > 0.3 else "porous_invasion"}


_LINE = """# a line's header: its protocol
name = "toyline"
description = "a toy line"
[base]
w_i = 10.0
porosity_floor = 0.1
[options]
h = 2.0
t_end = 1.5
stop_front_radius = 45.0
[axes]
cement = [1.0, 2.0, 3.0]
eta_o = {log = [0.1, 1.0, 3]}
[classify]
min_crack_length = 4.0
[[diagrams]]
kind = "scatter"
x = "eta_o"
y = "cement"
file = "regimes.png"
[run]
isolate = "none"
runner = "test_companion:failing_at_c2_runner"
"""


def _points(spec_path):
    spec = load_spec(spec_path)
    return samplers()[spec.sampler["kind"]]().initial(spec)


@pytest.fixture
def ended_line(tmp_path):
    """The toy line run to its end: 9 points, the 3 at cement = 2 % failed."""
    spec = tmp_path / "campaigns" / "toyline.toml"
    spec.parent.mkdir()
    spec.write_text(_LINE)
    assert cli_main(["run", str(spec), "--results", str(tmp_path / "results"), "--quiet"]) == 1  # its failures
    return spec


def test_companion_reruns_exactly_the_failed_points_with_the_changed_option(ended_line, tmp_path):
    out = write_companion(ended_line, tmp_path / "results", options={"transport": "upwind"}, suffix="_upwind_fallback")
    assert out == ended_line.with_name("toyline_upwind_fallback.toml")
    comp = load_spec(out)
    assert comp.name == "toyline_upwind_fallback" and comp.blocks[0].mode == "zip"
    line_pts = {(p.params["cement"], p.params["eta_o"]): p for p in _points(ended_line)}
    comp_pts = _points(out)
    assert sorted((p.params["cement"], p.params["eta_o"]) for p in comp_pts) == [k for k in sorted(line_pts) if k[0] == 2.0]
    assert len(comp_pts) == 3
    for p in comp_pts:   # every other value is the line's: parameters equal, options equal but the changed one
        q = line_pts[(p.params["cement"], p.params["eta_o"])]
        assert dict(p.params) == dict(q.params)
        assert {**q.options, "transport": "upwind"} == dict(p.options) and q.options["transport"] != "upwind"
    assert dict(comp.classify) == dict(load_spec(ended_line).classify) and comp.diagrams == load_spec(ended_line).diagrams
    text = out.read_text()
    assert "3 failed points of its 9 runs" in text and text.count("Newton diverged at eta_o") == 3
    header = " ".join(ln[1:].strip() for ln in text.splitlines() if ln.startswith("#"))
    assert header.count("(last: Newton did not converge in 25 iterations)") == 3     # each reason whole, wrapped
    assert max(len(ln) for ln in text.splitlines() if ln.startswith("#")) <= 120
    # and the companion runs: each of its points is ok with upwind transport
    assert cli_main(["run", str(out), "--results", str(tmp_path / "results"), "--quiet"]) == 0


def test_companion_from_the_committed_table_alone(ended_line, tmp_path):
    """A fresh clone has the committed table, not the run folders: the same companion text."""
    res = tmp_path / "results"
    with_runs = companion_text(ended_line, res, options={"transport": "upwind"}, suffix="_f")
    shutil.rmtree(res / "toyline" / "runs")
    plan = plan_campaign(load_spec(ended_line), res, verify=False)
    assert not plan.records and len(plan.archived) == 9
    assert companion_text(ended_line, res, options={"transport": "upwind"}, suffix="_f") == with_runs


def test_companion_refuses_a_campaign_that_has_not_ended(tmp_path):
    spec = tmp_path / "toyline.toml"
    spec.write_text(_LINE)
    with pytest.raises(ValueError, match="9 of its 9 points are pending.*once the campaign has ended"):
        companion_text(spec, tmp_path / "results", options={"transport": "upwind"}, suffix="_f")


def test_companion_refuses_nothing_to_rerun_and_no_change(tmp_path, ended_line):
    res = tmp_path / "results"
    with pytest.raises(ValueError, match="at least one option must change"):
        companion_text(ended_line, res, options={}, suffix="_f")
    ok_line = ended_line.with_name("okline.toml")
    ok_line.write_text(_LINE.replace('"toyline"', '"okline"').replace("[1.0, 2.0, 3.0]", "[1.0, 3.0]"))
    assert cli_main(["run", str(ok_line), "--results", str(res), "--quiet"]) == 0
    with pytest.raises(ValueError, match="no failed run in its table, nothing to rerun"):
        companion_text(ok_line, res, options={"transport": "upwind"}, suffix="_f")


def test_cli_companion_bad_option_and_existing_out_write_nothing(ended_line, tmp_path, capsys):
    res = str(tmp_path / "results")
    args = ["companion", str(ended_line), "--results", res, "--suffix", "_f"]
    assert cli_main(args + ["--set", "transpor=upwind"]) == 2
    assert "transpor" in capsys.readouterr().err
    assert sorted(p.name for p in ended_line.parent.iterdir()) == ["toyline.toml"]   # nothing written, no temp file
    assert cli_main(args + ["--set", "transport=upwind"]) == 0
    assert load_spec(ended_line.with_name("toyline_f.toml")).options["transport"] == "upwind"
    assert cli_main(args + ["--set", "transport='upwind'"]) == 2          # a TOML literal is read as one
    assert "exists; a companion is written once" in capsys.readouterr().err
    assert cli_main(args + ["--set", "=upwind"]) == 2
    assert "expected KEY=VALUE" in capsys.readouterr().err


def test_toml_text_round_trips_tables_inline_tables_and_quoted_keys():
    d = {"name": "x", "paper": 'Sec. 3 "quoted" \u00e9', "mode": "zip",
         "base": {"w_i": 27.07, "kbar": 1e-05, "flag": True},
         "axes": {"cement": [0.5, 2.0], "options.h": [2.0, 1.0], "eta_o": {"log": [0.029, 2.9, 5]}},
         "diagrams": [{"kind": "scatter", "x": "eta_o"}, {"kind": "ca_star_vs_cement", "title": "t"}]}
    assert tomllib.loads(_toml_text(d)) == d

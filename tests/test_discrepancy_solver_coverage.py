"""The real-solver coverage table (sweep.discrepancy.solver_coverage) on hand-made twin results."""
import json

import pytest

from sweep.discrepancy.coverage import wilson
from sweep.discrepancy.solver_coverage import coverage_markdown, coverage_summary, main, twin_rows


def _entry(expect, hidden, interval, named=None, gap=(4.0, 1.0)):
    return {"expect": expect, "hidden": hidden, "named_effect": expect if named is None else named,
            "verdict": "named" if named is None else "unexplained_discrepancy", "strength_interval": interval,
            "strength": None if interval is None else sum(interval) / 2, "gap_before": gap[0], "gap_after": gap[1],
            "passed": True, "wall_time_s": 10.0, "overrides": ["spec.profile.fine=false"]}


def _write(folder, entries, reports=None):
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps(entries))
    for name, rep in (reports or {}).items():
        (folder / name).mkdir()
        (folder / name / "report.json").write_text(json.dumps(rep))


def test_coverage_counts_named_twins_splits_misses_by_side_and_reads_the_refresh(tmp_path):
    """Four named twins (one covered, one missed low, one missed high, one covered at its upper end), one
    twin whose effect was not named (not counted), one control (no row): 2 / 4 covered with the Wilson
    interval of 2 of 4; each miss's side, the truth's place in the interval and the report's refresh."""
    _write(tmp_path / "a", {
        "dv": _entry("damage_viscosity", {"beta": 45.0, "E": 360.0}, [30.0, 60.0]),
        "dv_low": _entry("damage_viscosity", {"beta": 45.0}, [20.0, 40.0]),
        "cb_high": _entry("compliant_boundary", {"outer_compliance": 0.012}, [0.013, 0.02]),
        "control": {**_entry("no_missing_effect", {}, None), "named_effect": None},
    }, reports={"dv_low": {"accepted": [{"effect": "damage_viscosity", "refresh_converged": True,
                                         "strength_before_refresh": 36.0, "strength_interval_wald": [25.0, 50.0]}],
                           "discretization_refresh": [{}, {}],
                           "profiles": {"damage_viscosity": {"emulator": {"confirmed": True}}}}})
    _write(tmp_path / "b", {"edge": _entry("compliant_boundary", {"outer_compliance": 0.01}, [0.005, 0.01]),
                            "unnamed": _entry("damage_viscosity", {"beta": 50.0}, None, named="")})
    rows = twin_rows([tmp_path / "a", tmp_path / "b"])
    by = {r["twin"]: r for r in rows}
    assert set(by) == {"dv", "dv_low", "cb_high", "edge", "unnamed"}          # the control has no row
    assert by["dv"]["covered"] and by["dv"]["position"] == pytest.approx(0.5)
    assert (by["dv_low"]["miss"], by["cb_high"]["miss"]) == ("low", "high")
    assert by["edge"]["covered"] and by["edge"]["position"] == pytest.approx(1.0)
    low = by["dv_low"]
    assert (low["refresh_passes"], low["refresh_converged"], low["wald_covered"], low["emulator_confirmed"]) == (2, True, True, True)
    assert low["before_refresh_error"] == pytest.approx(-0.2)
    assert not by["unnamed"]["named"] and "covered" not in by["unnamed"]
    s = coverage_summary(rows)["pooled"]
    assert (s["twins"], s["named"], s["covered"], s["miss_low"], s["miss_high"]) == (5, 4, 2, 1, 1)
    assert s["wilson95"] == pytest.approx(list(wilson(2, 4)))
    by_eff = coverage_summary(rows)["by_effect"]
    assert (by_eff["damage_viscosity"]["named"], by_eff["compliant_boundary"]["covered"]) == (2, 1)
    md = coverage_markdown(rows, coverage_summary(rows))
    assert "**2 / 4**" in md and "**no (low)**" in md and "**no (high)**" in md


def test_solver_coverage_cli_writes_json_and_markdown_and_refuses_a_folder_without_a_summary(tmp_path, capsys):
    _write(tmp_path / "a", {"dv": _entry("damage_viscosity", {"beta": 45.0}, [30.0, 60.0])})
    out = tmp_path / "cov" / "coverage.json"
    out.parent.mkdir()
    assert main([str(tmp_path / "a"), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["pooled"]["covered"] == 1 and out.with_suffix(".md").is_file()
    capsys.readouterr()
    assert main([str(tmp_path / "nope")]) == 2
    assert "no summary.json" in capsys.readouterr().err


def test_coverage_by_correction_reads_each_report_and_the_parameters_a_linear_correction_follows(tmp_path):
    """Three twins of one set-up, each with the correction its report records ("point", "linear", and "linear"
    following k̄ too): the row carries it, the summary counts covered / named per correction, and the Markdown
    has one line per correction."""
    dv = {"beta": 55.0}

    def report(kind, follows=None):
        prof = {"correction": kind}
        if follows:
            prof["correction_model"] = {"follows": follows}
        return {"profiles": {"damage_viscosity": prof}}

    _write(tmp_path / "point", {"dv": _entry("damage_viscosity", dv, [23.0, 68.0])}, reports={"dv": report("point")})
    _write(tmp_path / "linear", {"dv": _entry("damage_viscosity", dv, [20.0, 46.7])}, reports={"dv": report("linear")})
    _write(tmp_path / "all", {"dv": _entry("damage_viscosity", dv, [18.4, 47.6])},
           reports={"dv": report("linear", ["kbar", "effect:damage_viscosity"])})
    rows = twin_rows([tmp_path / "point", tmp_path / "linear", tmp_path / "all"])
    assert [r["correction"] for r in rows] == ["point", "linear", "linear + kbar"]
    by = coverage_summary(rows)["by_correction"]
    assert {k: (c["covered"], c["named"], c["miss_low"]) for k, c in by.items()} == {
        "point": (1, 1, 0), "linear": (0, 1, 1), "linear + kbar": (0, 1, 1)}
    md = coverage_markdown(rows, coverage_summary(rows))
    assert "| point | 1 / 1 | 0 / 0 | 1 of 1 |" in md and "| linear + kbar | 0 / 1 | 1 / 0 | 1 of 1 |" in md


def test_dchfrac_discrepancy_coverage_is_the_same_command(tmp_path, capsys):
    """`dchfrac discrepancy coverage` runs the module's command: the same files; a bad folder exits 2 in one line
    before any file is written."""
    from sweep.cli import main as dchfrac

    _write(tmp_path / "a", {"dv": _entry("damage_viscosity", {"beta": 45.0}, [30.0, 60.0])})
    out = tmp_path / "coverage.json"
    assert dchfrac(["discrepancy", "coverage", str(tmp_path / "a"), "--out", str(out)]) == 0
    by = json.loads(out.read_text())["by_correction"]
    assert list(by) == ["fit"] and by["fit"]["covered"] == 1     # no report: the override fine=false says "fit"
    out.unlink()
    capsys.readouterr()
    assert dchfrac(["discrepancy", "coverage", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no summary.json" in err and not out.exists()

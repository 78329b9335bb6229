"""CLI conventions: --version, -v / -q through logging, progress (bar on a terminal, plain lines
otherwise, % of t_end and ETA), `dchfrac params`, `run --help` naming what --set accepts."""
from __future__ import annotations

import io
import logging
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import pytest

import solver
from solver import Parameters, RunOptions
from solver.params import field_unit
from solver.progress import StepProgress
from sweep.cli import build_parser, main
from sweep.campaign.logs import end_logging, level_of, setup_logging
from importlib.metadata import version as _dist_version

ROOT = Path(__file__).resolve().parents[1]


def test_version_names_the_version_the_code_hash_and_the_active_path(capsys, monkeypatch):
    from solver.paths import describe

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip().splitlines() == [
        f"dchfrac {_dist_version('dchfrac')} (code {solver.code_hash()})", describe()]
    monkeypatch.setattr(solver, "code_hash", lambda: "abc123", raising=False)
    monkeypatch.setenv("DCHFRAC_LINEAR_SOLVER", "superlu")
    with pytest.raises(SystemExit):
        main(["--version"])
    out = capsys.readouterr().out.strip().splitlines()
    assert out[0] == f"dchfrac {_dist_version('dchfrac')} (code abc123)"
    assert out[1].startswith("linear solver superlu") and "DCHFRAC_LINEAR_SOLVER=superlu" in out[1]


def test_verbosity_levels_and_flags_anywhere():
    assert [level_of(0, 0), level_of(1, 0), level_of(0, 1), level_of(0, 2)] == \
        [logging.INFO, logging.DEBUG, logging.WARNING, logging.ERROR]
    ap = build_parser()
    a = ap.parse_args(["-q", "campaign", "status", "x.toml"])
    b = ap.parse_args(["campaign", "status", "x.toml", "-q"])
    c = ap.parse_args(["run", "--out", "r", "-vv"])
    assert (a.less, a.verbose, b.less, b.verbose, c.verbose) == (1, 0, 1, 0, 2)


def test_quiet_keeps_warnings_and_drops_info():
    buf = io.StringIO()
    setup_logging(quiet=1, stream=buf)
    try:
        logging.getLogger("dchfrac.campaign").info("progress line")
        logging.getLogger("dchfrac.solver").warning("a warning")
    finally:
        end_logging()
    assert "a warning" in buf.getvalue() and "progress line" not in buf.getvalue()


class _Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_progress_lines_off_a_terminal_give_percent_and_eta(caplog):
    clock = _Clock()
    p = StepProgress(2.0, stream=io.StringIO(), tty=False, every_s=10.0, clock=clock, min_steps=2, min_fraction=0.05)
    with caplog.at_level(logging.INFO, logger="dchfrac.solver"):
        clock.now += 60.0  # set-up and first step (a compilation): not in the rate
        p.update(0.1, "dt = 1e-3 s")  # the first report: no rate yet
        clock.now += 10.0
        p.update(0.5)  # 10 s for 0.4 s simulated: 1.5 s left, 37.5 s
        clock.now += 1.0
        p.update(0.6)  # within every_s of the last line: no line
        clock.now += 19.0
        p.update(1.5)  # 30 s for 1.4 s: 0.5 s left, 10.7 s
        p.close()
    lines = [r.getMessage().strip() for r in caplog.records if r.name == "dchfrac.solver"]
    assert lines == ["5.0% t = 0.1 of 2 s, elapsed 1m00s, ETA -- | dt = 1e-3 s",
                     "25.0% t = 0.5 of 2 s, elapsed 1m10s, ETA 0m38s",
                     "75.0% t = 1.5 of 2 s, elapsed 1m30s, ETA 0m11s"]


def test_progress_shows_no_eta_before_enough_steps_and_simulated_time():
    clock = _Clock()
    p = StepProgress(2.0, stream=io.StringIO(), tty=False, clock=clock)  # defaults: 5 reports, 5 % of t_end
    t = 0.0
    for k in range(4):  # 4 reports: too few, whatever the fraction
        clock.now += 20.0
        t += 0.2
        p.update(t)
        assert "ETA --" in p.line(t)
    p = StepProgress(2.0, stream=io.StringIO(), tty=False, clock=clock)
    for k in range(10):  # many tiny first steps: below 5 % of t_end
        clock.now += 20.0
        p.update(1e-3 * (k + 1))
    assert "ETA --" in p.line(1e-2)
    assert p.eta(1e-2) != p.eta(1e-2)  # NaN


def test_progress_bar_on_a_terminal_redraws_in_place():
    clock, out = _Clock(), io.StringIO()
    p = StepProgress(1.0, stream=out, tty=True, width=10, clock=clock, min_steps=2)
    clock.now += 4.0
    p.update(0.25)
    clock.now += 4.0
    p.update(0.5)
    p.close()
    text = out.getvalue()
    assert "\r[#####-----]  50.0% t = 0.5 of 1 s" in text and "ETA 0m08s" in text and text.endswith("\n")
    assert text.startswith("\r[##--------]  25.0%") and "ETA --" in text.split("\r")[1]


def test_run_writes_no_carriage_return_when_not_on_a_terminal(tmp_path):
    r = subprocess.run([sys.executable, "-m", "sweep.cli", "run", "--out", str(tmp_path / "run"), "--h", "4",
                        "--t-end", "0.02"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "\r" not in r.stderr and "100.0% t = 0.02 of 0.02 s" in r.stderr and "ETA" in r.stderr
    assert r.stdout.startswith("status: ok")
    q = subprocess.run([sys.executable, "-m", "sweep.cli", "-q", "run", "--out", str(tmp_path / "run2"), "--h", "4",
                        "--t-end", "0.02"], capture_output=True, text=True, cwd=ROOT)
    # -q leaves warnings only (here: l_S = 4 mm below 2 h at h = 4), no progress
    assert q.returncode == 0 and "ETA" not in q.stderr and "%" not in q.stderr and q.stdout.startswith("status: ok")
    assert all("warning" in line for line in q.stderr.splitlines())


def test_params_lists_every_parameter_with_unit_default_and_range(capsys):
    assert main(["params"]) == 0
    out = capsys.readouterr().out
    assert "``" not in out and ":func:" not in out  # plain text, wrapped to the terminal
    rows, last = {}, None
    for ln in out.splitlines():
        if ln.startswith(" ") and last:  # a wrapped meaning continues its row
            rows[last] += " " + ln.strip()
        elif ln and not ln.startswith(("model", "run", "name")):
            last = ln.split()[0]
            rows[last] = ln
    for f in fields(Parameters):
        line = rows[f.name]
        unit = field_unit(f.name)
        assert (unit in line.split()) if unit else True
        assert str(f.default) in line
    assert "> 0" in rows["eta_o"] and "(-1, 0.5)" in rows["nu"]
    assert all(f.name in rows for f in fields(RunOptions))


def test_run_help_lists_what_set_accepts(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.replace(",", " ").split())
    words = set(text.split())
    assert {f.name for f in fields(Parameters)} <= words and {f.name for f in fields(RunOptions)} <= words


def test_every_run_option_declares_its_unit_and_meaning():
    """A new run option needs its unit in solver.options.OPTION_UNITS and a line in the RunOptions docstring."""
    from solver.options import OPTION_UNITS, option_docs

    names = {f.name for f in fields(RunOptions)}
    assert set(OPTION_UNITS) == names
    assert {n for n, d in option_docs().items() if d} >= names


def _every_parser(p):
    """``p`` and every parser below it, group parsers included (their help lists their commands' help)."""
    import argparse

    yield p
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for child in dict.fromkeys(a.choices.values()):
                yield from _every_parser(child)


def test_every_command_s_help_renders():
    """argparse %-formats help strings: a bare "%" (as in "95 % interval") breaks --help of the command's group."""
    from sweep.cli import build_parser

    parsers = list(_every_parser(build_parser()))
    assert len(parsers) > 30
    for p in parsers:
        assert p.format_help(), p.prog

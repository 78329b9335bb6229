"""The fallback path (SuperLU and numpy kernels), forced by its environment variables, solves the same problem as
the fast path (PARDISO and numba kernels), and invalid values of the variables are refused.

The fast path is the default of an install that follows the README; CI runs the whole suite on it.  This module
runs a short coarse solve in fresh processes (the variables are read when the process picks its path) with
``DCHFRAC_LINEAR_SOLVER=superlu DCHFRAC_KERNELS=numpy`` and with the defaults, and compares them.

Tolerance, from the method: every step's Newton stops when each field's update is below ``newton_rtol`` of the
field's scale (max |p| for the pressure; a reused Jacobian's linear convergence is tightened to keep the error
below that), so the two paths' states differ by at most about newton_rtol × max|p| per step, and backward Euler
does not amplify the difference: |Δp_inj| <= n_steps × newton_rtol × max|p|.  The step sequences are the same
(the state-change controller reads the accepted states, equal to that tolerance), which is checked too.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from solver import kernels, paths
from sweep.cli import main

ROOT = Path(__file__).resolve().parent.parent

_CHILD = """
import json, sys
from solver import Parameters, RunOptions, simulate
o = RunOptions(h=4.0, t_end=0.02, snapshot_times=[], write_xdmf=False)
res = simulate(Parameters(), o, out_dir=sys.argv[1])
ts = res.timeseries
print(json.dumps({"status": res.status, "path": res.path, "rtol": o.newton_rtol, "t": ts["t"].tolist(),
                  "p_inj": ts["p_inj"].tolist(), "p_max": float(abs(res.snapshots[-1][1]["p"]).max())}))
"""

FALLBACK = {"DCHFRAC_LINEAR_SOLVER": "superlu", "DCHFRAC_KERNELS": "numpy"}


def _solve(out: Path, **env) -> dict:
    e = {k: v for k, v in os.environ.items() if k not in FALLBACK}
    e.update(env, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cp = subprocess.run([sys.executable, "-c", _CHILD, str(out)], capture_output=True, text=True, env=e, cwd=ROOT,
                        check=True)
    return json.loads(cp.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    base = tmp_path_factory.mktemp("paths")
    return _solve(base / "fast"), _solve(base / "fallback", **FALLBACK), base


def test_fallback_solve_agrees_with_the_fast_path_within_the_newton_tolerance(both):
    fast, slow, _ = both
    assert fast["status"] == slow["status"] == "ok"
    assert slow["path"]["linear_solver"] == "superlu" and slow["path"]["kernels"] == "numpy"
    if paths.available_backends()[-1] == "pypardiso":
        assert fast["path"]["linear_solver"] == "pypardiso"
    if kernels.numba_available():
        assert fast["path"]["kernels"] == "numba"
    assert len(fast["t"]) == len(slow["t"])
    np.testing.assert_allclose(fast["t"], slow["t"], rtol=1e-6)
    bound = len(fast["t"]) * fast["rtol"] * max(fast["p_max"], slow["p_max"])
    assert np.max(np.abs(np.subtract(fast["p_inj"], slow["p_inj"]))) <= bound


def test_summary_records_the_path_that_ran(both):
    fast, slow, base = both
    for name, run in (("fast", fast), ("fallback", slow)):
        summary = json.loads((base / name / "summary.json").read_text())
        assert summary["path"] == run["path"]
        assert set(summary["path"]) == {"linear_solver", "linear_precision", "kernels"}


@pytest.mark.parametrize("var", ["DCHFRAC_LINEAR_SOLVER", "DCHFRAC_KERNELS"])
def test_invalid_path_variables_are_refused_with_one_line_naming_the_variable(var, monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(var, "mumps")
    with pytest.raises(ValueError, match=f"{var}='mumps' is not allowed"):
        paths.check_environment()
    assert main(["run", "--out", str(tmp_path / "run"), "--h", "4", "--t-end", "0.01"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and var in err and "'mumps'" in err
    assert not (tmp_path / "run").exists()


def test_forced_fallback_is_named_by_version_and_describe(monkeypatch):
    for k, v in FALLBACK.items():
        monkeypatch.setenv(k, v)
    assert paths.active_path() == {"linear_solver": "superlu", "kernels": "numpy", "fast": False}
    text = paths.describe()
    assert "DCHFRAC_LINEAR_SOLVER=superlu" in text and "DCHFRAC_KERNELS=numpy" in text and "fallback" in text
    cp = subprocess.run([sys.executable, "-m", "sweep.cli", "--version"], capture_output=True, text=True, cwd=ROOT,
                        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert cp.returncode == 0 and "superlu" in cp.stdout and "numpy" in cp.stdout

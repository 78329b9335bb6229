"""The run estimate (solver/budget.py): node and element counts against real meshes, the memory refusal (before any
work, one line naming h, the estimate and the memory available), and the wall time on the path that will run."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from solver import Parameters, RunOptions, budget, mesh
from solver.mesh import annulus_mesh
from sweep.cli import main

MESHES = [dict(h=8.0), dict(h=4.0), dict(h=2.0), dict(h=4.0, h_inner=1.0), dict(h=2.0, h_outer=0.5),
          dict(h=4.0, h_inner=0.5, grading_length=10.0, h_outer=1.0), dict(h=3.0, h_inner=0.25)]


@pytest.mark.parametrize("kw", MESHES, ids=lambda kw: ",".join(f"{k}={v}" for k, v in kw.items()))
def test_node_and_element_counts_match_the_real_meshes_within_the_stated_tolerance(kw):
    m = annulus_mesh(5.0, 53.0, kw["h"], h_inner=kw.get("h_inner"), grading_length=kw.get("grading_length", 5.0),
                     h_outer=kw.get("h_outer"))
    nodes, elements = budget.mesh_counts(kw["h"], kw.get("h_inner"), kw.get("grading_length"), kw.get("h_outer"))
    assert abs(nodes / m.n_nodes - 1) <= budget.COUNT_TOLERANCE
    assert abs(elements / m.n_elements - 1) <= budget.COUNT_TOLERANCE


def test_counts_scale_as_the_inverse_square_of_h():
    n1, _ = budget.mesh_counts(0.01)
    n2, _ = budget.mesh_counts(0.005)
    assert n2 / n1 == pytest.approx(4.0, rel=1e-3)  # the boundary term (1/h) is negligible this fine


def _no_mesh(*a, **k):
    raise AssertionError("the refusal must come before any mesh is built")


def test_run_that_cannot_fit_is_refused_in_one_line_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(mesh, "annulus_mesh", _no_mesh)
    monkeypatch.setattr(budget, "_measure_iteration", _no_mesh)
    out = tmp_path / "run"
    assert main(["run", "--out", str(out), "--h", "0.0001"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "h=0.0001" in err and "available" in err and "GB" in err and "--force" in err
    assert not out.exists()
    with pytest.raises(ValueError, match="h=0.0001 cannot fit"):
        from solver import simulate

        simulate(Parameters(), RunOptions(h=0.0001))


#: libraries a refusal does not need (each takes a fraction of a second to a second or more to import)
HEAVY = ("numba", "pypardiso", "scipy.sparse", "scipy.sparse.linalg", "scipy.spatial", "scipy.ndimage", "pandas",
         "matplotlib")


def test_the_refusal_comes_before_the_heavy_libraries_load(tmp_path):
    """``dchfrac run --h 0.0001`` in a fresh interpreter: refused (exit 2, one line naming h, the estimate and the
    memory available) with none of ``HEAVY`` imported, so that the answer is a fraction of a second of CPU."""
    code = ("import sys\nfrom sweep.cli import main\nrc = main(sys.argv[1:])\n"
            f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules) or 'none')\nsys.exit(rc)")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    r = subprocess.run([sys.executable, "-c", code, "run", "--out", str(tmp_path / "run"), "--h", "0.0001"],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip()
    assert err.count("\n") == 0 and "h=0.0001 cannot fit" in err and "nodes" in err and "available" in err, err
    assert r.stdout.split() == ["none"], f"imported before the refusal: {r.stdout}"
    assert not (tmp_path / "run").exists()


def test_memory_estimate_grows_with_the_unknowns_and_refuses_against_the_available_memory(monkeypatch):
    small = budget.check_fits(Parameters(), RunOptions(h=2.0))
    assert small.fits() and small.memory_bytes > budget.BASE_BYTES
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: small.memory_bytes * 0.99)
    with pytest.raises(ValueError, match=r"h=2\.0 cannot fit: the run needs about .* GB .* available"):
        budget.check_fits(Parameters(), RunOptions(h=2.0))


def test_wall_time_follows_the_calibrated_path_and_the_calibration_is_measured_once(tmp_path, monkeypatch):
    monkeypatch.setenv("DCHFRAC_CACHE", str(tmp_path))
    calls = []

    def fake(h=2.0):
        calls.append(h)
        return 0.1  # s per Newton iteration at h = 2 mm on this "machine"

    monkeypatch.setattr(budget, "_measure_iteration", fake)
    monkeypatch.setenv("DCHFRAC_LINEAR_SOLVER", "superlu")
    e2 = budget.estimate_run(Parameters(), RunOptions(h=2.0, t_end=2.0))
    e1 = budget.estimate_run(Parameters(), RunOptions(h=1.0, t_end=2.0))
    assert calls == [2.0] and e2.linear_solver == e1.linear_solver == "superlu"
    ref = budget.REFERENCE["newton_iteration_s"]["superlu"]
    factor = 0.1 / ref[0]
    # at the calibration size the rate is the measured iteration times the iterations per simulated second
    assert e2.wall_s == pytest.approx(factor * budget.REFERENCE["per_run_overhead_s"]
                                      + 2.0 * budget.ITERATIONS_PER_SIM_S * 0.1, rel=1e-3)
    assert e1.wall_s / e2.wall_s == pytest.approx(ref[1] / ref[0], rel=0.1)
    assert "about" in e1.line() and "superlu" in e1.line()


def test_reference_rates_are_those_of_the_committed_bench_json():
    import json
    from pathlib import Path

    bench = json.loads((Path(__file__).resolve().parents[1] / "results" / "bench" / "bench.json").read_text())
    ref = budget.REFERENCE
    assert [it["unknowns"] for it in bench["newton_iteration"]] == list(ref["unknowns"])
    for ls, times in ref["newton_iteration_s"].items():
        for it, t in zip(bench["newton_iteration"], times):
            if t is not None:
                assert it["backends"][ls]["newton_iteration_s"] == pytest.approx(t, rel=1e-3)
    assert bench["coupled_run_h2_wall_s_per_sim_s"] == pytest.approx(ref["reference_run_h2_wall_s_per_sim_s"], rel=1e-3)
    assert bench["per_run_overhead_s"] == pytest.approx(ref["per_run_overhead_s"], rel=1e-2)


def test_campaign_dry_run_shows_each_mesh_size_budget_and_flags_the_runs_that_cannot_fit(tmp_path, monkeypatch, capsys):
    """``campaign run --dry-run``: per distinct mesh, one run's nodes and peak memory against the memory available
    (solver.budget), the runs' wall time on the calibrated path, the refused mesh (cannot fit) and the one that
    cannot fit ``--jobs`` runs side by side; nothing is run or measured beyond the (faked) calibration."""
    from solver.progress import format_duration
    from sweep.campaign.cli import main as campaign_main

    factor = 3.0
    monkeypatch.setattr(budget, "calibration", lambda ls, kern: {"factor": factor})
    monkeypatch.setattr(mesh, "annulus_mesh", _no_mesh)
    mem4 = budget.memory_bytes(budget.N_FIELDS * budget.mesh_counts(4.0)[0], *budget._path())
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: 1.5 * mem4)  # one h = 4 run fits, two do not
    spec = tmp_path / "c.toml"
    spec.write_text('name = "c"\n[base]\nw_i = 10.0\n[options]\nt_end = 0.5\n[axes]\nh = [4.0, 0.01]\n'
                    "cement = [1.0, 2.0]\n")
    assert campaign_main(["run", str(spec), "--dry-run", "--jobs", "2", "--results", str(tmp_path / "res")]) == 0
    out = capsys.readouterr().out
    assert not (tmp_path / "res" / "c" / "runs").exists()
    for h in (4.0, 0.01):
        est = budget.estimate_run(Parameters(), RunOptions(h=h, t_end=0.5), calibrate=False)
        wall = 2 * budget.wall_time_s(est.unknowns, 0.5, est.linear_solver, factor)
        assert (f"h = {h:g} mm: 2 run(s), 1 simulated s, {format_duration(wall)} of wall time alone; each "
                f"{est.nodes:,} nodes") in out
    assert "REFUSED: the 2 run(s) at h = 0.01 mm cannot fit" in out and "REFUSED: the 2 run(s) at h = 4 mm" not in out
    assert "WARNING: 2 runs at h = 4 mm side by side" in out

"""``dchfrac bench``: performance figures of the solver, written as JSON.

Measured (wall-clock seconds, this machine):
* one Newton iteration at h = 2, 1, 0.5 mm split into residual+Jacobian
  assembly (on 1 thread and on every core; compiled or numpy kernels,
  ``solver.kernels``), factorization and solve, for the default backend and SuperLU;
* a 0.2 s coupled run at h = 2 mm (0.05 s with ``--quick``; assembly on every core) (wall time, accepted
  steps, factorizations per accepted step, wall seconds per simulated second);
* the reference case at h = 2 mm to 2 s (not with ``--quick``);
* optionally the paper's reference run (h = 1 mm to 2 s);
* the cost rates ``coupled_run_h{h}_wall_s_per_sim_s`` (the h = 2 one is ``solver.budget.REFERENCE``'s iterations
  per simulated second, over the Newton iteration), from the longest run made at each h: a campaign run lasts seconds of simulated time, and the short run's rate is
  the start-up's, whose small steps cost several times more per simulated second;
* ``shared_run_factor``: how much longer the h = 2 reference case takes with one run per core, each in a campaign
  worker's environment (one BLAS, MKL and OpenMP thread), than alone with every core: the dry run's factor for
  more than one job (not with ``--quick``);
* with ``--profile`` (:func:`run_profile`): the reference run's wall time split by phase (assembly,
  symbolic and numeric factorization, solves, damage solve, stagger, metrics, output, Python) and by
  part of the run (t < 0.05 s against the rest), from the run's own accumulators
  (:mod:`solver.profiling`), with the h = 1 mm refactorization time measured beside it.
Speed is measured here, never by timed tests.
"""
from __future__ import annotations

import json
import logging
import os
import platform
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

LOG = logging.getLogger("dchfrac.bench")


def _best(fn, repeats: int = 3) -> float:
    """Best wall time (s) of ``repeats`` calls after one warm-up call (compiled kernels, caches, pools)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


@contextmanager
def _assembly_threads(n: int):
    """Set DCHFRAC_ASSEMBLY_THREADS to ``n`` inside the block (solver.paths.assembly_threads)."""
    old = os.environ.get("DCHFRAC_ASSEMBLY_THREADS")
    os.environ["DCHFRAC_ASSEMBLY_THREADS"] = str(n)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("DCHFRAC_ASSEMBLY_THREADS")
        else:
            os.environ["DCHFRAC_ASSEMBLY_THREADS"] = old


def newton_state(h: float) -> dict:
    """The state every Newton-iteration benchmark uses: the reference parameters on the annulus of mesh size
    h mm, a displacement of 1e-3 mm noise, a pressure falling linearly from 200 kPa at r_i to 0 at r_o, an
    invaded zone S = 1 to 5 mm beyond r_i, and the step data of a 10 ms step.  Returns p (Parameters), disc, U
    (nodes x fields), data and the set-up times mesh_s and setup_s (s)."""
    from solver import Parameters
    from solver.mesh import annulus_mesh
    from solver.model import build_discretization, step_data
    from solver.porosity import random_porosity

    p = Parameters()
    t0 = time.perf_counter()
    mesh = annulus_mesh(p.r_inner, p.r_outer, h)
    t_mesh = time.perf_counter() - t0
    t0 = time.perf_counter()
    disc = build_discretization(mesh, p, random_porosity(mesh, seed=0))
    t_setup = time.perf_counter() - t0
    N, nf = disc.n_nodes, disc.n_fields
    rng = np.random.default_rng(0)
    r = np.hypot(*disc.points.T)
    U = np.zeros((N, nf))
    U[:, 0:2] = 1e-3 * rng.standard_normal((N, 2))
    U[:, 2] = 200 * (p.r_outer - r) / (p.r_outer - p.r_inner)
    U[:, 3] = np.clip(1.5 - (r - p.r_inner) / 10, 0, 1)
    data = step_data(disc, p, 0.99 * U, np.zeros(N), 1e-2)
    return {"p": p, "disc": disc, "U": U, "data": data, "mesh_s": t_mesh, "setup_s": t_setup}


def _newton_iteration(h: float, backends) -> dict:
    from solver import kernels, linsolve
    from solver.model import residual_and_jacobian

    st = newton_state(h)
    p, disc, U, data, t_mesh, t_setup = (st[k] for k in ("p", "disc", "U", "data", "mesh_s", "setup_s"))
    N, nf = disc.n_nodes, disc.n_fields
    t_res = _best(lambda: residual_and_jacobian(disc, p, U, data, need_jacobian=False))
    # assembly on 1 thread (what each solver of a campaign gets) and on every core (a single run; the
    # PARDISO factorization below uses every core too): best of 3 after a warm-up call
    threads = sorted({1, os.cpu_count() or 1})
    t_threads = {}
    for n in threads:
        with _assembly_threads(n):
            t_threads[n] = _best(lambda: residual_and_jacobian(disc, p, U, data))
    t_asm, t_asm_par = t_threads[1], t_threads[threads[-1]]
    R, J = residual_and_jacobian(disc, p, U, data)
    disc.dirichlet.apply_matrix(J)
    out = {"h_mm": h, "nodes": N, "elements": len(disc.triangles), "unknowns": N * nf, "jacobian_nnz": int(J.nnz),
           "mesh_s": t_mesh, "setup_s": t_setup, "kernels": kernels.backend(), "residual_s": t_res,
           "residual_and_jacobian_s": t_asm, "residual_and_jacobian_s_by_threads": t_threads, "backends": {}}
    for kind in backends:
        if kind == "superlu" and len(backends) > 1 and N * nf > 150_000:
            out["backends"][kind] = {"skipped": "SuperLU above 150,000 unknowns takes minutes and GBs; measured only below"}
            continue
        t0 = time.perf_counter()
        f = linsolve.factorize(J, kind, condense=disc.projection_dofs)
        t_first = time.perf_counter() - t0
        # a second factorization of the same pattern: what every Newton iteration after the first pays
        # (PARDISO reuses its symbolic analysis; SuperLU redoes everything)
        t0 = time.perf_counter()
        f = linsolve.factorize(J, kind, condense=disc.projection_dofs)
        t_fac = time.perf_counter() - t0
        t0 = time.perf_counter()
        f.solve(R)
        t_sol = time.perf_counter() - t0
        total = t_asm + t_fac + t_sol
        total_par = t_asm_par + t_fac + t_sol
        out["backends"][kind] = {"factorize_first_s": t_first, "factorize_s": t_fac, "solve_s": t_sol, "newton_iteration_s": total,
                                 "assembly_fraction": t_asm / total,
                                 f"newton_iteration_s_{threads[-1]}_threads": total_par,
                                 f"assembly_fraction_{threads[-1]}_threads": t_asm_par / total_par}
    return out


def _coupled_run(h: float, t_end: float) -> dict:
    """The reference experiment (Parameters() defaults: C = 1.2 %, random porosity) at mesh size h to t_end."""
    from solver import Parameters, RunOptions, simulate

    threads = os.cpu_count() or 1  # a single run: assembly on every core, as the factorization
    with _assembly_threads(threads):
        res = simulate(Parameters(), RunOptions(h=h, t_end=t_end, snapshot_times=[]))
    n = len(res.timeseries)
    return {"h_mm": h, "t_end_s": t_end, "assembly_threads": threads, "status": res.status, "wall_s": res.wall_time, "accepted_steps": n,
            "rejected_steps": len(res.rejected_steps), "factorizations": res.factorizations,
            "factorizations_per_step": res.factorizations / max(n, 1),
            "wall_s_per_sim_s": res.wall_time / t_end,
            "p_inj_end_kPa": float(res.timeseries["p_inj"].iloc[-1]) if n else None}


_SHARED_CHILD = """
import json, sys, time
from solver import Parameters, RunOptions, simulate
res = simulate(Parameters(), RunOptions(h=float(sys.argv[1]), t_end=float(sys.argv[2]), snapshot_times=[]))
print(json.dumps({"status": res.status, "wall_s": res.wall_time}))
"""


def _shared_run(h: float, t_end: float) -> dict:
    """The reference case at mesh size h (mm) to t_end (s) as a campaign with one job per core runs it: one
    fresh process per core at once, each with the worker's thread environment (``sweep.campaign.scheduler``: one BLAS,
    MKL and OpenMP thread, one assembly thread); the mean of their solver wall times (s)."""
    import subprocess
    import sys

    from sweep.campaign.scheduler import ExecConfig, child_env

    n = os.cpu_count() or 1
    env = child_env(ExecConfig(root=".", campaign="bench", runner=None, blas_threads=1))
    env["DCHFRAC_ASSEMBLY_THREADS"] = "1"
    procs = [subprocess.Popen([sys.executable, "-c", _SHARED_CHILD, str(h), str(t_end)], stdout=subprocess.PIPE,
                              text=True, env=env, cwd=Path(__file__).resolve().parents[2]) for _ in range(n)]
    outs = [_child_result(p.communicate()[0]) for p in procs]
    ok = [o["wall_s"] for o in outs if o["status"] == "ok"]
    return {"h_mm": h, "t_end_s": t_end, "jobs": n, "status": "ok" if len(ok) == n else "failed",
            "wall_s": float(np.mean(ok)) if ok else None,
            "wall_s_per_sim_s": float(np.mean(ok)) / t_end if ok else None}


def _child_result(stdout: str) -> dict:
    """The JSON line a bench child prints last, or a failed status when it printed none (it crashed)."""
    lines = (stdout or "").strip().splitlines()
    try:
        return json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        return {"status": "failed", "wall_s": None}


def _refactorization_h1() -> dict:
    """The h = 1 mm refactorization time (s) of the default backend on this machine, now: the yardstick
    stated beside every absolute figure (machines of the same kind differ by 1.6-2.4x)."""
    from solver import paths

    kind = paths.resolve("auto", 10**6)
    it = _newton_iteration(1.0, [kind])
    return {"backend": kind, "refactorization_s": it["backends"][kind]["factorize_s"],
            "solve_s": it["backends"][kind]["solve_s"], "residual_and_jacobian_s": it["residual_and_jacobian_s"]}


def profiled_run(h: float, t_end: float = 2.0, options: dict | None = None, model: dict | None = None) -> dict:
    """The reference case at mesh size h (mm) to t_end (s) with its wall time split by phase and part of the
    run (``SimulationResult.profile``, :mod:`solver.profiling`), plus the run's own figures.  ``options``: other
    RunOptions of the run (e.g. ``{"anderson_depth": 3}``); ``model``: the parameters as ``{"preset": name or
    None, "changes": {...}}`` (default: ``Parameters()``, the reference case)."""
    from solver import Parameters, RunOptions, simulate
    from solver.presets import preset_changes

    model = model or {}
    params = Parameters.from_dict({**(preset_changes(model["preset"]) if model.get("preset") else {}),
                                   **model.get("changes", {})})
    threads = os.cpu_count() or 1
    with _assembly_threads(threads):
        res = simulate(params, RunOptions(**{**(options or {}), "h": h, "t_end": t_end, "snapshot_times": []}))
    n = len(res.timeseries)
    return {"h_mm": h, "t_end_s": t_end, "options": dict(options or {}), "model": dict(model),
            "assembly_threads": threads,
            "kernels": _kernels(), "status": res.status,
            "newton_iterations": int(res.timeseries["newton_its"].sum()) if n else 0,
            "wall_s": res.wall_time, "accepted_steps": n, "rejected_steps": len(res.rejected_steps),
            "factorizations": res.factorizations,
            "p_inj_end_kPa": float(res.timeseries["p_inj"].iloc[-1]) if n else None, "profile": res.profile,
            # the injection-pressure curve, to check that a faster solver gives the same physics
            "p_inj_curve": {"t_s": res.timeseries["t"].tolist() if n else [],
                            "p_inj_kPa": res.timeseries["p_inj"].tolist() if n else []}}


_OVERHEAD_CHILD = """
import json, sys, tempfile, time
t0 = time.perf_counter()
from sweep.campaign.scheduler import DefaultRunner
from solver import Parameters, RunOptions
with tempfile.TemporaryDirectory() as d:
    opts = RunOptions(h=float(sys.argv[1]), t_end=1e-3, dt0=1e-3, snapshot_times=[]).to_dict()
    out = DefaultRunner()(Parameters().to_dict(), opts, d)
print(json.dumps({"child_s": time.perf_counter() - t0, "solver_s": out["metrics"]["solver_wall_time_s"]}))
"""


def per_run_overhead(h: float = 2.0) -> dict:
    """Fixed wall seconds of one campaign run besides its time loop (the dry-run estimate's per-run term,
    ``sweep.campaign.cost.per_run_overhead``): a fresh process runs one 1 ms step at mesh size h (mm) through
    the campaign runner (imports, mesh and set-up, first factorization, classification, run folder);
    everything counts but the step's share of a long run's time loop, which the per-simulated-second
    figure already holds, so the overhead is the whole child's wall time."""
    import subprocess
    import sys

    t0 = time.perf_counter()
    cp = subprocess.run([sys.executable, "-c", _OVERHEAD_CHILD, str(h)], capture_output=True, text=True, check=True,
                        cwd=Path(__file__).resolve().parents[2])
    wall = time.perf_counter() - t0
    child = json.loads(cp.stdout.strip().splitlines()[-1])
    return {"h_mm": h, "per_run_overhead_s": wall, "child_inner_s": child["child_s"], "solver_wall_s": child["solver_s"]}


def _kernels() -> str:
    from solver import kernels

    return kernels.backend()


def run_profile(out_path, sizes=(2.0,), t_end: float = 2.0, options: dict | None = None,
                compare: dict | None = None, model: dict | None = None) -> dict:
    """``dchfrac bench --profile``: profiled reference runs at each mesh size of ``sizes`` (mm) to ``t_end`` (s),
    with the run options ``options`` (default none) and the model ``model`` (:func:`profiled_run`; default the
    reference case), and the h = 1 refactorization time measured in the same
    process; written as JSON to ``out_path``.  With ``compare`` (run options of a variant) each size is run as
    base, variant, base, variant, side by side in time, and ``comparisons`` holds the variant's wall time over the
    base's (sums of the pairs) and the relative change of p_inj at t_end."""
    from solver import paths
    from solver.paths import active_path, describe

    result = {"machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(), "platform": platform.platform(),
                          "load_average_1_5_15": list(os.getloadavg()) if hasattr(os, "getloadavg") else None},
              "backend": paths.resolve("auto", 10**6), "active_path": active_path(), "runs": []}
    print(f"bench: {describe()}", flush=True)
    print("bench: h = 1 mm refactorization (yardstick) ...", flush=True)
    result["h1_refactorization"] = _refactorization_h1()
    for h in sizes:
        print(f"bench: profiled reference run h = {h:g} mm to {t_end:g} s ...", flush=True)
        if compare is None:
            result["runs"].append(profiled_run(h, t_end, options, model))
            _write_json(out_path, result)  # each finished run is kept, should a later (longer) one not finish
            continue
        pair = [profiled_run(h, t_end, {**(options or {}), **(compare if k % 2 else {})}, model) for k in range(4)]
        result["runs"] += pair
        result.setdefault("comparisons", []).append(_comparison(h, compare, pair[0::2], pair[1::2]))
        print(json.dumps(result["comparisons"][-1]), flush=True)
        _write_json(out_path, result)
    if hasattr(os, "getloadavg"):
        result["machine"]["load_average_after"] = list(os.getloadavg())
    _write_json(out_path, result)
    print(json.dumps({r["h_mm"]: r["profile"]["total"]["seconds"] for r in result["runs"]}, indent=2))
    return result


def _comparison(h: float, variant: dict, base: list, other: list) -> dict:
    """The variant's runs against the base's at mesh size h (mm): wall-time ratio of the sums, p_inj at the end
    (kPa) and its relative change, Newton iterations and factorizations of each."""
    ok = all(r["status"] == "ok" for r in base + other)
    p0, p1 = base[0]["p_inj_end_kPa"], other[0]["p_inj_end_kPa"]
    return {"h_mm": h, "variant": dict(variant), "status": "ok" if ok else "failed",
            "wall_s_base": [r["wall_s"] for r in base], "wall_s_variant": [r["wall_s"] for r in other],
            "wall_ratio": sum(r["wall_s"] for r in other) / sum(r["wall_s"] for r in base) if ok else None,
            "p_inj_end_kPa": [p0, p1], "p_inj_end_rel_change": abs(p1 - p0) / abs(p0) if ok and p0 else None,
            "newton_iterations": [base[0]["newton_iterations"], other[0]["newton_iterations"]],
            "factorizations": [base[0]["factorizations"], other[0]["factorizations"]]}


def _write_json(out_path, result: dict) -> None:
    from sweep.campaign.store import write_json_atomic

    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, result)


def _cost_rates(result: dict) -> None:
    """The dry-run cost rates, wall s per simulated s at h = 2 and 1 mm, from the longest run at each h."""
    for h, runs in ((2, ("reference_run_h2", "coupled_run_h2")), (1, ("reference_run_h1",))):
        run = next((result[k] for k in runs if k in result and result[k].get("status") == "ok"), None)
        if run is not None:
            result[f"coupled_run_h{h}_wall_s_per_sim_s"] = run["wall_s_per_sim_s"]
            result[f"coupled_run_h{h}_wall_s_per_sim_s_from"] = f"{run['t_end_s']:g} s run at h = {h} mm"
    alone, shared = result.get("reference_run_h2", {}), result.get("shared_run_h2", {})
    if alone.get("status") == "ok" and shared.get("status") == "ok":
        result["shared_run_factor"] = shared["wall_s_per_sim_s"] / alone["wall_s_per_sim_s"]


def run_benchmarks(out_path, quick: bool = False, reference: bool = False) -> dict:
    """Run the benchmarks and write them as JSON to ``out_path``; returns the dict."""
    from solver import paths
    from solver.paths import active_path, describe

    backends = paths.available_backends()
    sizes = [2.0, 1.0] if quick else [2.0, 1.0, 0.5]
    print(f"bench: {describe()}", flush=True)
    result = {"machine": {"python": platform.python_version(), "cpu_count": __import__("os").cpu_count(),
                          "platform": platform.platform()},
              "active_path": active_path(), "backends_available": backends, "newton_iteration": []}
    for h in sizes:
        LOG.info(f"bench: one Newton iteration at h = {h} mm ...")
        result["newton_iteration"].append(_newton_iteration(h, backends))
    t_end = 0.05 if quick else 0.2
    LOG.info(f"bench: coupled run h = 2 mm to {t_end} s ...")
    run = _coupled_run(2.0, t_end)
    result["coupled_run_h2"] = run
    if not quick:
        LOG.info("bench: reference case at h = 2 mm to 2 s ...")
        result["reference_run_h2"] = _coupled_run(2.0, 2.0)
        LOG.info("bench: the same case with one run per core, as a campaign runs it ...")
        result["shared_run_h2"] = _shared_run(2.0, 2.0)
    if reference:
        LOG.info("bench: reference run h = 1 mm to 2 s ...")
        result["reference_run_h1"] = _coupled_run(1.0, 2.0)
    _cost_rates(result)
    print("bench: per-run overhead of a campaign run (h = 2 mm, one step, fresh process) ...", flush=True)
    result["per_run_overhead"] = per_run_overhead(2.0)
    result["per_run_overhead_s"] = result["per_run_overhead"]["per_run_overhead_s"]
    _write_json(out_path, result)
    print(json.dumps(result, indent=2))
    return result

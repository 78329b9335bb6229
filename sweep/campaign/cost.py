"""The dry run's cost estimate of a campaign's runs to do (wall seconds), from ``dchfrac bench`` figures.

    estimate_cost("campaigns/examples/demo.toml", jobs=2)     # {"cpu_s": ..., "wall_s": ..., "by_mesh_size": ...}
    run_budgets(todo_points, jobs=2)     # solver.budget's memory and wall time per run, per distinct mesh
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import _todo, as_spec, plan_campaign

__all__ = ["estimate_cost", "run_budgets", "wall_per_sim_second", "per_run_overhead", "shared_run_factor", "estimated_sim_time",
           "DEFAULT_WALL_S_PER_SIM_S_H2", "COST_MESH_EXPONENT", "DEFAULT_PER_RUN_OVERHEAD_S",
           "DEFAULT_SHARED_RUN_FACTOR"]

# Dry-run cost model: wall seconds per simulated second of one coupled run at mesh size h (mm):
#   c(h) = c2 * (2 / h) ** COST_MESH_EXPONENT,
# c2 from <root>/bench/bench.json key "coupled_run_h2_wall_s_per_sim_s" when present (an exact
# "coupled_run_h{h:g}_wall_s_per_sim_s" key wins), else the placeholder default below. The
# exponent: elements ~ h^-2, sparse direct solves ~ n^1.25 in 2-D -> 2.5.
DEFAULT_WALL_S_PER_SIM_S_H2 = 60.0
COST_MESH_EXPONENT = 2.5
# Plus a fixed cost per run, s, whatever its simulated time: the run's child process and imports, the
# mesh and discretization, the first (symbolic) factorization, classification and writing the run
# folder.  From <root>/bench/bench.json key "per_run_overhead_s" (``dchfrac bench`` measures it) when
# present, else this default: the committed h = 2 campaigns spent 2.0-2.5 s per run outside the
# solver's time loop (wall_time_s - solver_wall_time_s of their tables) plus about 1 s of solver set-up.
DEFAULT_PER_RUN_OVERHEAD_S = 3.0
# With more than one job each run shares the machine (one core, one BLAS/MKL thread each): the rate above,
# measured on a lone run, is multiplied by the factor ``dchfrac bench`` measures with one run per core
# (bench.json key "shared_run_factor"), else by this default (h = 2 reference case, 2-core machine: 20.0 s side
# by side against 13.1 s alone, results/bench/README.md, ninth round).
DEFAULT_SHARED_RUN_FACTOR = 1.5

def _load_bench(root, spec=None) -> dict:
    """``<root>/bench/bench.json``, else the one of the spec's project results (a run into another root, such
    as the README's ``--results runs``, costs what the project's benchmark measured); {} when neither."""
    from sweep.campaign.paths import project_root

    project = project_root(spec.source) if spec is not None else None
    for p in (Path(root) / "bench" / "bench.json", *([project / DEFAULT_ROOT / "bench" / "bench.json"] if project else [])):
        try:
            return json.loads(p.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            continue
    return {}


def wall_per_sim_second(h: float, bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """Estimated wall seconds per simulated second of one coupled run at mesh size ``h`` (mm),
    and where the figure comes from ("bench h=..", "bench h=2 scaled", "default")."""
    bench = bench or {}
    exact = bench.get(f"coupled_run_h{h:g}_wall_s_per_sim_s")
    if isinstance(exact, (int, float)) and exact > 0:
        return float(exact), f"bench h={h:g}"
    c2 = bench.get("coupled_run_h2_wall_s_per_sim_s")
    src = "bench h=2 scaled"
    if not (isinstance(c2, (int, float)) and c2 > 0):
        c2, src = DEFAULT_WALL_S_PER_SIM_S_H2, "default"
    return float(c2) * (2.0 / float(h)) ** COST_MESH_EXPONENT, src


def per_run_overhead(bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """Fixed wall seconds of one campaign run besides its time loop, and where the figure comes from
    ("bench" or "default"); see DEFAULT_PER_RUN_OVERHEAD_S."""
    v = (bench or {}).get("per_run_overhead_s")
    if isinstance(v, (int, float)) and v >= 0:
        return float(v), "bench"
    return DEFAULT_PER_RUN_OVERHEAD_S, "default"


def shared_run_factor(jobs: int, bench: Mapping[str, Any] | None = None) -> tuple[float, str]:
    """How much longer a run takes beside others than alone with every core (1 for one job), and where the
    figure comes from ("one job", "bench" or "default"); see DEFAULT_SHARED_RUN_FACTOR."""
    if jobs <= 1:
        return 1.0, "one job"
    v = (bench or {}).get("shared_run_factor")
    if isinstance(v, (int, float)) and v > 0:
        return float(v), "bench"
    return DEFAULT_SHARED_RUN_FACTOR, "default"


def estimated_sim_time(params: Mapping[str, Any], options: Mapping[str, Any]) -> float:
    """Simulated time of a run, s: t_end, or less when the front should reach stop_front_radius first.

    The front estimate fills the porosity: φ π (r² − r_i²) = 2 π r_i w_i t (per unit gap height),
    so t = φ (r_stop² − r_i²) / (2 r_i w_i).
    """
    t_end = float(options.get("t_end", 2.0))
    r_stop = options.get("stop_front_radius")
    w_i, r_i, phi = params.get("w_i"), params.get("r_inner", 5.0), params.get("phi_mean", 0.4)
    if r_stop is None or not w_i or w_i <= 0 or r_stop <= r_i:
        return t_end
    return min(t_end, phi * (r_stop**2 - r_i**2) / (2.0 * r_i * w_i))


#: the run options and parameters that set a run's mesh and linear solver, hence its memory (solver.budget)
_MESH_KEYS = (("options", "h"), ("options", "h_inner"), ("options", "inner_grading_length"), ("options", "h_outer"),
              ("params", "r_inner"), ("params", "r_outer"), ("options", "linear_solver"))


def run_budgets(points, jobs: int = 1, calibrate: bool = True) -> list[dict]:
    """:mod:`solver.budget`'s estimate of the runs ``points`` (campaign points with ``params`` and ``options``),
    one entry per distinct mesh (``_MESH_KEYS``), in order of h: {"h" (mm), "runs", "estimate" (the
    :class:`solver.budget.Estimate` of one run: nodes, peak memory, memory available, path), "wall_s" (s: the runs' wall times alone, each to
    its :func:`estimated_sim_time`, on the path that will run, calibrated on this machine; None without
    ``calibrate``), "refused" (the runs cannot fit: solver.simulate refuses them), "side_by_side" (``jobs`` runs
    at once cannot fit)}."""
    from solver import Parameters, RunOptions
    from solver.budget import calibration, estimate_run, wall_time_s

    groups: dict[tuple, dict] = {}
    for p in points:
        key = tuple(repr(getattr(p, part).get(name)) for part, name in _MESH_KEYS)
        g = groups.get(key)
        if g is None:
            params, options = Parameters.from_dict(p.params), RunOptions.from_dict(p.options)
            est = estimate_run(params, options, calibrate=False)
            factor = calibration(est.linear_solver, est.kernels)["factor"] if calibrate else None
            g = groups[key] = {"h": options.h, "runs": 0, "estimate": est, "factor": factor,
                               "wall_s": 0.0 if calibrate else None, "refused": not est.fits(),
                               "side_by_side": est.available_bytes is not None
                               and jobs * est.memory_bytes > est.available_bytes}
        g["runs"] += 1
        if calibrate:
            est = g["estimate"]
            g["wall_s"] += wall_time_s(est.unknowns, estimated_sim_time(p.params, p.options), est.linear_solver,
                                       g["factor"])
    return sorted(groups.values(), key=lambda g: -g["h"])


def estimate_cost(spec, root=DEFAULT_ROOT, *, jobs: int = 1, code_hash: str | None = None,
                  retry_failed: bool = False, rerun_stale: bool = False, rerun_archived: bool = False,
                  budget: bool = False) -> dict:
    """Grid size and estimated wall time (s) of the runs to do (pending, damaged, stale unless
    ``rerun_stale``, failed with ``retry_failed``, archived with ``rerun_archived``) of a campaign on ``jobs`` workers.

    Per run: :func:`per_run_overhead` plus :func:`wall_per_sim_second` (bench figures or the documented
    default) times :func:`shared_run_factor` (a run beside others is slower than alone) times
    :func:`estimated_sim_time`; the sum divided by ``jobs`` (perfect packing: a lower bound of the wall time
    when runs differ much in cost). Failed runs count only with ``retry_failed``.  With ``budget``, also
    ``"budget"``: :func:`run_budgets` of the runs to do (memory, refusals, calibrated wall time).
    """
    spec = as_spec(spec)
    root = results_root(spec, root)
    plan = plan_campaign(spec, root, code_hash=code_hash, rerun_stale=rerun_stale)
    bench = _load_bench(root, spec)
    overhead, overhead_src = per_run_overhead(bench)
    shared, shared_src = shared_run_factor(jobs, bench)
    per_h: dict[float, dict] = {}
    total = 0.0
    todo = _todo(plan, retry_failed, rerun_archived)
    n_todo = len(todo)
    for p, k in todo:
        h = float(p.options.get("h", 1.0))
        c, src = wall_per_sim_second(h, bench)
        c *= shared
        t = estimated_sim_time(p.params, p.options)
        d = per_h.setdefault(h, {"runs": 0, "sim_s": 0.0, "wall_s": 0.0, "wall_s_per_sim_s": c, "source": src,
                                 "overhead_s": 0.0})
        d["runs"] += 1
        d["sim_s"] += t
        d["overhead_s"] += overhead
        d["wall_s"] += c * t + overhead
        total += c * t + overhead
    return {
        "name": spec.name,
        "grid_size": len(plan.points),
        "done": len(plan.done),
        "failed": len(plan.failed),
        "pending": len(plan.pending),
        "stale": len(plan.stale) if rerun_stale else 0,
        "stale_kept": 0 if rerun_stale else len(plan.stale),
        "archived": len(plan.archived),
        "runs_to_do": n_todo,
        "damaged": len(plan.damaged),
        "by_mesh_size": per_h,
        "cpu_s": total,
        "wall_s": total / max(1, jobs),
        "jobs": jobs,
        "per_run_overhead_s": overhead,
        "per_run_overhead_source": overhead_src,
        "shared_run_factor": shared,
        "shared_run_factor_source": shared_src,
        **({"budget": run_budgets([p for p, _ in todo], jobs)} if budget else {}),
    }

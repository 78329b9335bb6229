"""A campaign's cost before it runs: wall and CPU seconds of its runs to do, memory per mesh, runs refused.

    estimate_cost("campaigns/examples/demo.toml", jobs=2)   # {"cpu_s": ..., "wall_s": ..., "by_mesh": [...], ...}

One estimate, from :mod:`solver.budget`: each distinct mesh (its h, grading and radii) is counted from its size
function without being built, priced on the path that will run (PARDISO or SuperLU, numba or numpy kernels) and
scaled by this machine's calibration (one Newton iteration at h = 2 mm, measured once per code hash and path).
With more than one job a run shares the machine and is slower than alone by :func:`shared_run_factor`.  Units: s.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.plan import _todo, as_spec, plan_campaign

__all__ = ["estimate_cost", "measured_wall", "run_budgets", "shared_run_factor", "estimated_sim_time",
           "DEFAULT_SHARED_RUN_FACTOR"]

# With more than one job each run shares the machine (one core, one BLAS/MKL thread each): a lone run's wall time
# is multiplied by the factor ``dchfrac bench`` measures with one run per core (bench.json key
# "shared_run_factor"), else by this default (h = 2 reference case, 2-core machine: 20.0 s side by side against
# 13.1 s alone, results/archive/bench_rounds.md, ninth round).
DEFAULT_SHARED_RUN_FACTOR = 1.5


def _load_bench(root, spec=None) -> dict:
    """``<root>/bench/bench.json``, else the one of the spec's project results (a run into another root, such
    as the README's ``--results runs``, shares what the project's benchmark measured); {} when neither."""
    from sweep.campaign.paths import project_root

    project = project_root(spec.source) if spec is not None else None
    for p in (Path(root) / "bench" / "bench.json", *([project / DEFAULT_ROOT / "bench" / "bench.json"] if project else [])):
        try:
            return json.loads(p.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            continue
    return {}


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


def run_budgets(points, jobs: int = 1, machine_factor: float | None = None) -> list[dict]:
    """:mod:`solver.budget`'s estimate of the runs ``points`` (campaign points with ``params`` and ``options``),
    one entry per distinct mesh (``_MESH_KEYS``), coarsest first: {"h" (mm), "runs", "sim_s" (simulated s, each
    run to its :func:`estimated_sim_time`), "estimate" (the :class:`solver.budget.Estimate` of one run: nodes,
    peak memory, memory available, path), "factor" (this machine and path over the reference machine's fast
    path), "wall_s" (s: the runs' wall times alone), "refused" (the runs cannot fit: solver.simulate refuses
    them), "side_by_side" (``jobs`` runs at once cannot fit)}.

    ``machine_factor``: None measures it (:func:`solver.budget.calibration`: one Newton iteration at h = 2 mm on
    the path that will run, about 2 s once per code hash and path); a number prices the runs on a machine that
    many times slower than the reference (1.0: the reference machine's figures, no measurement)."""
    from solver import Parameters, RunOptions
    from solver.budget import calibration, estimate_run, wall_time_s

    groups: dict[tuple, dict] = {}
    for p in points:
        key = tuple(repr(getattr(p, part).get(name)) for part, name in _MESH_KEYS)
        g = groups.get(key)
        if g is None:
            params, options = Parameters.from_dict(p.params), RunOptions.from_dict(p.options)
            est = estimate_run(params, options, calibrate=False)
            factor = (calibration(est.linear_solver, est.kernels)["factor"] if machine_factor is None
                      else float(machine_factor))
            g = groups[key] = {"h": options.h, "runs": 0, "sim_s": 0.0, "estimate": est, "factor": factor,
                               "wall_s": 0.0, "refused": not est.fits(),
                               "side_by_side": est.available_bytes is not None
                               and jobs * est.memory_bytes > est.available_bytes}
        t = estimated_sim_time(p.params, p.options)
        g["runs"] += 1
        g["sim_s"] += t
        g["wall_s"] += wall_time_s(g["estimate"].unknowns, t, g["estimate"].linear_solver, g["factor"])
    return sorted(groups.values(), key=lambda g: -g["h"])


def measured_wall(plan) -> dict | None:
    """The wall times (s) this campaign's finished runs took, ok or failed: a record's over all its pieces
    (:func:`sweep.campaign.table.record_wall_time`, the table's own rule) and an archived row's table value;
    count, median, min and max; None when no run has finished.  Beside the model's estimate in the dry run, it
    shows how far the estimate is from what the campaign's runs cost here."""
    import math
    import statistics

    from sweep.campaign.table import record_wall_time

    def finished(r) -> bool:
        return bool(r) and r.get("status") in ("ok", "failed")

    walls = [record_wall_time(r) for r in plan.records.values() if finished(r)]
    walls += [r.get("wall_time_s") for r in plan.archived_rows.values() if finished(r)]
    walls = sorted(float(w) for w in walls if w is not None and math.isfinite(float(w)))
    if not walls:
        return None
    return {"runs": len(walls), "median_s": statistics.median(walls), "min_s": walls[0], "max_s": walls[-1]}


def estimate_cost(spec, root=DEFAULT_ROOT, *, jobs: int = 1, code_hash: str | None = None,
                  retry_failed: bool = False, rerun_stale: bool = False, rerun_archived: bool = False,
                  machine_factor: float | None = None) -> dict:
    """Grid size and estimated CPU and wall time (s) of the runs to do (pending, damaged, stale with
    ``rerun_stale``, failed with ``retry_failed``, archived with ``rerun_archived``) of a campaign on ``jobs``
    workers.

    Per run: its wall time alone from :func:`run_budgets` (its mesh, the path that will run, this machine's
    calibration, or ``machine_factor``) times :func:`shared_run_factor` (a run beside others is slower than
    alone).  ``cpu_s`` is their sum and ``wall_s`` that over ``jobs`` (perfect packing: a lower bound when runs
    differ much in cost).  ``by_mesh``: the :func:`run_budgets` groups (memory, refusals).  ``measured``:
    :func:`measured_wall` of the runs already finished, or None."""
    spec = as_spec(spec)
    root = results_root(spec, root)
    plan = plan_campaign(spec, root, code_hash=code_hash, rerun_stale=rerun_stale)
    shared, shared_src = shared_run_factor(jobs, _load_bench(root, spec))
    todo = _todo(plan, retry_failed, rerun_archived)
    groups = run_budgets([p for p, _ in todo], jobs, machine_factor)
    cpu = shared * sum(g["wall_s"] for g in groups)
    out = {
        "name": spec.name,
        "grid_size": len(plan.points),
        "done": len(plan.done),
        "failed": len(plan.failed),
        "pending": len(plan.pending),
        "stale": len(plan.stale) if rerun_stale else 0,
        "stale_kept": 0 if rerun_stale else len(plan.stale),
        "archived": len(plan.archived),
        "runs_to_do": len(todo),
        "damaged": len(plan.damaged),
        "by_mesh": groups,
        "cpu_s": cpu,
        "wall_s": cpu / max(1, jobs),
        "jobs": jobs,
        "shared_run_factor": shared,
        "shared_run_factor_source": shared_src,
    }
    out["measured"] = measured_wall(plan)
    return out

"""``dchfrac discrepancy run --measured DIR --model SPEC --out DIR`` (argparse), added by the main CLI."""
from __future__ import annotations

import argparse
import logging
import sys

__all__ = ["add_discrepancy_commands", "main", "show_progress"]


def show_progress(quiet: bool = False) -> None:
    """Print the workflow's progress (logger ``dchfrac.discrepancy``, INFO: each stage's forward runs and
    seconds, each refit, each profile point, the verdict) on stderr, unless ``quiet``.  A run takes minutes to
    hours; its progress is how a user tells a slow stage from a stuck one.  Idempotent."""
    lg = logging.getLogger("dchfrac.discrepancy")
    if quiet or lg.handlers:
        return
    h = logging.StreamHandler(sys.stderr)
    h.setFormatter(logging.Formatter("%(asctime)s %(message)s", "%H:%M:%S"))
    lg.addHandler(h)
    lg.setLevel(logging.INFO)


def add_discrepancy_commands(subparsers) -> argparse.ArgumentParser:
    """Add ``discrepancy run`` to an argparse subparsers object; the leaf sets ``func(args) -> int``."""
    d = subparsers.add_parser("discrepancy", help="name the missing effect between simulation and measured data",
                              description="Discrepancy workflow (see sweep/discrepancy).")
    sub = d.add_subparsers(dest="discrepancy_command", metavar="{run}")
    sub.required = True
    r = sub.add_parser("run", help="calibrate, localize, screen, refit, report")
    r.add_argument("--measured", required=True, help="measured-data folder (conditions.csv, observations.csv)")
    r.add_argument("--model", required=True, help="model SPEC (TOML)")
    r.add_argument("--out", required=True, help="output folder (report.md, report.json, figures, run cache)")
    r.add_argument("--jobs", type=int, default=None, help="parallel solver runs (default: spec workflow.n_jobs)")
    r.add_argument("--cache", default=None, help="forward-run cache folder (default: OUT/cache)")
    r.add_argument("--no-figures", action="store_true")
    r.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    r.set_defaults(func=cmd_run)
    return d


def cmd_run(args) -> int:
    from pathlib import Path

    from solver import RunOptions
    from solver.output import check_writable_dir

    from .checks import check_data_against_model
    from .data import load_measured
    from .forward import SolverForward, fine_forwards
    from .report import ROUGH_NOTE
    from .spec import load_spec
    from .workflow import run_workflow

    out = Path(args.out)
    cache = Path(args.cache) if args.cache else out / "cache"
    try:  # bad input and unwritable outputs: one line, before any forward run
        data = load_measured(args.measured)
        spec = load_spec(args.model)
        check_writable_dir(out, "--out")
        check_writable_dir(cache, "--cache")
        jobs = args.jobs if args.jobs is not None else spec.wf("n_jobs")
        fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), cache, n_jobs=jobs)
        fine = fine_forwards(spec, cache, jobs)      # one per mesh realization ([discretization] mesh_seeds)
        check_data_against_model(data, spec, [fwd, *fine])
    except ValueError as exc:
        print(f"dchfrac discrepancy: {exc}", file=sys.stderr)
        return 2
    show_progress(args.quiet)
    rep = run_workflow(data, spec, fwd, out, figures=not args.no_figures, fine_forward=fine)
    print(f"verdict: {rep['verdict']}" + (f"; named effect {rep['named_effect']} = {rep['strength']:.4g} "
                                          f"{rep['strength_interval']}"
                                          + (f" ({ROUGH_NOTE})" if rep.get("strength_interval_rough") else "")
                                          if rep["named_effect"] else ""))
    print(f"held-out gap (total): before {rep['gap_before'].get('total', float('nan')):.3g}, after "
          f"{rep['gap_after'].get('total', float('nan')):.3g}; report in {out / 'report.md'}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="dchfrac")
    add_discrepancy_commands(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

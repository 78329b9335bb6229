"""``dchfrac campaign ...`` commands (argparse), added to the main CLI by :func:`add_campaign_commands`.

    dchfrac campaign run SPEC [--jobs N] [--backend loky|dask|ray] [--scheduler ADDR] [--dry-run]
                              [--retry-failed] [--fail-fast] [--timeout S] [--retries N] [--results DIR]
    dchfrac campaign status SPEC [--results DIR]
    dchfrac campaign plot SPEC [--results DIR]
    dchfrac campaign report SPEC [--results DIR]
    dchfrac campaign classify SPEC [--results DIR]     (rerun the classifier on finished runs)

Also runnable alone: ``python -m sweep.campaign_cli run campaigns/demo.toml``.
Exit codes: 0 success, 1 failed runs (run) or errors, 2 bad arguments or spec, 130 interrupted.
"""
from __future__ import annotations

import argparse
import sys

from sweep.scheduler import BACKENDS

__all__ = ["add_campaign_commands", "main"]


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", help="campaign spec, a TOML file (see campaigns/)")
    p.add_argument("--results", default="results", metavar="DIR",
                   help="results root (default: results); the campaign lives in DIR/<name>/")


def add_campaign_commands(subparsers) -> argparse.ArgumentParser:
    """Add ``campaign {run,status,plot,report,classify}`` to an argparse subparsers object.

    Each leaf parser sets ``func`` (``func(args) -> int`` exit code)."""
    camp = subparsers.add_parser("campaign", help="parameter campaigns: run, status, plot, report",
                                 description="Run and inspect parameter campaigns (campaigns/*.toml).")
    sub = camp.add_subparsers(dest="campaign_command", metavar="{run,status,plot,report,classify}")
    sub.required = True

    p = sub.add_parser("run", help="run the pending runs of a campaign (resumable)")
    _common(p)
    p.add_argument("--jobs", "-j", type=int, default=None, help="parallel runs (default: spec [run] jobs or 1; -1 = all cores)")
    p.add_argument("--backend", choices=BACKENDS, default="loky", help="joblib backend (default loky)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="dask scheduler / ray address (default: a local cluster of --jobs workers)")
    p.add_argument("--dry-run", action="store_true", help="print the grid size and an estimated cost, run nothing")
    p.add_argument("--retry-failed", action="store_true", help="rerun runs recorded as failed")
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed run")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="wall-time limit per run, s (default: spec [run] timeout, else none); the run is killed")
    p.add_argument("--retries", type=int, default=None, help="extra attempts after a failure (default: spec or 0)")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_run)

    for name, fn, helptext in (
        ("status", cmd_status, "done, failed (with reasons) and pending runs"),
        ("plot", cmd_plot, "draw the campaign's diagrams from its table"),
        ("report", cmd_report, "write a Markdown summary with the figures"),
        ("classify", cmd_classify, "rerun the classifier on the finished runs (no simulation)"),
    ):
        q = sub.add_parser(name, help=helptext)
        _common(q)
        q.set_defaults(func=fn)
    return camp


def _guarded(fn):
    """Bad spec or arguments -> message on stderr and exit code 2 (no traceback)."""
    import functools

    @functools.wraps(fn)
    def wrapper(args) -> int:
        from sweep.spec import SpecError

        try:
            return fn(args)
        except SpecError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        except ValueError as e:
            if getattr(args, "campaign_command", None) == "run" and "must be" in str(e):
                print(f"error: {e}", file=sys.stderr)
                return 2
            raise
        except RuntimeError as e:
            if "is in use by process" in str(e):
                print(f"error: {e}", file=sys.stderr)
                return 2
            raise

    return wrapper


def _spec(args):
    from sweep.spec import load_spec

    return load_spec(args.spec)


def _fmt_s(s: float) -> str:
    from sweep.campaign import _hms

    return _hms(s)


@_guarded
def cmd_run(args) -> int:
    from sweep.campaign import COST_MESH_EXPONENT, DEFAULT_WALL_S_PER_SIM_S_H2, estimate_cost, run_campaign

    spec = _spec(args)
    if args.dry_run:
        jobs = args.jobs or int(spec.run.get("jobs", 1))
        est = estimate_cost(spec, args.results, jobs=jobs, retry_failed=args.retry_failed)
        print(f"campaign {spec.name}: {est['grid_size']} runs in the grid ({est['done']} done, "
              f"{est['failed']} failed, {est['pending']} pending)")
        for h, d in sorted(est["by_mesh_size"].items()):
            print(f"  h = {h:g} mm: {d['runs']} runs, {d['sim_s']:.1f} simulated s x {d['wall_s_per_sim_s']:.3g} "
                  f"wall s per simulated s ({d['source']}) + {d['runs']} x {est['per_run_overhead_s']:.3g} s per run "
                  f"({est['per_run_overhead_source']}) = {_fmt_s(d['wall_s'])} CPU")
        print(f"estimated cost of the runs to do: {_fmt_s(est['cpu_s'])} CPU, about {_fmt_s(est['wall_s'])} "
              f"wall on {jobs} job(s)")
        if any(d["source"] == "default" for d in est["by_mesh_size"].values()):
            print(f"  (no {args.results}/bench/bench.json: default {DEFAULT_WALL_S_PER_SIM_S_H2:g} wall s per "
                  f"simulated s at h = 2 mm, scaled as (2/h)^{COST_MESH_EXPONENT:g}; run `dchfrac bench` for real figures)")
        return 0
    timeout = "spec" if args.timeout is None else args.timeout
    try:
        res = run_campaign(spec, args.results, jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                           timeout=timeout, retries=args.retries, fail_fast=args.fail_fast,
                           retry_failed=args.retry_failed, progress=None if args.quiet else sys.stderr)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished runs are recorded; rerun the same command to resume", file=sys.stderr)
        return 130
    print(f"campaign {spec.name}: {res.n_points} runs, {res.n_executed} executed now "
          f"({res.n_ok} ok, {res.n_failed} failed), {res.n_skipped} not executed (already recorded or cancelled)")
    for k, reason in res.failures:
        print(f"  failed {k}: {reason}")
    if res.aborted:
        print("stopped at the first failure (--fail-fast)")
    for p in res.table_paths:
        print(f"table: {p}")
    return 1 if res.n_failed else 0


@_guarded
def cmd_status(args) -> int:
    from sweep.campaign import plan_campaign

    spec = _spec(args)
    plan = plan_campaign(spec, args.results)
    print(f"campaign {spec.name}: {len(plan.points)} runs: {len(plan.done)} done, {len(plan.failed)} failed, "
          f"{len(plan.pending)} pending  ({plan.store.dir})")
    for p, k in plan.failed:
        swept = ", ".join(f"{a}={v}" for a, v in p.swept.items())
        print(f"  failed {k} ({swept}): {plan.records[k].get('reason')}")
    return 0


@_guarded
def cmd_plot(args) -> int:
    from sweep.campaign import plot_campaign

    spec = _spec(args)
    figs = plot_campaign(spec, args.results)
    if not figs:
        print(f"campaign {spec.name}: nothing to plot (no finished runs or no diagrams in the spec)")
    for f in figs:
        print(f"figure: {f}")
    return 0


@_guarded
def cmd_report(args) -> int:
    from sweep.campaign import write_report

    path = write_report(_spec(args), args.results)
    print(f"report: {path}")
    return 0


@_guarded
def cmd_classify(args) -> int:
    from sweep.campaign import reclassify

    n = reclassify(_spec(args), args.results)
    print(f"reclassified {n} runs")
    return 0


def main(argv=None) -> int:
    """Standalone entry point: the ``campaign`` subcommands without the ``dchfrac campaign`` prefix."""
    parser = argparse.ArgumentParser(prog="python -m sweep.campaign_cli")
    sub = parser.add_subparsers(dest="cmd")
    add_campaign_commands(sub)
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(["campaign", *argv])
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())

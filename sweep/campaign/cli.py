"""``dchfrac campaign ...`` commands (argparse), added to the main CLI by :func:`add_campaign_commands`.

    dchfrac campaign run SPEC [--jobs N] [--backend loky|dask|ray] [--scheduler ADDR] [--dry-run]
                              [--retry-failed] [--rerun-stale] [--rerun-archived] [--fail-fast] [--timeout S]
                              [--retries N] [--results DIR]
    dchfrac campaign status SPEC [--results DIR]       (also: runs made by other code, damaged runs)
    dchfrac campaign plot SPEC [--results DIR]
    dchfrac campaign report SPEC [--results DIR] [--html]
    dchfrac campaign classify SPEC [--results DIR]     (rerun the classifier on finished runs)
    dchfrac campaign columns SPEC [--results DIR] [--timeseries]   (column dictionary: name, unit, meaning)
    dchfrac campaign prune SPEC [--results DIR]        (keep of each finished run what its label was read from)
    dchfrac campaign tables [SPEC...] [--all]         (table.parquet with units, columns.csv, from committed tables)
    dchfrac campaign redraw [SPEC...] [--all]         (every figure of committed campaigns, from their tables)
    dchfrac campaign compare SPEC OTHER [--label L] [--columns A,B] [--out FILE]   (sweep.campaign.compare)
    dchfrac campaign companion SPEC --set KEY=VALUE --suffix S [--results DIR] [--out FILE]
                                                      (its failed points rerun with changed options: a new spec)

``run`` runs the pending points and reruns damaged runs; runs made by other solver code (stale) only with
``--rerun-stale``, archived runs (committed rows without a run folder here) only with ``--rerun-archived``,
and it prints how many runs it will make and their estimated cost first. ``plot``, ``report`` and ``classify``
refuse (exit 1) while runs are damaged, naming them, and when they would replace a committed table with an
emptier one. ``--results`` defaults to ``results/`` of the spec's project (``sweep.campaign.paths``).

Also runnable alone: ``python -m sweep.campaign.cli run campaigns/examples/demo.toml``.
Exit codes: 0 success, 1 failed runs (run), damaged runs (status, plot, report, classify) or errors,
2 bad arguments or spec, 130 interrupted.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from sweep.campaign.cli_guard import UsageError, guarded, name_damaged
from sweep.campaign.logs import LogStream, end_logging, setup_logging
from sweep.campaign.scheduler import BACKENDS, check_backend

__all__ = ["add_campaign_commands", "main"]


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", help="campaign spec, a TOML file (see campaigns/)")
    p.add_argument("--results", default=None, metavar="DIR",
                   help="results root (default: results/ of the spec's project, the folder holding its campaigns/); "
                        "the campaign lives in DIR/<name>/")
    p.add_argument("--max-runs", type=int, default=None, metavar="N",
                   help="allow grids of up to N runs (default: spec [run] max_runs, else 10000)")


def add_campaign_commands(subparsers) -> argparse.ArgumentParser:
    """Add ``campaign {run,status,plot,report,classify}`` to an argparse subparsers object.

    Each leaf parser sets ``func`` (``func(args) -> int`` exit code)."""
    camp = subparsers.add_parser("campaign", help="parameter campaigns: run, status, plot, report",
                                 description="Run and inspect parameter campaigns (campaigns/*.toml).")
    sub = camp.add_subparsers(dest="campaign_command",
                              metavar="{run,status,plot,report,classify,columns,compare,prune,tables,redraw,companion}")
    sub.required = True

    _add_run_parser(sub)
    _add_inspect_parsers(sub)
    _add_table_parsers(sub)
    from sweep.campaign.companion import add_companion_command
    from sweep.campaign.compare import add_compare_command

    add_compare_command(sub)
    add_companion_command(sub)
    return camp


def _add_run_parser(sub) -> None:
    """``campaign run``: its options (jobs, backend, what is rerun, limits)."""
    p = sub.add_parser("run", help="run the pending runs of a campaign (resumable)")
    _common(p)
    p.add_argument("--jobs", "-j", type=int, default=None, help="parallel runs (default: spec [run] jobs or 1; -1 = all cores)")
    p.add_argument("--backend", choices=BACKENDS, default="loky", help="joblib backend (default loky)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="dask scheduler / ray address (default: a local cluster of --jobs workers)")
    p.add_argument("--dry-run", action="store_true", help="print the grid size and an estimated cost, run nothing")
    p.add_argument("--retry-failed", action="store_true", help="rerun runs recorded as failed")
    p.add_argument("--rerun-stale", action="store_true",
                   help="rerun the runs made by other solver code (stale); by default they are kept and listed")
    p.add_argument("--rerun-archived", action="store_true",
                   help="rerun the archived runs (rows of the committed table whose run folders are not here)")
    p.add_argument("--relabel", action="store_true",
                   help="relabel finished runs labelled by other classifier code (default: keep their labels)")
    p.add_argument("--accept-stale", action="store_true",
                   help="keep the runs made by other solver code (the default; kept for old scripts)")
    p.add_argument("--fail-fast", action="store_true", help="stop at the first failed run")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="wall-time limit per run, s (default: spec [run] timeout, else none); the run is killed")
    p.add_argument("--retries", type=int, default=None, help="extra attempts after a failure (default: spec or 0)")
    p.add_argument("--quiet", action="store_true", help="no progress lines (as -q)")
    p.add_argument("--strict", action="store_true",
                   help="refuse a grid with implausible inputs (a likely unit slip, an unresolved length) instead "
                        "of warning (the dry run lists them)")
    p.set_defaults(func=cmd_run)


def _add_inspect_parsers(sub) -> None:
    """``campaign status|plot|report|classify|columns|prune``: one campaign, no run."""
    for name, fn, helptext in (
        ("status", cmd_status, "done, failed (with reasons) and pending runs"),
        ("plot", cmd_plot, "draw the campaign's diagrams from its table"),
        ("report", cmd_report, "write a Markdown summary with the figures"),
        ("classify", cmd_classify, "rerun the classifier on the finished runs (no simulation)"),
        ("columns", cmd_columns, "the column dictionary of the campaign table: name, unit, dtype, meaning"),
        ("prune", cmd_prune, "remove the snapshots no label was read from (sweep.campaign.archive); keeps the campaign "
                             "resumable and its diagrams drawable"),
    ):
        q = sub.add_parser(name, help=helptext)
        _common(q)
        q.set_defaults(func=fn)
        if name == "columns":
            q.add_argument("--timeseries", action="store_true", help="the columns of the runs' timeseries.csv instead")
        if name == "report":
            q.add_argument("--html", action="store_true",
                           help="also write report.html: one self-contained file (table, diagrams, thumbnails, paper)")


def _add_table_parsers(sub) -> None:
    """``campaign tables|redraw``: many committed campaigns, from their tables."""
    for name, fn, helptext in (
        ("tables", cmd_tables, "rewrite table.parquet (units in its metadata) and columns.csv of campaigns from "
                               "their committed tables or records (no run)"),
        ("redraw", cmd_redraw, "redraw the figures of campaigns from their committed tables (no run); a figure "
                               "that needs absent run folders is kept"),
    ):
        q = sub.add_parser(name, help=helptext)
        q.add_argument("specs", nargs="*", metavar="SPEC", help="campaign specs (TOML)")
        q.add_argument("--all", action="store_true",
                       help="every campaign spec under PROJECT/campaigns/ whose results folder holds a table")
        q.add_argument("--project", default=".", metavar="PROJECT", help="project folder for --all (default: .)")
        q.add_argument("--results", default=None, metavar="DIR",
                       help="results root (default: results/ of each spec's project)")
        q.set_defaults(func=fn)


def _spec(args, writes: bool = True):
    """The validated spec of ``args``; with ``writes``, the campaign folder RESULTS/<name> is checked writable."""
    from solver.output import check_writable_dir
    from sweep.campaign.spec import load_spec

    from sweep.campaign.paths import results_root

    spec = load_spec(args.spec, max_runs=getattr(args, "max_runs", None))
    args.results = str(results_root(spec, None) if args.results is None else Path(args.results).resolve())
    if writes:
        try:
            check_writable_dir(f"{args.results}/{spec.name}", "--results campaign folder")
        except ValueError as e:
            raise UsageError(str(e)) from None
    return spec


def _input_warnings(spec) -> list[str]:
    """Warnings of ``solver.options.check_run_inputs`` over the grid, each once with its number of runs."""
    from solver import Parameters, RunOptions
    from solver.options import check_run_inputs
    from sweep.campaign.sampler import grid_points

    counts: dict[str, int] = {}
    for p in grid_points(spec):
        for w in check_run_inputs(Parameters.from_dict(p.params), RunOptions.from_dict(p.options)):
            counts[w] = counts.get(w, 0) + 1
    return [f"{n} run(s): {w}" for w, n in counts.items()]


def _check_environment() -> None:
    """The environment variables the runs read (``solver.options.check_environment``): refused before any run
    (UsageError), its warnings logged."""
    from solver.options import check_environment

    try:
        for w in check_environment():
            logging.getLogger("dchfrac.campaign").warning("warning: %s", w)
    except ValueError as e:
        raise UsageError(str(e)) from None


def _fmt_s(s: float) -> str:
    from sweep.campaign.run import _hms

    return _hms(s)


def _print_estimate(spec, est, jobs: int) -> None:
    """The dry run's lines: the runs of the grid by state; per distinct mesh, one run's nodes and peak memory
    against the memory available and the runs' wall time (solver.budget: the path that will run, calibrated on
    this machine); the runs refused or too big for ``jobs`` at a time; the total."""
    print(f"campaign {spec.name}: {est['grid_size']} runs in the grid ({est['done']} done, {est['failed']} failed, "
          f"{est['archived']} archived, {est['pending']} pending, {est['stale']} made by other code to rerun, "
          f"{est['stale_kept']} made by other code kept, {est['damaged']} damaged)")
    if est["by_mesh"]:
        print(f"per mesh (solver.budget: the path that will run, this machine {est['by_mesh'][0]['factor']:.3g}x "
              "the reference machine's fast path):")
    for g in est["by_mesh"]:
        e = g["estimate"]
        print(f"  h = {g['h']:g} mm: {g['runs']} run(s), {g['sim_s']:.3g} simulated s, {_fmt_s(g['wall_s'])} of wall "
              f"time alone; each {e.nodes:,} nodes ({e.unknowns:,} unknowns), peak memory about "
              f"{e.memory_bytes / 1e9:.3g} GB of {_avail(e)} available ({e.linear_solver}, {e.kernels} kernels)")
        if g["refused"]:
            print(f"  REFUSED: the {g['runs']} run(s) at h = {g['h']:g} mm cannot fit in memory (solver.simulate "
                  "refuses them; allowed: a coarser h)")
        elif g["side_by_side"]:
            print(f"  WARNING: {jobs} runs at h = {g['h']:g} mm side by side need about "
                  f"{jobs * e.memory_bytes / 1e9:.3g} GB, more than is available (allowed: fewer --jobs)")
    if jobs > 1:
        print(f"  (x {est['shared_run_factor']:.3g}: a run beside {jobs - 1} other(s) against alone, "
              f"{est['shared_run_factor_source']})")
    print(f"estimated cost of the {est['runs_to_do']} run(s) to do: {_fmt_s(est['cpu_s'])} CPU, about "
          f"{_fmt_s(est['wall_s'])} wall on {jobs} job(s)")
    if text := _measured_text(est):
        print(f"measured: {text}")


def _measured_text(est) -> str:
    """What the campaign's finished runs took and the runs to do at that pace ("" when none finished): beside
    the model's estimate, which does not know how a run's time steps shrink (a crack's growth, a failure)."""
    m = est.get("measured")
    if not (m and est["runs_to_do"]):
        return ""
    return (f"this campaign's {m['runs']} finished run(s) took {_fmt_s(m['median_s'])} each (median; "
            f"{_fmt_s(m['min_s'])} to {_fmt_s(m['max_s'])}); at that pace the {est['runs_to_do']} to do take "
            f"about {_fmt_s(m['median_s'] * est['runs_to_do'])} CPU")


def _avail(e) -> str:
    return "unknown" if e.available_bytes is None else f"{e.available_bytes / 1e9:.3g} GB"


@guarded
def cmd_run(args) -> int:
    from sweep.campaign.cost import estimate_cost
    from sweep.campaign.run import run_campaign

    spec = _spec(args)
    _check_environment()
    if args.strict:
        warnings = _input_warnings(spec)
        if warnings:
            raise UsageError(f"--strict refuses: {warnings[0]}"
                             + (f" (and {len(warnings) - 1} more warning(s))" if len(warnings) > 1 else ""))
    jobs = args.jobs or int(spec.run.get("jobs", 1))
    est = estimate_cost(spec, args.results, jobs=max(1, jobs), retry_failed=args.retry_failed,
                        rerun_stale=args.rerun_stale, rerun_archived=args.rerun_archived)
    if args.dry_run:
        _print_estimate(spec, est, jobs)
        for w in _input_warnings(spec):
            print(f"warning: {w}")
        return 0
    if est["runs_to_do"]:  # what is about to be spent, before any run starts
        print(f"campaign {spec.name}: {est['runs_to_do']} run(s) to do, estimated {_fmt_s(est['cpu_s'])} CPU, about "
              f"{_fmt_s(est['wall_s'])} wall on {jobs} job(s) (`--dry-run` details them)", flush=True)
        if text := _measured_text(est):
            print(f"  measured: {text}", flush=True)
    elif est["archived"] or est["stale_kept"]:
        print(f"campaign {spec.name}: nothing to rerun: {est['archived']} archived and {est['stale_kept']} stale "
              f"run(s) kept (`--rerun-archived`, `--rerun-stale` rerun them)", flush=True)
    timeout = "spec" if args.timeout is None else args.timeout
    try:                                        # before anything is run or written
        check_backend(args.backend, args.scheduler)
    except ValueError as e:
        raise UsageError(str(e)) from None
    try:
        res = run_campaign(spec, args.results, jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                           timeout=timeout, retries=args.retries, fail_fast=args.fail_fast,
                           retry_failed=args.retry_failed, rerun_stale=args.rerun_stale,
                           rerun_archived=args.rerun_archived, relabel=args.relabel,
                           progress=None if args.quiet else LogStream("dchfrac.campaign"))
    except KeyboardInterrupt:
        logging.getLogger("dchfrac.campaign").warning("interrupted: finished runs are recorded; rerun the same command to resume")
        return 130
    print(f"campaign {spec.name}: {res.n_points} runs, {res.n_executed} executed now "
          f"({res.n_ok} ok, {res.n_failed} failed), {res.n_skipped} not executed (already recorded, archived or cancelled)")
    _print_provenance(res)
    for k, reason in res.failures:
        print(f"  failed {k}: {reason}")
    if res.aborted:
        print("stopped at the first failure (--fail-fast)")
    for p in res.table_paths:
        print(f"table: {p}")
    return 1 if res.n_failed else 0


def _print_provenance(res) -> None:
    """What ``campaign run`` did about stale and damaged runs."""
    if res.stale_reused:
        print(f"  kept {len(res.stale_reused)} run(s) made by other solver code (--rerun-stale reruns them): "
              + " ".join(res.stale_reused))
    if res.stale_rerun:
        print(f"  reran {len(res.stale_rerun)} run(s) made by other solver code")
    if res.damaged_rerun:
        print(f"  reran {len(res.damaged_rerun)} damaged run(s): " + " ".join(res.damaged_rerun))
    if res.reclassified:
        print(f"  relabelled {len(res.reclassified)} run(s) labelled by other classifier code (--relabel)")
    if res.labels_kept:
        print(f"  kept the labels of {len(res.labels_kept)} run(s) labelled by other classifier code "
              "(`--relabel` or `campaign classify` relabels them)")


def _sampler_status_lines(st: dict) -> list[str]:
    """The lines of ``campaign status`` on an adaptive sampler's state: the boundary sampler's round, budget and
    boundary uncertainty (tolerance units), or with replicates its band (decades) and replicate counts."""
    if "uncertainty" not in st:     # with replicates: sweep.campaign.replicate_sampler.state
        from sweep.campaign.run import _sampler_text

        pts = st["points"]
        lines = [f"{st['sampler']} {_sampler_text(st)}",
                 f"  {sum(p['replicates'] for p in pts)} labelled runs at {len(pts)} points (at most "
                 f"{st['replicates']} each), {sum(p['pending'] for p in pts)} pending, "
                 f"{sum(p['unlabelled'] for p in pts)} finished without a label"]
        return lines + ([] if st["stopped"] else ["  running: rerun `campaign run` to continue"])
    from sweep.regimes.diagrams import regime_style

    unc = "not yet measured (fewer than two labels)" if st["uncertainty"] is None else \
        f"{st['uncertainty']:.2f} x tolerance (largest half-width of the boundary's band)"
    lines = [f"{st['sampler']} sampler: round {st['round']}, {st['runs_used']}/{st['budget']} runs of the budget "
             f"({st['pending']} pending), boundary uncertainty {unc}"]
    for pair, v in sorted(st["uncertainty_by_pair"].items()):
        words = " | ".join(regime_style(x.strip())["label"] for x in str(pair).split("|"))
        lines.append(f"  boundary {words}: {v:.2f} x tolerance")
    return lines + [f"  stopped: {st['reason']}" if st["stopped"] else "  running: rerun `campaign run` to continue"]


@guarded
def cmd_status(args) -> int:
    from sweep.campaign.accounting import campaign_throughput
    from sweep.campaign.plan import _archived_text, code_counts, plan_campaign
    from sweep.campaign.run import sampler_status

    spec = _spec(args, writes=False)
    plan = plan_campaign(spec, args.results)
    print(f"campaign {spec.name}: {len(plan.points)} runs: {len(plan.done)} done, {len(plan.failed)} failed, "
          f"{len(plan.pending)} pending, {len(plan.archived)} archived, {len(plan.damaged)} damaged"
          f"  ({plan.store.dir})")
    if plan.archived or plan.unmatched_rows:
        print(f"  archived (rows of the committed table, run folders not here): {_archived_text(plan)}")
    counts = code_counts(plan)
    print(f"  current code: solver {plan.code_hash}, classifier {plan.classifier_hash}; runs by code: "
          + ", ".join(f"{h}{' (current)' if h == plan.code_hash else ''}: {n}" for h, n in counts.items()))
    if plan.store.records():
        print("  " + campaign_throughput(plan.store.records()).text())
    if plan.misclassified:
        print(f"  {len(plan.misclassified)} run(s) labelled by other classifier code (kept; `campaign run --relabel` or `campaign classify` relabels them)")
    n_stale = sum(n for h, n in counts.items() if h != plan.code_hash)
    if n_stale:
        print(f"  {n_stale} made by other code (stale): used like the others; "
              "`campaign run --rerun-stale` reruns them")
    for p, k in plan.failed:
        swept = ", ".join(f"{a}={v}" for a, v in p.swept.items())
        print(f"  failed {k} ({swept}): {plan.records[k].get('reason')}")
    st = sampler_status(spec, args.results)
    if st is not None:
        print("\n".join(_sampler_status_lines(st)))
    if plan.damaged:
        print(plan.damage_text())
        return 1
    return 0


@guarded
def cmd_plot(args) -> int:
    from sweep.campaign.plot import plot_campaign

    spec = _spec(args)
    figs = plot_campaign(spec, args.results)
    if not figs:
        print(f"campaign {spec.name}: nothing to plot (no finished runs or no diagrams in the spec)")
    for f in figs:
        print(f"figure: {f}")
    return 0


@guarded
def cmd_report(args) -> int:
    from sweep.campaign.report import write_report

    spec = _spec(args)
    path = write_report(spec, args.results)
    print(f"report: {path}")
    if getattr(args, "html", False):
        from sweep.campaign.report_html import write_html_report

        print(f"report: {write_html_report(spec, args.results, plot=False)}")
    return 0


@guarded
def cmd_classify(args) -> int:
    from sweep.campaign.plan import plan_campaign
    from sweep.campaign.run import reclassify

    spec = _spec(args)
    n = reclassify(spec, args.results)
    plan = plan_campaign(spec, args.results, verify=False)
    print(f"reclassified {n} runs" + (f"; {len(plan.archived)} archived run(s) have no run folder here to read "
                                       "(their committed labels stay)" if plan.archived else ""))
    errors = [(k, plan.records[k]["metrics"]["classify_error"]) for _, k in plan.done
              if "classify_error" in (plan.records[k].get("metrics") or {})]
    for k, e in errors:
        print(f"  no label for {k}: {e}", file=sys.stderr)
    return 1 if errors else 0


@guarded
def cmd_prune(args) -> int:
    from sweep.campaign.archive import prune_campaign

    spec = _spec(args)
    try:
        rep = prune_campaign(spec, args.results)
    except ValueError as e:
        raise UsageError(str(e)) from None
    print(f"pruned {len(rep.pruned)} runs, {rep.bytes_freed / 2**20:.1f} MiB freed; {len(rep.skipped)} left as they were")
    for k, why in rep.skipped.items():
        print(f"  {k}: {why}", file=sys.stderr)
    return 0


@guarded
def cmd_columns(args) -> int:
    from sweep.campaign.columns import column_dictionary, timeseries_dictionary
    from sweep.campaign.load import load_campaign

    spec = _spec(args)
    if args.timeseries:
        cols = timeseries_dictionary()
    else:
        try:
            table = load_campaign(spec, args.results)
        except FileNotFoundError:
            table = None
        if table is None or table.empty:
            print(f"campaign {spec.name}: no finished runs yet, so no table", file=sys.stderr)
            return 1
        name_damaged(args.spec, args.results)
        cols = column_dictionary(table)
    width = max(len(n) for n in cols["name"])
    uw = max(len(u) for u in cols["unit"])
    for name, unit, meaning in zip(cols["name"], cols["unit"], cols["meaning"]):
        print(f"{name:<{width}}  {unit:<{uw}}  {meaning}")
    return 0


def committed_specs(project) -> list[Path]:
    """The campaign specs of ``project/campaigns`` (twin campaigns of ``discrepancy/`` excepted) whose
    results folder holds a committed table."""
    from sweep.campaign.paths import results_root
    from sweep.campaign.spec import load_spec

    out = []
    for p in sorted(Path(project, "campaigns").rglob("*.toml")):
        if "discrepancy" in p.relative_to(Path(project, "campaigns")).parts:
            continue
        d = results_root(p, None) / load_spec(p).name
        if (d / "table.csv").is_file() or (d / "table.parquet").is_file():
            out.append(p)
    return out


def _each_spec(args, fn) -> int:
    """``fn(spec, root)`` on every spec of ``args`` (SPEC... and --all); prints what each wrote; exit code."""
    from sweep.campaign.spec import load_spec

    specs = [Path(s) for s in args.specs] + (committed_specs(args.project) if args.all else [])
    if not specs:
        raise UsageError("give campaign specs or --all")
    root = None if args.results is None else Path(args.results).resolve()
    rc = 0
    for s in specs:
        try:
            paths = fn(load_spec(s), root)
        except FileNotFoundError as e:
            print(f"error: {e}", file=sys.stderr)
            rc = 1
            continue
        except Exception as e:  # one campaign that cannot be drawn never stops the others
            print(f"error: {s}: {type(e).__name__}: {e}", file=sys.stderr)
            rc = 1
            continue
        print(f"{s}: " + (", ".join(Path(p).name for p in paths) or "nothing written"), flush=True)
    return rc


@guarded
def cmd_tables(args) -> int:
    from sweep.campaign.table import refresh_table

    return _each_spec(args, refresh_table)


@guarded
def cmd_redraw(args) -> int:
    from sweep.campaign.plot import plot_campaign

    return _each_spec(args, plot_campaign)


def main(argv=None) -> int:
    """Standalone entry point: the ``campaign`` subcommands without the ``dchfrac campaign`` prefix."""
    parser = argparse.ArgumentParser(prog="python -m sweep.campaign.cli")
    sub = parser.add_subparsers(dest="cmd")
    add_campaign_commands(sub)
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(["campaign", *argv])
    setup_logging()
    try:
        return int(args.func(args))
    finally:
        end_logging()


if __name__ == "__main__":
    sys.exit(main())

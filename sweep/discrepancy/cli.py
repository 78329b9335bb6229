"""``dchfrac discrepancy run --measured DIR --model SPEC --out DIR``, ``dchfrac discrepancy init --measured DIR``,
``status --cache DIR``, ``model --report OUT/report.json --model SPEC --out FILE``, ``render OUT...`` and
``coverage FOLDER... [--out JSON]`` (argparse), added by the main CLI."""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

__all__ = ["add_discrepancy_commands", "main", "show_progress", "EXIT_INCONCLUSIVE"]

#: exit code of ``discrepancy run`` when it draws no verdict (forward runs that did not reach the data)
EXIT_INCONCLUSIVE = 3


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
    """Add ``discrepancy run``, ``init``, ``status``, ``model``, ``render`` and ``coverage`` to an argparse
    subparsers object; each leaf sets ``func(args) -> int``."""
    d = subparsers.add_parser("discrepancy", help="name the missing effect between simulation and measured data",
                              description="Discrepancy workflow (see sweep/discrepancy).")
    sub = d.add_subparsers(dest="discrepancy_command", metavar="{run,init,status,model,render,coverage}")
    sub.required = True
    r = sub.add_parser("run", help="calibrate, localize, screen, refit, report")
    r.add_argument("--measured", required=True, help="measured-data folder (conditions.csv, observations.csv)")
    r.add_argument("--model", required=True, help="model SPEC (TOML)")
    r.add_argument("--out", required=True, help="output folder (report.md, report.json, figures, run cache)")
    r.add_argument("--jobs", type=int, default=None, help="parallel solver runs (default: the spec's [fit] n_jobs)")
    r.add_argument("--cache", default=None, help="forward-run cache folder (default: OUT/cache)")
    r.add_argument("--no-figures", action="store_true")
    r.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    r.add_argument("--strict", action="store_true",
                   help="refuse implausible inputs (a likely unit slip, an unresolved length) instead of warning")
    r.set_defaults(func=cmd_run)
    i = sub.add_parser("init", help="write a commented starting SPEC from a measured-data folder")
    i.add_argument("--measured", required=True, help="measured-data folder (conditions.csv, observations.csv)")
    i.add_argument("--out", default="discrepancy_spec.toml", help="SPEC file to write (default: %(default)s)")
    i.add_argument("--force", action="store_true", help="overwrite an existing SPEC file")
    i.add_argument("--strict", action="store_true",
                   help="refuse implausible inputs (e.g. observation times in ms: an implausible t_end)")
    i.set_defaults(func=cmd_init)
    st = sub.add_parser("status", help="the forward runs of a discrepancy run's cache: done, failed, in flight")
    st.add_argument("--cache", required=True, help="forward-run cache folder (a run's --cache, default OUT/cache)")
    st.set_defaults(func=cmd_status)
    m = sub.add_parser("model", help="write the named model of a report as a campaign [base] model file")
    m.add_argument("--report", required=True, help="a discrepancy run's OUT/report.json")
    m.add_argument("--model", required=True, help="the model SPEC (TOML) of that run")
    m.add_argument("--measured", default=None,
                   help="the run's measured-data folder, whose condition columns are left out of the model "
                        "(default: the columns the report records; needed for a report that does not)")
    m.add_argument("--out", default="named_model.toml", help="parameter file to write (default: %(default)s)")
    m.set_defaults(func=cmd_model)
    rd = sub.add_parser("render", help="rewrite report.md from report.json (no forward run)")
    rd.add_argument("out", nargs="+", help="a discrepancy run's --out folder (holding report.json)")
    rd.add_argument("--figures", action="store_true", help="also redraw the profile figures from the report")
    rd.set_defaults(func=cmd_render)
    from .solver_coverage import add_coverage_arguments, cmd_coverage

    cv = sub.add_parser("coverage", help="coverage of the named strength's 95 %% interval over twin results folders "
                                         "(no forward run): pooled, by effect and by correction")
    add_coverage_arguments(cv)
    cv.set_defaults(func=cmd_coverage)
    return d


def cmd_render(args) -> int:
    """Rewrite each folder's report.md from its report.json with this code's renderer (the figures made from the
    forward runs are linked where their files exist); exit 2 with one line when a folder holds no report.json,
    before any folder is written."""
    from .report import render_report

    missing = [o for o in args.out if not (Path(o) / "report.json").is_file()]
    if missing:
        print(f"dchfrac discrepancy render: {missing[0]!r} holds no report.json (a discrepancy run's --out folder "
              "does)", file=sys.stderr)
        return 2
    for o in args.out:
        print(render_report(o, figures=args.figures))
    return 0


def cmd_model(args) -> int:
    """Write the named model's condition-independent parameters (sweep.discrepancy.named_model) for a campaign's
    ``[base] model = ...``; exit 2 with one line on bad input (a tie, a missing file, an unknown parameter)."""
    from solver.output import check_writable_dir

    from .named_model import write_named_model

    try:
        check_writable_dir(Path(args.out).parent, "--out folder")
        path, verdict = write_named_model(args.report, args.model, args.measured, args.out)
    except ValueError as exc:
        print(f"dchfrac discrepancy: {exc}", file=sys.stderr)
        return 2
    what = "the named model" if verdict == "named" else f"the calibrated baseline (verdict {verdict}: no effect named)"
    print(f"wrote {path}: {what}; a campaign takes it as [base] model = \"{path}\" (relative to the spec's folder)")
    return 0


def cmd_status(args) -> int:
    """Print one line per forward run of a cache (sweep.discrepancy.forward.cache_status) and the counts: how
    far a long discrepancy run has come, read while it runs (exit 2 when the folder does not exist)."""
    from .forward import cache_status

    cache = Path(args.cache)
    if not cache.is_dir():
        print(f"dchfrac discrepancy: --cache {str(cache)!r} is not a folder (a discrepancy run's cache: --cache, "
              "default OUT/cache)", file=sys.stderr)
        return 2
    rows = cache_status(cache)
    print(f"{'key':22s} {'h (mm)':>7s} {'seed':>5s} {'status':>10s} {'t (s)':>8s} {'wall (s)':>9s}  code")
    for r in rows:
        num = (lambda v, f: "-" if v is None else format(v, f))
        print(f"{r['key']:22s} {num(r['h'], 'g'):>7s} {num(r['mesh_seed'], 'd'):>5s} {r['status']:>10s} "
              f"{num(r['t'], '.4g'):>8s} {num(r['wall_s'], '.0f'):>9s}  {'current' if r['current_code'] else 'other'}")
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "failed", "running", "unreadable")}
    other = sum(not r["current_code"] for r in rows)
    print(f"{len(rows)} runs: {counts['ok']} ok, {counts['failed']} failed, {counts['running']} running or "
          f"interrupted, {counts['unreadable']} unreadable; {other} made by other solver code")
    return 0


def cmd_init(args) -> int:
    """Validate the measured data and write a starting SPEC (exit 2 with one line on bad input)."""
    from solver.output import check_writable_dir

    from .init_spec import write_starting_spec

    try:
        check_writable_dir(Path(args.out).parent, "--out folder")
        path, warnings = write_starting_spec(args.measured, args.out, force=args.force,
                                             strict=getattr(args, "strict", False))
    except ValueError as exc:
        print(f"dchfrac discrepancy: {exc}", file=sys.stderr)
        return 2
    for w in warnings:
        print(f"dchfrac discrepancy: warning: {w}", file=sys.stderr)
    print(f"wrote {path}: edit it, then dchfrac discrepancy run --measured {args.measured} --model {path} --out OUT")
    from .data import load_measured
    from .init_spec import too_few_conditions

    if note := too_few_conditions(load_measured(args.measured), args.measured):
        print(f"warning: {note}", file=sys.stderr)
    return 0


def cmd_run(args) -> int:
    """Run the workflow: exit 0 with a verdict, 2 on bad input (one line, before any forward run),
    EXIT_INCONCLUSIVE (3) when the forward runs did not reach the observation times (no verdict)."""
    from solver import RunOptions
    from solver.options import check_environment
    from solver.output import check_writable_dir

    from .checks import check_data_against_model
    from .data import load_measured
    from .heldout import heldout_data
    from .forward import SolverForward, fine_forwards
    from .observables import ObservableUnavailable
    from .report import ROUGH_NOTE, interval_caveats
    from .spec import load_spec
    from .workflow import run_workflow

    out = Path(args.out)
    cache = Path(args.cache) if args.cache else out / "cache"
    try:  # bad input and unwritable outputs: one line, before any forward run
        data = load_measured(args.measured)
        spec = load_spec(args.model)
        check_writable_dir(out, "--out")
        check_writable_dir(cache, "--cache")
        jobs = args.jobs if args.jobs is not None else spec.fit.n_jobs
        if args.jobs is not None and not 1 <= args.jobs <= 256:
            raise ValueError(f"--jobs {args.jobs} is not allowed: an integer in [1, 256] (as [fit] n_jobs)")
        fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), cache, n_jobs=jobs)
        fine = fine_forwards(spec, cache, jobs)      # one per mesh realization ([discretization] mesh_seeds)
        data = heldout_data(data, spec)             # [holdout] observables
        warnings = check_data_against_model(data, spec, [fwd, *fine], strict=getattr(args, "strict", False))
        warnings += check_environment()
    except ValueError as exc:
        print(f"dchfrac discrepancy: {exc}", file=sys.stderr)
        return 2
    for w in warnings:
        print(f"dchfrac discrepancy: warning: {w}", file=sys.stderr)
    if not getattr(args, "logging_configured", False):  # `dchfrac -v/-q discrepancy ...` set it already
        show_progress(args.quiet)
    try:
        rep = run_workflow(data, spec, fwd, out, figures=not args.no_figures, fine_forward=fine)
    except ObservableUnavailable as exc:       # the solver's time series lacks an observable's column
        print(f"dchfrac discrepancy: {exc}", file=sys.stderr)
        return 2
    if rep["verdict"] == "inconclusive":       # a verdict never rests on runs that did not reach the data
        from .workflow import failed_text

        for stage, failed in rep["failed_points"].items():
            print(f"dchfrac discrepancy: no verdict: at the {stage} the forward runs did not reach "
                  f"{failed_text(failed)}; report in {out / 'report.md'}", file=sys.stderr)
        return EXIT_INCONCLUSIVE
    print(f"verdict: {rep['verdict']}" + (f"; named effect {rep['named_effect']} = {rep['strength']:.4g} "
                                          f"{rep['strength_interval']}"
                                          + (f" ({ROUGH_NOTE})" if rep.get("strength_interval_rough") else "")
                                          + (f" ({interval_caveats(rep)[2:]})" if interval_caveats(rep) else "")
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

"""The ``dchfrac`` command line.

    dchfrac [--version] [-v | -q] COMMAND ...
    dchfrac run [--preset NAME] [--config FILE] [--set name=value ...] --out DIR [--h 1.0] [--t-end 2.0]
    dchfrac params                                   (every parameter: unit, default, allowed range)
    dchfrac warmup                                   (compile the numba kernels ahead of the first run)
    dchfrac balance RUN [RUN ...] --out FIG.png      (volume balance by phase: water and oil in, stored, out)
    dchfrac animate RUN [--fields S,phi,d,p] [--out FILE] [--fps 6]
    dchfrac bench [--out results/bench/bench.json] [--quick] [--reference] [--profile [--h H] [--t-end T]]
    dchfrac campaign run|status|plot|report SPEC ...
    dchfrac report reference|convergence RUN... --out DIR
    dchfrac discrepancy run --measured DIR --model SPEC --out DIR
"""
from __future__ import annotations

import argparse
import ast
import logging
import sys
from pathlib import Path

LOG = logging.getLogger("dchfrac")


def _parse_value(text: str):
    """A Python literal (numbers, lists, None, True/False), TOML's true/false, else the text itself."""
    if text in ("true", "false"):
        return text == "true"
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _split_sets(pairs, flag: str = "--set"):
    out = {}
    for item in pairs or []:
        if "=" not in item:
            raise ValueError(f"{flag} {item!r} is not allowed: name=value")
        k, v = item.split("=", 1)
        out[k.strip()] = _parse_value(v.strip())
    return out


def _load_config(path):
    """A TOML file with optional [parameters] and [options] tables (or a flat parameter table).

    Raises ValueError naming the file when it is missing, is not TOML, or its tables are not tables."""
    from solver.tomlio import TOMLDecodeError, read_toml

    if not Path(path).is_file():
        raise ValueError(f"--config {str(path)!r}: file not found (allowed: a TOML file with [parameters] "
                         "and [options] tables)")
    try:
        data = read_toml(path)
    except TOMLDecodeError as exc:            # its message names the file
        raise ValueError(f"--config: not valid TOML: {exc}") from None
    if "parameters" not in data and "options" not in data:
        return data, {}
    tables = data.get("parameters", {}), data.get("options", {})
    for name, t in zip(("parameters", "options"), tables):
        if not isinstance(t, dict):
            raise ValueError(f"--config {str(path)!r}: [{name}] = {t!r} is not allowed: a table")
    extra = sorted(set(data) - {"parameters", "options"})
    if extra:
        raise ValueError(f"--config {str(path)!r}: unknown key(s) {extra} next to [parameters] and [options]")
    return dict(tables[0]), dict(tables[1])


# snapshots of ``dchfrac run`` besides t = 0 and snapshot_times, unless --set frames=N or a --config says
# otherwise (RunOptions.frames; ``dchfrac animate RUN`` then has a movie of CLI_FRAMES + 1 frames)
CLI_FRAMES = 20


def _run_inputs(args):
    """(Parameters, RunOptions, warnings) of ``dchfrac run``, validated together with the output folder.

    Raises ValueError naming the input, its value and what is allowed."""
    from solver import Parameters, RunOptions
    from solver.options import check_environment, check_run_inputs
    from solver.output import check_writable_dir

    pdict, odict = _load_config(args.config) if args.config else ({}, {})
    if getattr(args, "preset", None):
        from solver.presets import preset_changes

        pdict = {**preset_changes(args.preset), **pdict}
    opt_names = set(RunOptions.__dataclass_fields__)
    for k, v in _split_sets(args.set).items():
        (odict if k in opt_names else pdict)[k] = v
    for flag, name, v in (("--h", "h", args.h), ("--t-end", "t_end", args.t_end)):
        if v is not None and name in odict and odict[name] != v:
            raise ValueError(f"{flag} {v:g} conflicts with {name}={odict[name]!r} of --set/--config "
                             "(allowed: one value, given once)")
        if v is not None:
            odict[name] = v
    unknown = sorted(set(pdict) - set(Parameters.__dataclass_fields__))
    if unknown:
        from solver.plausible import did_you_mean

        raise ValueError(f"unknown parameter or run option {unknown[0]!r}"
                         f"{did_you_mean(unknown, [*Parameters.__dataclass_fields__, *opt_names])} "
                         "(allowed: the names `dchfrac params` lists)")
    odict.setdefault("frames", CLI_FRAMES)  # a run from the command line is animated: evenly spaced snapshots
    params = Parameters.from_dict(pdict)
    options = RunOptions.from_dict(odict)
    warnings = check_run_inputs(params, options) + check_environment()
    if getattr(args, "strict", False) and warnings:
        raise ValueError(f"--strict refuses: {warnings[0]}"
                         + (f" (and {len(warnings) - 1} more warning(s))" if len(warnings) > 1 else ""))
    _check_run_out(args.out, getattr(args, "force", False))
    if not getattr(args, "force", False):  # a run that cannot fit in memory: refused before anything is written
        from solver.budget import check_fits

        check_fits(params, options)
    check_writable_dir(args.out, "--out")
    return params, options, warnings


def _check_run_out(out: str, force: bool) -> None:
    """``--out``: a folder name (not empty), and not an existing run folder unless ``force`` or it holds a
    checkpoint (a run killed part-way, which resumes: ``solver.checkpoint``)."""
    from solver.checkpoint import NAME

    if not str(out).strip():
        raise ValueError("--out '' is not allowed: a run folder name")
    if (Path(out) / "summary.json").exists() and not force and not (Path(out) / NAME).exists():
        raise ValueError(f"--out {str(out)!r} is an existing run folder (allowed: a new folder, a run killed "
                         f"part-way with its {NAME}, which resumes, or --force to overwrite it)")


def cmd_run(args) -> int:
    try:  # bad input: one clear line before any work (and before the solver's libraries load)
        params, options, warnings = _run_inputs(args)
    except ValueError as exc:
        print(f"dchfrac run: {exc}", file=sys.stderr)
        return 2
    from solver import simulate

    for w in warnings:
        LOG.warning("dchfrac run: warning: %s", w)
    if LOG.isEnabledFor(logging.INFO):
        from solver.budget import estimate_run

        LOG.info("dchfrac run: estimate: %s", estimate_run(params, options).line())
    res = simulate(params, options, out_dir=args.out, progress=not args.quiet and LOG.isEnabledFor(logging.INFO),
                   check_memory=not args.force, resume=not args.force)
    ts = res.timeseries
    last = ts.iloc[-1] if len(ts) else None
    print(f"status: {res.status}" + (f" ({res.reason})" if res.reason else ""))
    if last is not None:
        print(f"t = {last['t']:.4g} s, p_inj = {last['p_inj']:.1f} kPa, front = {last['front_radius_mean']:.1f} mm, "
              f"open tip = {last['open_tip_radius']:.1f} mm, mean damage = {last['mean_damage']:.3g}")
    print(f"wall time {res.wall_time:.1f} s, {res.factorizations} factorizations, {len(res.rejected_steps)} rejected steps; output in {args.out}")
    return 0 if res.status == "ok" else 1


def _writable_or_exit(command: str, path, what: str) -> int | None:
    """2 (after one line on stderr) if the folder ``path`` cannot be written, else None."""
    from solver.output import check_writable_dir

    try:
        check_writable_dir(path, what)
    except ValueError as exc:
        print(f"dchfrac {command}: {exc}", file=sys.stderr)
        return 2
    return None


def _bench_options(pairs: list[str]) -> dict:
    """``KEY=VALUE`` run options of ``dchfrac bench --profile --option``, validated as RunOptions before any
    run; returns {key: value}."""
    from solver import RunOptions

    out = _split_sets(pairs, "--option")
    RunOptions.from_dict({**RunOptions().to_dict(), **out})  # names and ranges checked before any run
    return out


def _bench_model(preset: str | None, pairs: list[str]) -> dict | None:
    """The model of ``dchfrac bench --profile --preset NAME --set KEY=VALUE``, validated as Parameters before any
    run: {"preset": name, "changes": {key: value}}, or None (the reference case)."""
    from solver import Parameters
    from solver.presets import preset_changes

    if preset is None and not pairs:
        return None
    changes = _split_sets(pairs, "--set")
    Parameters.from_dict({**(preset_changes(preset) if preset else {}), **changes})  # names and ranges checked
    return {"preset": preset, "changes": changes}


def cmd_bench(args) -> int:
    from .studies.bench import run_benchmarks, run_profile

    out = args.out or ("results/bench/profile.json" if args.profile else "results/bench/bench.json")
    bad = _writable_or_exit("bench", Path(out).parent, "--out folder")
    if bad:
        return bad
    if args.profile:
        sizes = args.h or ([2.0, 1.0] if args.reference else [2.0])
        bad = [h for h in sizes if not 0 < h <= 24]
        t_end = 2.0 if args.t_end is None else args.t_end
        if bad:
            print(f"dchfrac bench: --h {bad[0]!r} is out of range: allowed 0 < h <= 24 (mm)", file=sys.stderr)
            return 2
        if not t_end > 0:
            print(f"dchfrac bench: --t-end {t_end!r} is out of range: allowed > 0 (s)", file=sys.stderr)
            return 2
        try:
            options = _bench_options(args.option or [])
            compare = _bench_options(args.compare) if args.compare else None
            model = _bench_model(args.preset, args.set or [])
        except ValueError as e:
            print(f"dchfrac bench: {e}", file=sys.stderr)
            return 2
        run_profile(out, sizes, t_end, options=options, compare=compare, model=model)
        return 0
    if args.h or args.t_end is not None or args.option or args.compare or args.preset or args.set:
        print("dchfrac bench: --h, --t-end, --option, --compare, --preset and --set apply only with --profile",
              file=sys.stderr)
        return 2
    run_benchmarks(out, quick=args.quick, reference=args.reference)
    return 0


def cmd_warmup(args) -> int:
    """Compile (or load) the numba kernels ahead of the first run (solver.simulate.warmup)."""
    from solver.simulate import warmup
    from solver.paths import describe

    print(describe())
    res = warmup()
    print(f"kernels {'compiled' if res['compiled'] else 'already in the cache'} ({res['wall_s']:.0f} s)")
    return 0


def _check_report_runs(kind: str, runs: list) -> None:
    """The run folders of ``report``: one for "reference", several for "convergence", each with the files the
    report reads (timeseries.csv, options.toml; snapshots/mesh.npz for "reference").  ValueError naming the first
    that is not."""
    if kind == "reference" and len(runs) != 1:
        raise ValueError(f"report reference takes exactly one run folder, got {len(runs)}")
    if kind == "convergence" and len(runs) < 2:
        raise ValueError(f"report convergence takes two or more run folders (mesh sizes), got {len(runs)}")
    need = ("timeseries.csv", "options.toml") + (("snapshots/mesh.npz",) if kind == "reference" else ())
    for r in runs:
        missing = [f for f in need if not (Path(r) / f).is_file()]
        if missing:
            raise ValueError(f"run {str(r)!r} is not a run folder: no {missing[0]} (allowed: folders written by "
                             "`dchfrac run`)")


def cmd_report(args) -> int:
    from .studies.reference import convergence_report, reference_report

    bad = _writable_or_exit("report", args.out, "--out")
    if bad:
        return bad
    try:            # before anything is written
        _check_report_runs(args.kind, args.runs)
    except ValueError as exc:
        print(f"dchfrac report: {exc}", file=sys.stderr)
        return 2
    if args.kind == "reference":
        res = reference_report(args.runs[0], args.out, args.paper)
        print(res["table"].to_string(index=False))
    else:
        print(convergence_report(args.runs, args.out).to_string(index=False))
    print(f"written to {args.out}")
    return 0


def cmd_balance(args) -> int:
    """Plot the volume balance by phase of one or more runs (sweep.studies.balance); bad input: one line, exit code 2."""
    from .studies.balance import plot_phase_balance

    labels = args.labels.split(",") if args.labels else [Path(r).name for r in args.runs]
    try:
        if len(labels) != len(args.runs):
            raise ValueError(f"--labels {args.labels!r}: allowed one label per run ({len(args.runs)})")
        bad = _writable_or_exit("balance", Path(args.out).parent, "--out")
        if bad:
            return bad
        path = plot_phase_balance(dict(zip(labels, args.runs)), args.out)
    except ValueError as exc:
        print(f"dchfrac balance: {exc}", file=sys.stderr)
        return 2
    print(f"written to {path}")
    return 0


def cmd_animate(args) -> int:
    """Animate a run folder's snapshots (MP4 with ffmpeg, else GIF); bad input: one line, exit code 2."""
    from solver.output import check_writable_dir

    from .animate import animate_run, animation_writer, check_animatable, parse_fields

    run = Path(args.run)
    try:
        fields = parse_fields(args.fields)
        animation_writer(args.out)
        if args.out is not None:
            check_writable_dir(Path(args.out).resolve().parent, "--out folder")
        if not (run / "snapshots" / "mesh.npz").is_file():
            raise ValueError(f"run {str(run)!r}: not a run folder (no snapshots/mesh.npz)")
        if args.fps < 1:
            raise ValueError(f"--fps {args.fps}: allowed an integer >= 1")
        check_animatable(run, fields)
    except ValueError as exc:
        print(f"dchfrac animate: {exc}", file=sys.stderr)
        return 2
    print(f"animation: {animate_run(run, fields, args.out, fps=args.fps)}")
    return 0


def cmd_params(args) -> int:
    """Print every model parameter (unit, default, allowed range, meaning) and every run option."""
    from dataclasses import fields

    from solver.options import OPTION_UNITS, RunOptions, option_docs
    from solver.params import parameter_table

    def _allowed(r) -> str:
        plaus = "" if r["plausible"] is None else "; plausible: [{:g}, {:g}]".format(*r["plausible"])
        return f"{r['meaning']} [allowed: {r['allowed']}{plaus}]"

    rows = [(r["name"], r["unit"] or "", _show(r["default"]), _allowed(r)) for r in parameter_table()]
    _print_rows("model parameters (units mm, s, kPa; None: follows its law of the cement ratio C; outside the "
                "plausible range a run warns, --strict refuses)",
                ("name", "unit", "default", "meaning [allowed values]"), rows)
    from solver.presets import preset_changes, preset_description, preset_names

    print()
    _print_rows("presets (dchfrac run --preset NAME; changes from the defaults above)", ("name", "changes", "what"),
                [(n, ", ".join(f"{k}={_show(v)}" for k, v in preset_changes(n).items()) or "(none)",
                  preset_description(n)) for n in preset_names()])
    docs = option_docs()
    rows = [(f.name, OPTION_UNITS.get(f.name, "?"), _show(getattr(RunOptions(), f.name)), docs.get(f.name, ""))
            for f in fields(RunOptions)]
    print()
    _print_rows("run options (discretization and outputs; set them like parameters with --set)",
                ("name", "unit", "default", "meaning"), rows)
    return 0


def _preset_names() -> list[str]:
    from solver.presets import preset_names

    return preset_names()


def _show(v) -> str:
    return "None" if v is None else str(list(v) if isinstance(v, tuple) else v)


def plain_text(text: str) -> str:
    """A docstring fragment without its reStructuredText markup (``x``, :func:`x`, :meth:`x` -> x)."""
    import re

    return re.sub(r"``([^`]*)``", r"\1", re.sub(r":\w+:`~?([^`]*)`", r"\1", str(text)))


def _print_rows(title, header, rows, width: int | None = None) -> None:
    """A table whose short columns are aligned and whose last one (the meaning) is wrapped to the terminal
    (``width`` characters, default the terminal's), in plain text."""
    import shutil
    import textwrap

    width = width or shutil.get_terminal_size((100, 24)).columns
    rows = [tuple(r[:-1]) + (plain_text(r[-1]),) for r in rows]
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
    lead = sum(widths[:-1]) + 2 * (len(widths) - 1)
    room = width - lead
    if room < 30:  # too narrow beside the columns: the meaning goes below, indented
        lead, room = 4, max(20, width - 4)
    print(title)
    for r in (header, *rows):
        cols = "  ".join(str(x).ljust(w) for x, w in zip(r[:-1], widths))
        lines = textwrap.wrap(str(r[-1]), room) or [""]
        if lead == 4:
            print(cols.rstrip())
            print("\n".join(" " * 4 + ln for ln in lines))
        else:
            print(cols + "  " + lines[0])
            for ln in lines[1:]:
                print(" " * lead + ln)


def version_text() -> str:
    """``dchfrac VERSION``, plus the code hash when the solver provides ``solver.code_hash()``."""
    import solver

    from importlib.metadata import PackageNotFoundError, version

    try:
        text = f"dchfrac {version('dchfrac')}"
    except PackageNotFoundError:
        text = "dchfrac (not installed)"
    code_hash = getattr(solver, "code_hash", None)
    if callable(code_hash):
        text += f" (code {code_hash()})"
    from solver.paths import describe

    return text + "\n" + describe()


class _VersionAction(argparse.Action):
    """``--version``: the version text, computed only when asked (the code hash reads the sources)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        try:
            print(version_text())
        except ValueError as exc:  # an invalid DCHFRAC_KERNELS / DCHFRAC_LINEAR_SOLVER
            parser.exit(2, f"dchfrac: {exc}\n")
        parser.exit()


def _run_epilog() -> str:
    from dataclasses import fields

    from solver.options import RunOptions
    from solver.params import Parameters
    import textwrap

    wrap = lambda names: textwrap.fill(", ".join(names), 100, initial_indent="  ", subsequent_indent="  ")  # noqa: E731
    return ("--set accepts these model parameters (units, defaults and ranges: `dchfrac params`):\n"
            + wrap([f.name for f in fields(Parameters)]) + "\nand these run options:\n"
            + wrap([f.name for f in fields(RunOptions)]) + "\nValues are Python literals: --set cement=1.2 "
            "--set porosity_field=pockets --set snapshot_times=[0.5,1.0].")


def _verbosity(p: argparse.ArgumentParser, top: bool) -> None:
    """``-v`` / ``-q`` on a parser; below the top they only override when given (SUPPRESS defaults)."""
    d = {} if top else {"default": argparse.SUPPRESS}
    p.add_argument("-v", "--verbose", action="count", help="more log output (-v: debug)", **({"default": 0} if top else d))
    p.add_argument("-q", dest="less", action="count",
                   help="less log output (-q: warnings only, -qq: errors only)", **({"default": 0} if top else d))


def _leaf_parsers(p: argparse.ArgumentParser):
    subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield p
    for a in subs:
        for child in dict.fromkeys(a.choices.values()):
            yield from _leaf_parsers(child)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="dchfrac", description="Darcy–Cahn–Hilliard fluid-driven fracture: runs, benchmarks, campaigns (units mm, s, kPa)")
    ap.add_argument("--version", action=_VersionAction, help="print the version (and the code hash) and exit")
    _verbosity(ap, top=True)
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one simulation", epilog=_run_epilog(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--config", help="TOML with [parameters] and [options] tables")
    r.add_argument("--preset", help="named model the parameters start from (--config and --set override it): "
                                    "one of " + ", ".join(_preset_names()) + " (`dchfrac params` lists them)")
    r.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter or run option (names below)")
    r.add_argument("--out", required=True, help="run folder")
    r.add_argument("--h", type=float, help="mesh size, mm")
    r.add_argument("--t-end", type=float, help="final time, s")
    r.add_argument("--quiet", action="store_true", help="no progress bar / progress lines")
    r.add_argument("--strict", action="store_true",
                   help="refuse implausible inputs (a likely unit slip, an unresolved length) instead of warning")
    r.add_argument("--force", action="store_true",
                   help="overwrite an existing run folder --out, and run even when the estimated memory exceeds what "
                        "is available (solver.budget)")
    r.set_defaults(func=cmd_run)
    an = sub.add_parser("animate", help="animate a run's snapshots (MP4 with ffmpeg, else GIF)",
                        description="Animate a run folder's snapshots: one panel per field, fixed colour scales, "
                                    "time stamp. Dense snapshots: run with --set frames=N.")
    an.add_argument("run", help="run folder")
    an.add_argument("--fields", default="S,phi,d,p", help="comma-separated snapshot fields (default S,phi,d,p)")
    an.add_argument("--out", default=None, help="output file, .mp4 (needs ffmpeg) or .gif (default RUN/animation.mp4|gif)")
    an.add_argument("--fps", type=int, default=6, help="frames per second (default 6)")
    an.set_defaults(func=cmd_animate)
    ba = sub.add_parser("balance", help="plot water and oil in, stored and out over time (volume balance by phase)")
    ba.add_argument("runs", nargs="+", help="run folder(s), one panel each")
    ba.add_argument("--out", required=True, help="figure file (.png or .pdf)")
    ba.add_argument("--labels", default=None, metavar="A,B", help="panel titles, one per run (default: folder names)")
    ba.set_defaults(func=cmd_balance)
    pa = sub.add_parser("params", help="list every model parameter with unit, default and allowed range, and the run options")
    pa.set_defaults(func=cmd_params)
    b = sub.add_parser("bench", help="performance benchmarks (JSON)")
    b.add_argument("--out", help="JSON file (default results/bench/bench.json, with --profile results/bench/profile.json)")
    b.add_argument("--quick", action="store_true", help="skip h = 0.5 mm and shorten the coupled run")
    b.add_argument("--reference", action="store_true", help="also time the full reference run (h = 1 mm to 2 s)")
    b.add_argument("--profile", action="store_true",
                   help="wall time of the reference run split by phase and part of the run (h = 2 mm; with --reference also h = 1 mm)")
    b.add_argument("--h", type=float, action="append", help="with --profile: mesh size(s) to profile, mm (repeatable)")
    b.add_argument("--t-end", type=float, help="with --profile: final time, s (default 2)")
    b.add_argument("--option", action="append", metavar="KEY=VALUE",
                   help="with --profile: a run option of the profiled runs (repeatable), e.g. anderson_depth=3")
    b.add_argument("--compare", action="append", metavar="KEY=VALUE",
                   help="with --profile: a variant's run option (repeatable); each size runs base, variant, base, "
                        "variant side by side in time and reports the wall-time ratio and the change of p_inj")
    b.add_argument("--preset", help="with --profile: the named model the profiled runs start from (default: the "
                                    "reference case)")
    b.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="with --profile: a model parameter of the profiled runs (repeatable), e.g. porosity_floor=0.1")
    b.set_defaults(func=cmd_bench)
    w = sub.add_parser("warmup", help="compile the numba kernels ahead of the first run (about a minute of CPU, once)")
    w.set_defaults(func=cmd_warmup)
    rp = sub.add_parser("report", help="figures and paper comparison of a reference run or a mesh-convergence set")
    rp.add_argument("kind", choices=["reference", "convergence"])
    rp.add_argument("runs", nargs="+", help="run folder(s)")
    rp.add_argument("--out", required=True)
    rp.add_argument("--paper", help="path to paper_reported.toml (default: the shared file beside the project, else the copy shipped with the package)")
    rp.set_defaults(func=cmd_report)
    from .campaign.cli import add_campaign_commands
    from .discrepancy.cli import add_discrepancy_commands
    from .studies.commands import add_closure_command, add_cracks_command, add_judge_command, add_provenance_command

    add_campaign_commands(sub)
    add_judge_command(sub)
    add_closure_command(sub)
    add_cracks_command(sub)
    add_provenance_command(sub)
    add_discrepancy_commands(sub)
    for leaf in _leaf_parsers(ap):
        if leaf is not ap:
            _verbosity(leaf, top=False)
    return ap


def main(argv=None) -> int:
    from .campaign.logs import end_logging, setup_logging

    from solver.paths import check_environment

    args = build_parser().parse_args(argv)
    try:  # the path-forcing environment variables: one line before any work
        check_environment()
    except ValueError as exc:
        print(f"dchfrac: {exc}", file=sys.stderr)
        return 2
    setup_logging(args.verbose, args.less)
    args.logging_configured = True
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # `dchfrac ... | head`: the reader left; not an error of ours
        return 0
    finally:
        end_logging()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""The ``dchfrac`` command line.

    dchfrac run [--config FILE] [--set name=value ...] --out DIR [--h 1.0] [--t-end 2.0]
    dchfrac bench [--out results/bench/bench.json] [--quick]
    dchfrac campaign run|status|plot|report SPEC ...
    dchfrac report reference|convergence RUN... --out DIR
    dchfrac discrepancy run --measured DIR --model SPEC --out DIR
"""
from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path


def _parse_value(text: str):
    """A Python literal (numbers, lists, None, True/False), TOML's true/false, else the text itself."""
    if text in ("true", "false"):
        return text == "true"
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _split_sets(pairs):
    out = {}
    for item in pairs or []:
        if "=" not in item:
            raise ValueError(f"--set {item!r} is not allowed: name=value")
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
    except (TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"--config {str(path)!r}: not valid TOML ({exc})") from None
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


def _run_inputs(args):
    """(Parameters, RunOptions, warnings) of ``dchfrac run``, validated together with the output folder.

    Raises ValueError naming the input, its value and what is allowed."""
    from solver import Parameters, RunOptions
    from solver.options import check_run_inputs
    from solver.output import check_writable_dir

    pdict, odict = _load_config(args.config) if args.config else ({}, {})
    opt_names = set(RunOptions.__dataclass_fields__)
    for k, v in _split_sets(args.set).items():
        (odict if k in opt_names else pdict)[k] = v
    if args.h is not None:
        odict["h"] = args.h
    if args.t_end is not None:
        odict["t_end"] = args.t_end
    params = Parameters.from_dict(pdict)
    options = RunOptions.from_dict(odict)
    warnings = check_run_inputs(params, options)
    check_writable_dir(args.out, "--out")
    return params, options, warnings


def cmd_run(args) -> int:
    from solver import simulate

    try:  # bad input: one clear line before any work
        params, options, warnings = _run_inputs(args)
    except ValueError as exc:
        print(f"dchfrac run: {exc}", file=sys.stderr)
        return 2
    for w in warnings:
        print(f"dchfrac run: warning: {w}", file=sys.stderr)
    res = simulate(params, options, out_dir=args.out, progress=not args.quiet)
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


def cmd_bench(args) -> int:
    from .bench import run_benchmarks

    bad = _writable_or_exit("bench", Path(args.out).parent, "--out folder")
    if bad:
        return bad
    run_benchmarks(args.out, quick=args.quick, reference=args.reference)
    return 0


def cmd_report(args) -> int:
    from .reference import convergence_report, reference_report

    bad = _writable_or_exit("report", args.out, "--out")
    if bad:
        return bad
    if args.kind == "reference":
        if len(args.runs) != 1:
            raise SystemExit("dchfrac report reference takes exactly one run folder")
        res = reference_report(args.runs[0], args.out, args.paper)
        print(res["table"].to_string(index=False))
    else:
        print(convergence_report(args.runs, args.out).to_string(index=False))
    print(f"written to {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="dchfrac", description="Darcy–Cahn–Hilliard fluid-driven fracture: runs, benchmarks, campaigns (units mm, s, kPa)")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one simulation")
    r.add_argument("--config", help="TOML with [parameters] and [options] tables")
    r.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter or run option")
    r.add_argument("--out", required=True, help="run folder")
    r.add_argument("--h", type=float, help="mesh size, mm")
    r.add_argument("--t-end", type=float, help="final time, s")
    r.add_argument("--quiet", action="store_true", help="no progress line")
    r.set_defaults(func=cmd_run)
    b = sub.add_parser("bench", help="performance benchmarks (JSON)")
    b.add_argument("--out", default="results/bench/bench.json")
    b.add_argument("--quick", action="store_true", help="skip h = 0.5 mm and shorten the coupled run")
    b.add_argument("--reference", action="store_true", help="also time the full reference run (h = 1 mm to 2 s)")
    b.set_defaults(func=cmd_bench)
    rp = sub.add_parser("report", help="figures and paper comparison of a reference run or a mesh-convergence set")
    rp.add_argument("kind", choices=["reference", "convergence"])
    rp.add_argument("runs", nargs="+", help="run folder(s)")
    rp.add_argument("--out", required=True)
    rp.add_argument("--paper", help="path to paper_reported.toml (default: ../shared/data/)")
    rp.set_defaults(func=cmd_report)
    try:
        from .campaign_cli import add_campaign_commands

        add_campaign_commands(sub)
    except ImportError as exc:  # pragma: no cover - campaign module missing
        print(f"(campaign commands unavailable: {exc})", file=sys.stderr)
    from .discrepancy.cli import add_discrepancy_commands

    add_discrepancy_commands(sub)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

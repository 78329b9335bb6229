"""The ``dchfrac`` command line.

    dchfrac run [--config FILE] [--set name=value ...] --out DIR [--h 1.0] [--t-end 2.0]
    dchfrac bench [--out results/bench/bench.json] [--quick] [--reference] [--profile [--h H] [--t-end T]]
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
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _split_sets(pairs):
    out = {}
    for item in pairs or []:
        if "=" not in item:
            raise SystemExit(f"--set expects name=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = _parse_value(v.strip())
    return out


def _load_config(path):
    """A TOML file with optional [parameters] and [options] tables (or a flat parameter table)."""
    from solver.tomlio import read_toml

    data = read_toml(path)
    if "parameters" in data or "options" in data:
        return dict(data.get("parameters", {})), dict(data.get("options", {}))
    return data, {}


def cmd_run(args) -> int:
    from solver import Parameters, RunOptions, simulate
    from solver.options import RunOptions as RO

    pdict, odict = _load_config(args.config) if args.config else ({}, {})
    opt_names = {f for f in RO.__dataclass_fields__}
    for k, v in _split_sets(args.set).items():
        (odict if k in opt_names else pdict)[k] = v
    if args.h is not None:
        odict["h"] = args.h
    if args.t_end is not None:
        odict["t_end"] = args.t_end
    try:
        params = Parameters.from_dict(pdict)
        options = RunOptions.from_dict(odict)
    except ValueError as exc:  # bad input: a clear message before any work
        print(f"dchfrac run: {exc}", file=sys.stderr)
        return 2
    res = simulate(params, options, out_dir=args.out, progress=not args.quiet)
    ts = res.timeseries
    last = ts.iloc[-1] if len(ts) else None
    print(f"status: {res.status}" + (f" ({res.reason})" if res.reason else ""))
    if last is not None:
        print(f"t = {last['t']:.4g} s, p_inj = {last['p_inj']:.1f} kPa, front = {last['front_radius_mean']:.1f} mm, "
              f"open tip = {last['open_tip_radius']:.1f} mm, mean damage = {last['mean_damage']:.3g}")
    print(f"wall time {res.wall_time:.1f} s, {res.factorizations} factorizations, {len(res.rejected_steps)} rejected steps; output in {args.out}")
    return 0 if res.status == "ok" else 1


def cmd_bench(args) -> int:
    from .bench import run_benchmarks, run_profile

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
        run_profile(args.out or "results/bench/profile.json", sizes, t_end)
        return 0
    if args.h or args.t_end is not None:
        print("dchfrac bench: --h and --t-end apply only with --profile", file=sys.stderr)
        return 2
    run_benchmarks(args.out or "results/bench/bench.json", quick=args.quick, reference=args.reference)
    return 0


def cmd_report(args) -> int:
    from .reference import convergence_report, reference_report

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
    b.add_argument("--out", help="JSON file (default results/bench/bench.json, with --profile results/bench/profile.json)")
    b.add_argument("--quick", action="store_true", help="skip h = 0.5 mm and shorten the coupled run")
    b.add_argument("--reference", action="store_true", help="also time the full reference run (h = 1 mm to 2 s)")
    b.add_argument("--profile", action="store_true",
                   help="wall time of the reference run split by phase and part of the run (h = 2 mm; with --reference also h = 1 mm)")
    b.add_argument("--h", type=float, action="append", help="with --profile: mesh size(s) to profile, mm (repeatable)")
    b.add_argument("--t-end", type=float, help="with --profile: final time, s (default 2)")
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

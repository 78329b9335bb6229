"""The argparse front of the study commands ``dchfrac closure``, ``dchfrac cracks``, ``dchfrac judge`` and
``dchfrac provenance``.

A command's module (:mod:`sweep.studies.closure`, :mod:`sweep.studies.cracks`, :mod:`sweep.studies.protocols`) loads
pandas, scipy.ndimage and matplotlib; it is imported when its command runs, not when the ``dchfrac`` parser is built
(every command's parser is built before ``dchfrac run`` checks its input).  A command's description is the first
paragraph of its module's docstring, read from the source without importing it.  Units: mm, s, kPa.
"""
from __future__ import annotations

import ast
from importlib import import_module
from importlib.util import find_spec
from pathlib import Path

__all__ = ["add_closure_command", "add_cracks_command", "add_judge_command", "add_provenance_command", "PROTOCOL_NAMES"]

#: the judging protocols of ``dchfrac judge`` (sweep.studies.protocols.PROTOCOLS)
PROTOCOL_NAMES = ("draws", "pockets", "pockets_tip", "experiment_lines", "nf_nb_draws", "nf_nb_quadrants")


def _deferred(module: str, name: str):
    """The command function ``module.name``, imported when the command runs."""
    def run(args) -> int:
        return getattr(import_module(module), name)(args)

    run.__qualname__ = run.__name__ = name
    return run


def _doc_head(module: str) -> str:
    """The first paragraph of ``module``'s docstring, read from its source file."""
    source = Path(find_spec(module).origin).read_text(encoding="utf-8")
    return (ast.get_docstring(ast.parse(source)) or "").split("\n\n")[0]


def add_closure_command(subparsers):
    """``dchfrac closure CAMPAIGN_DIR --out F.json [--md F.md]`` (:mod:`sweep.studies.closure`)."""
    mod = "sweep.studies.closure"
    c = subparsers.add_parser("closure", help="the closing probes' per-run quantities (crack, p_inj, outflow, rings)",
                              description=_doc_head(mod))
    c.add_argument("campaign_dir", type=Path, help="the campaign's store folder (with runs/)")
    c.add_argument("--out", type=Path, required=True, help="JSON, one entry per ok run")
    c.add_argument("--md", type=Path, help="Markdown tables")
    c.set_defaults(func=_deferred(mod, "cmd_closure"))
    return c


def add_cracks_command(subparsers):
    """``dchfrac cracks history|separatrix ...`` (see :mod:`sweep.studies.cracks`)."""
    mod = "sweep.studies.cracks"
    c = subparsers.add_parser("cracks", help="the crack over a run's life: per-snapshot history, longest-crack separatrix")
    sub = c.add_subparsers(dest="cracks_command", required=True)
    h = sub.add_parser("history", help="the classifier's crack at every snapshot of a campaign's runs (CSV)")
    h.add_argument("campaign_dir", type=Path, help="the campaign's store folder (with runs/)")
    h.add_argument("--out", type=Path, required=True, help="CSV, one row per snapshot (rows of pruned runs kept)")
    h.add_argument("--summary", type=Path, help="also write the per-run summary (Markdown)")
    h.set_defaults(func=_deferred(mod, "cmd_history"))
    s = sub.add_parser("separatrix", help="the Ca*-C separatrix with each run labelled by its longest crack")
    s.add_argument("folder", type=Path, help="a boundary campaign's results folder (crack_history.csv; runs/ or longest_crack_steps.csv)")
    s.add_argument("--table", type=Path, help="the campaign's table.csv (default FOLDER/table.csv)")
    s.add_argument("--l-min", type=float, nargs="+", required=True, help="crack lengths L_min (mm)")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--md", type=Path)
    s.add_argument("--steps-out", type=Path, help="also write the steps' longest crack per run (CSV; committed as "
                   "FOLDER/longest_crack_steps.csv it stands in for runs/)")
    s.set_defaults(func=_deferred(mod, "cmd_separatrix"))
    return c


def add_judge_command(subparsers):
    """``dchfrac judge PROTOCOL CAMPAIGN_DIR [SECOND_DIR]``: a boundary line's declared judging protocol
    (:mod:`sweep.studies.protocols`)."""
    mod = "sweep.studies.protocols"
    j = subparsers.add_parser("judge", help="judge a boundary line by its declared protocol (summary.json, figures)",
                              description=_doc_head(mod))
    j.add_argument("protocol", choices=sorted(PROTOCOL_NAMES))
    j.add_argument("campaign_dir", type=Path, help="the campaign folder (results/<name>/ or the store's)")
    j.add_argument("second_dir", type=Path, nargs="?", help="pockets: the mesh stage's campaign folder; "
                   "experiment_lines: the w_i line's campaign folder (pooled with the first); nf_nb_quadrants: a "
                   "reference campaign over the same grid (label by label)")
    j.add_argument("--out", type=Path, help="summary JSON (also printed)")
    j.add_argument("--figure", type=Path, help="PNG: the labels per realization and the share fracturing")
    j.add_argument("--fallback", type=Path, action="append", help="experiment_lines, nf_nb_quadrants: a judged "
                   "campaign's fallback folder, named <campaign>_upwind_fallback (its failed points rerun; the "
                   "secondary verdict); repeatable for the two lines")
    j.add_argument("--crack-map", type=Path, help="pockets: PNG of the crack length over the Ca*-C plane per mesh")
    j.set_defaults(func=_deferred(mod, "cmd_judge"))
    return j


def add_provenance_command(subparsers):
    """``dchfrac provenance [--results DIR] [--check]`` (:mod:`sweep.campaign.provenance`)."""
    mod = "sweep.campaign.provenance"
    p = subparsers.add_parser("provenance", help="write results/PROVENANCE.md from the campaign tables' code hashes",
                              description=_doc_head(mod))
    p.add_argument("--results", type=Path, default=Path("results"), help="the results folder (default results)")
    p.add_argument("--check", action="store_true", help="compare instead of writing; exit 1 when out of date")
    p.set_defaults(func=_deferred(mod, "cmd_provenance"))
    return p

"""Compare two campaigns run over the same points: the same grid with two model options, or two meshes.

    from sweep.campaign.compare import compare_campaigns
    c = compare_campaigns("campaigns/studies/nf_vs_nb_h2_wall.toml", "campaigns/studies/nf_vs_nb_h2_wall_floor.toml")
    c.pairs            # one row per matched point: swept values, status_a/_b, regime_a/_b, <column>_a/_b
    c.label_table      # cross-tabulation of the labels of the points finished in both (rows: a, columns: b)
    print(c.markdown())

Runs are matched on the swept parameters of both campaigns (their values compared to 12 significant digits; a
parameter swept in one campaign only is matched on the value the other holds it at) and, with replicates, on their
seeds, so that each run has at most one counterpart; never on derived columns such as N_f, whose scale (dp_cri)
each campaign estimates from its own runs.
Units are those of the compared columns (mm, s, kPa; ``columns.csv`` beside each table).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sweep.campaign.cli_guard import UsageError, guarded, name_damaged

__all__ = ["CampaignComparison", "add_compare_command", "cmd_compare", "compare_campaigns", "matching_key"]

_DIGITS = 12


@dataclass(frozen=True)
class CampaignComparison:
    """The matched points of campaigns ``a`` and ``b`` (folder names), label by label.

    pairs : pandas DataFrame, one row per point present in both: the shared swept values, ``status_a``,
        ``status_b``, ``<label>_a``, ``<label>_b`` and ``<column>_a``, ``<column>_b`` for each compared column.
    only_a, only_b : points of one campaign without a counterpart (pandas DataFrames of swept values).
    on : the swept names matched on; label : the label column; columns : the compared numeric columns.
    """

    a: str
    b: str
    on: tuple
    label: str
    columns: tuple
    pairs: object
    only_a: object
    only_b: object

    @property
    def both_ok(self):
        """The matched points finished (status ok) in both campaigns."""
        p = self.pairs
        return p[(p["status_a"] == "ok") & (p["status_b"] == "ok")]

    @property
    def label_table(self):
        """Cross-tabulation of the labels of the points finished in both (rows: a, columns: b)."""
        import pandas as pd

        ok = self.both_ok
        return pd.crosstab(ok[f"{self.label}_a"].astype(str), ok[f"{self.label}_b"].astype(str))

    @property
    def status_table(self):
        """Cross-tabulation of the run statuses over every matched point (rows: a, columns: b)."""
        import pandas as pd

        return pd.crosstab(self.pairs["status_a"].astype(str), self.pairs["status_b"].astype(str))

    def agreement(self) -> tuple[int, int]:
        """(points whose labels agree, points finished in both)."""
        ok = self.both_ok
        same = (ok[f"{self.label}_a"].astype(str) == ok[f"{self.label}_b"].astype(str)).sum()
        return int(same), int(len(ok))

    def column_changes(self):
        """Per compared column, over the points finished in both: median and largest |b - a| and the median of
        b / a (pandas DataFrame indexed by column; the column's own unit)."""
        import numpy as np
        import pandas as pd

        ok, rows = self.both_ok, {}
        for c in self.columns:
            xa = pd.to_numeric(ok[f"{c}_a"], errors="coerce").to_numpy(float)
            xb = pd.to_numeric(ok[f"{c}_b"], errors="coerce").to_numpy(float)
            m = np.isfinite(xa) & np.isfinite(xb)
            d = np.abs(xb[m] - xa[m])
            ratio = xb[m][xa[m] != 0] / xa[m][xa[m] != 0]
            rows[c] = {"n": int(m.sum()), "median_abs_change": float(np.median(d)) if d.size else np.nan,
                       "max_abs_change": float(d.max()) if d.size else np.nan,
                       "median_ratio_b_over_a": float(np.median(ratio)) if ratio.size else np.nan}
        return pd.DataFrame.from_dict(rows, orient="index")

    def markdown(self) -> str:
        """A Markdown summary: matched points, statuses, label agreement and table, column changes."""
        same, n = self.agreement()
        lines = [f"# `{self.a}` against `{self.b}`", "",
                 f"Matched on {', '.join(self.on)}: {len(self.pairs)} points in both, {len(self.only_a)} only in "
                 f"`{self.a}`, {len(self.only_b)} only in `{self.b}`.", "",
                 "## Status (rows: a, columns: b)", "", _md_table(self.status_table), "",
                 f"## {self.label} (points finished in both; rows: a, columns: b)", "",
                 f"{same} of {n} labels agree.", "", _md_table(self.label_table) if n else "(none)", ""]
        if self.columns:
            lines += ["## Compared columns (points finished in both; |b - a| in the column's unit)", "",
                      _md_table(self.column_changes().round(4)), ""]
        return "\n".join(lines)


def _md_table(df) -> str:
    head = ["", *map(str, df.columns)]
    rows = [[str(i), *map(str, r)] for i, r in zip(df.index, df.to_numpy().tolist())]
    return "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head),
                      *["| " + " | ".join(r) + " |" for r in rows]])


def matching_key(table, on):
    """One hashable key per row: the values of ``on``, numbers rounded to ``_DIGITS`` significant digits, a missing
    value (None, NaN, NA: e.g. the deterministic mesh's mesh_seed) as None, so that missing matches missing."""
    cols = [[_key_value(x) for x in table[n].to_numpy()] for n in on]
    return list(zip(*cols)) if cols else []


def _key_value(x):
    import pandas as pd

    if x is None or x is pd.NA or (isinstance(x, float) and x != x):
        return None
    try:
        return float(f"{float(x):.{_DIGITS - 1}e}")
    except (TypeError, ValueError):
        return str(x)


def _frame(source, root, label, columns):
    """The table of one campaign, its folder name and its swept names; refuses missing columns."""
    from sweep.campaign.load import _swept_names, campaign_dir, load_campaign

    d = campaign_dir(source, root)
    table = load_campaign(source, root)
    if table.empty:
        raise ValueError(f"campaign {d.name!r}: no finished runs in {d} (no table.parquet or table.csv there, no "
                         "run records): nothing to compare")
    missing = [c for c in (label, *columns) if c not in table.columns]
    if missing:
        raise ValueError(f"campaign {d.name!r} has no column {missing[0]!r}: `dchfrac campaign columns` lists them")
    return table, d.name, _swept_names(Path(d), table)


def _column(table, name):
    """The column of ``table`` holding ``name`` (bare, or prefixed where the name was taken), None if none."""
    return next((c for c in (name, f"swept_{name}", f"param_{name}", f"opt_{name}") if c in table.columns), None)


# the fields a point's replicates vary (sweep.campaign.replicates.REPLICATE_KEYS): runs of one point told apart
_REPLICATE_FIELDS = ("seed", "mesh_seed")


def _match_on(ta, tb, on_a, on_b, names) -> tuple:
    """The names two campaign tables are matched on: the swept names of either campaign that both tables hold
    (a name swept in one campaign is matched on the value the other holds it at), and, when runs of one
    campaign still share those values (replicates), the replicated seeds.  ValueError when runs still share
    them: pairing them would be arbitrary (every run of one with every run of the other)."""
    on = tuple(dict.fromkeys(n for n in (*on_a, *on_b) if _column(ta, n) and _column(tb, n)))
    for extra in ((), _REPLICATE_FIELDS):
        on = tuple(dict.fromkeys((*on, *(n for n in extra if _column(ta, n) and _column(tb, n)))))
        dup = [(n, len(t) - len(set(matching_key(_named(t, on), on)))) for n, t in zip(names, (ta, tb))]
        dup = [d for d in dup if d[1]]
        if not dup:
            return on
    raise ValueError(f"campaign {dup[0][0]!r}: {dup[0][1]} run(s) share their values of {', '.join(on)} with another "
                     "of its runs: they cannot be paired with the other campaign's runs one to one")


def _named(table, names):
    """The columns of ``names`` (bare or prefixed) under their bare names."""
    import pandas as pd

    return pd.DataFrame({n: table[_column(table, n)].to_numpy() for n in names}, index=table.index)


def compare_campaigns(a, b, root="results", *, label: str = "regime", columns=()) -> CampaignComparison:
    """Match the runs of campaigns ``a`` and ``b`` point by point.

    a, b : campaign folders, spec TOML paths or CampaignSpecs (folders under ``root``).
    label : the categorical column compared (default ``regime``; e.g. ``fracturing``).
    columns : numeric columns compared too (e.g. ``("crack_length", "front_radius_mean")``, mm).
    Runs are matched on the swept names of both campaigns (one swept in a single campaign on the value the other
    holds it at) and, with replicates, on their seeds (``seed``, ``mesh_seed``): draw by draw.
    Raises ValueError when the campaigns share no swept parameter, lack a named column, or hold runs that these
    values do not tell apart.
    """
    columns = tuple(columns)
    ta, name_a, on_a = _frame(a, root, label, columns)
    tb, name_b, on_b = _frame(b, root, label, columns)
    if not any(n in on_b for n in on_a):
        raise ValueError(f"campaigns {name_a!r} and {name_b!r} share no swept parameter "
                         f"({name_a}: {on_a or 'none'}; {name_b}: {on_b or 'none'}): nothing to match on")
    on = _match_on(ta, tb, on_a, on_b, (name_a, name_b))
    keep = ["status", label, *columns]
    left = _named(ta, on).join(ta[keep]).assign(_k=matching_key(_named(ta, on), on))
    right = tb[keep].assign(_k=matching_key(_named(tb, on), on))
    pairs = left.merge(right, on="_k", suffixes=("_a", "_b"), how="inner")
    only_a = left[~left["_k"].isin(set(right["_k"]))][list(on)].reset_index(drop=True)
    only_b = _named(tb, on)[~right["_k"].isin(set(left["_k"]))].reset_index(drop=True)
    pairs = pairs.drop(columns="_k").reset_index(drop=True)
    return CampaignComparison(name_a, name_b, on, label, columns, pairs, only_a, only_b)


def add_compare_command(sub) -> None:
    """Add ``compare`` to the ``dchfrac campaign`` subparsers ``sub``."""
    q = sub.add_parser("compare", help="match two campaigns point by point: statuses, labels, column changes")
    q.add_argument("spec", help="first campaign: spec TOML or campaign folder")
    q.add_argument("other", help="second campaign: spec TOML or campaign folder")
    q.add_argument("--results", default=None, metavar="DIR",
                   help="results root (default: results/ of each spec's project)")
    q.add_argument("--label", default="regime", help="categorical column compared (default: regime)")
    q.add_argument("--columns", default="", metavar="A,B",
                   help="numeric columns compared too, comma-separated (e.g. crack_length,front_radius_mean)")
    q.add_argument("--out", default=None, metavar="FILE", help="also write the Markdown summary to FILE")
    q.set_defaults(func=cmd_compare)


@guarded
def cmd_compare(args) -> int:
    from solver.output import check_writable_dir
    from sweep.campaign.store import write_text_atomic

    if args.out is not None:
        try:
            check_writable_dir(str(Path(args.out).resolve().parent), "--out folder")
        except ValueError as e:
            raise UsageError(str(e)) from None
    columns = tuple(c.strip() for c in args.columns.split(",") if c.strip())
    for source in (args.spec, args.other):
        name_damaged(source, args.results)
    try:
        root = "results" if args.results is None else Path(args.results).resolve()
        c = compare_campaigns(args.spec, args.other, root, label=args.label, columns=columns)
    except (ValueError, FileNotFoundError) as e:
        raise UsageError(str(e)) from None
    text = c.markdown()
    print(text)
    if args.out is not None:
        write_text_atomic(args.out, text + "\n")
    return 0

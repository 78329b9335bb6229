"""Archived runs: rows of a campaign's committed table whose run folders are not here.

A campaign folder carried by git holds its table (``table.parquet`` / ``table.csv``) but usually not its run
folders (``runs/`` is pruned or left out).  Such a run is *archived*: its row is the evidence, read as it was
written, and every reader (status, table, plots, report, loaders) uses it; ``campaign run`` reruns it only when
asked.  A row belongs to a point of the spec by its run key, else by the point's swept values and blocks (the key
hashes every parameter and option, so it changes when a parameter is added to the model; the swept values name
the point the spec asked for), provided the row holds the values the spec writes for its other fields (a row made
before the spec's base changed is another point's).  Floats are compared to 10 significant digits.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

__all__ = ["read_committed_table", "match_committed", "row_values"]


def read_committed_table(campaign_dir):
    """The committed table of a campaign folder (typed pandas DataFrame), None when there is none."""
    import pandas as pd

    d = Path(campaign_dir)
    if (d / "table.parquet").is_file():
        df = pd.read_parquet(d / "table.parquet")
    elif (d / "table.csv").is_file():
        df = pd.read_csv(d / "table.csv")
    else:
        return None
    from sweep.campaign.columns import typed_frame

    return typed_frame(d, df) if len(df) else None


def _plain(v):
    """A table cell as a plain Python value (NA -> None, numpy scalars -> Python, arrays -> lists)."""
    if v is None:
        return None
    if hasattr(v, "tolist") and not isinstance(v, (str, bytes)):
        v = v.tolist()
    if isinstance(v, list):
        return [_plain(x) for x in v]
    try:
        import pandas as pd

        if v is pd.NA or v is pd.NaT:
            return None
    except ImportError:  # pragma: no cover
        pass
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def row_values(row: Mapping[str, Any]) -> dict:
    """{column: plain value} of one committed row."""
    return {str(k): _plain(v) for k, v in dict(row).items()}


def _norm(v):
    from sweep.campaign.spec_model import round_sig

    if isinstance(v, bool) or v is None:
        return v
    if isinstance(v, (int, float)):
        return round_sig(float(v), 10)
    if isinstance(v, (list, tuple)):
        return tuple(_norm(x) for x in v)
    return str(v)


def _signature(swept: Mapping[str, Any], blocks) -> tuple:
    return (str(blocks or ""),) + tuple((a, _norm(v)) for a, v in sorted(swept.items()))


def _row_swept(row: Mapping[str, Any], names: Sequence[str]) -> dict | None:
    out = {}
    for a in names:
        for col in (f"swept_{a}", a):
            if col in row:
                out[a] = row[col]
                break
        else:
            return None
    return out


def _row_blocks(row: Mapping[str, Any]):
    b = row.get("blocks")
    return ";".join(b) if isinstance(b, list) else b


def _row_identity(row: Mapping[str, Any], identity) -> tuple:
    """The row's values of the replicated fields ``identity`` ((namespace, name) pairs): its column ``name``, else
    ``param_name`` / ``opt_name``; None when absent."""
    out = []
    for target, name in identity:
        col = next((c for c in (name, f"{'param' if target == 'params' else 'opt'}_{name}") if c in row), None)
        out.append(_norm(row.get(col)) if col else None)
    return tuple(out)


def _agrees(row: Mapping[str, Any], p, written) -> bool:
    """Whether the row's values of the fields the spec writes ``written`` ((namespace, name) pairs) are the
    point's: its column ``param_name`` / ``opt_name``, else ``name``; a field the row lacks (a table written
    before the model had it) or holds no value of is not compared."""
    for target, name in written:
        col = next((c for c in (f"{'param' if target == 'params' else 'opt'}_{name}", name) if c in row), None)
        v = row.get(col) if col else None
        if v is not None and _norm(v) != _norm((p.params if target == "params" else p.options).get(name)):
            return False
    return True


def _point_identity(p, identity) -> tuple:
    return tuple(_norm((p.params if target == "params" else p.options).get(name)) for target, name in identity)


def match_committed(points, keys: Sequence[str], skip: set, rows: Sequence[Mapping[str, Any]], identity=(),
                    held=(), written=()):
    """(matched, unmatched): ``matched`` {point key: committed row} for the points whose key is not in ``skip``
    (points with a record or a run folder), by run key first, then by swept values and blocks (rows in table
    order); ``unmatched``: the rows no point took (runs a sampler added, or points the spec no longer asks for).
    ``identity``: the (namespace, name) of the fields that the replicates of a point vary (``[replicates]``:
    ("params", "seed"), ("options", "mesh_seed")); their values must match too, since a point's replicates share
    its swept values.  ``held``: (point, key) of the runs here (records); each takes the committed row of its own
    run first, by key, else by swept values, blocks and identity (a row of older code has another key), so that a
    rerun archived run replaces its row: the row is neither matched nor unmatched (a sampler's table shows its
    unmatched rows).  ``written``: the (namespace, name) of the fields the spec sets (not swept): a row matched by
    swept values holds the point's values of them too (:func:`_agrees`), else it was made for another point (the
    spec's base changed since) and is not this point's result."""
    by_key = {r.get("key"): i for i, r in enumerate(rows)}
    taken: set[int] = {by_key[k] for k in skip if k in by_key}
    matched: dict[str, dict] = {}
    for k in keys:
        if k not in skip and k in by_key and by_key[k] not in taken:
            matched[k] = rows[by_key[k]]
            taken.add(by_key[k])
    find = _SweptIndex(rows, identity, written)
    for p, k in held:
        if k not in by_key and p.swept and (i := find(p, taken)) is not None:
            taken.add(i)
    for p, k in zip(points, keys):
        if k not in skip and k not in matched and (i := find(p, taken)) is not None:
            matched[k] = rows[i]
            taken.add(i)
    return matched, [r for i, r in enumerate(rows) if i not in taken]


class _SweptIndex:
    """The committed rows indexed by swept values (blocks, and without) and the replicated fields ``identity``;
    called with a point and the rows taken, it returns the first row of the point not taken, or None."""

    def __init__(self, rows: Sequence[Mapping[str, Any]], identity, written=()):
        self.rows, self.identity, self.written, self.index = rows, identity, written, {}

    def _by_names(self, names: tuple) -> dict:
        if names not in self.index:
            self.index[names] = {}
            for i, r in enumerate(self.rows):
                sw = _row_swept(r, names)
                if sw is not None:
                    rid = _row_identity(r, self.identity)
                    self.index[names].setdefault(_signature(sw, _row_blocks(r)) + rid, []).append(i)
                    self.index[names].setdefault(_signature(sw, None) + rid, []).append(i)
        return self.index[names]

    def __call__(self, p, taken: set) -> int | None:
        index = self._by_names(tuple(sorted(p.swept)))
        pid = _point_identity(p, self.identity)
        for sig in (_signature(p.swept, ";".join(p.blocks)) + pid, _signature(p.swept, None) + pid):
            cand = [i for i in index.get(sig, []) if i not in taken and _agrees(self.rows[i], p, self.written)]
            if cand:
                return cand[0]
        return None

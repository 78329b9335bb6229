"""A campaign's plan: its points, their run keys and what the store and the committed table hold for each.

    plan = plan_campaign("campaigns/examples/demo.toml")    # done / failed / pending / archived / damaged
    plan.stale                                              # made by other solver code (a note, not a state)

Each point with a record is damaged (its files fail :func:`sweep.campaign.store.verify_run`), done or failed;
a point without one is archived (a row of the committed table: :mod:`sweep.campaign.archived`) or pending.
Results roots resolve against the spec's project (:mod:`sweep.campaign.paths`).
"""
from __future__ import annotations

import sys
from pathlib import Path
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from sweep.campaign.paths import DEFAULT_ROOT, results_root
from sweep.campaign.sampler import Point
from sweep.campaign.spec import CampaignSpec, load_spec, samplers
from sweep.campaign.store import ResultsStore, current_classifier_hash, current_code_hash, run_key, verify_run

__all__ = ["as_spec", "Plan", "plan_campaign", "check_intact", "DamagedRunsError", "EmptierResultError",
           "check_not_emptier", "code_counts", "provenance_lines"]


def as_spec(spec) -> CampaignSpec:
    """A CampaignSpec from a spec object or a path to a TOML file."""
    return spec if isinstance(spec, CampaignSpec) else load_spec(spec)


class DamagedRunsError(RuntimeError):
    """Stored runs whose files are missing, changed or do not parse (see :func:`sweep.campaign.store.verify_run`)."""


@dataclass
class Plan:
    """The grid of a campaign and what the store already holds for it.

    Each point is exactly one of: damaged (its files fail :func:`verify_run`), done ("ok") or failed (a
    record of a run folder here), archived (no run folder here, but a row of the committed table:
    :mod:`sweep.campaign.archived`) or pending (neither).  Stale (made by other solver code: recorded
    ``code_hash`` != ``code_hash``; a record without one is stale) is a note on done, failed and archived
    runs, not a state: it decides nothing unless ``rerun_stale`` (then the stale runs with a record are
    neither done nor failed: :func:`run_campaign` reruns them).
    """

    spec: CampaignSpec
    store: ResultsStore
    points: list[Point]
    keys: list[str]
    records: dict[str, dict]
    code_hash: str
    classifier_hash: str
    rerun_stale: bool = False
    verify: bool = True
    archived_rows: dict[str, dict] = field(default_factory=dict)
    unmatched_rows: list[dict] = field(default_factory=list)
    _problems: dict[str, list[str]] = field(default_factory=dict, repr=False)

    def problems(self, key: str) -> list[str]:
        """What is wrong with the stored run ``key`` ([] = intact, or not verified)."""
        if not self.verify or key not in self.records:
            return []
        if key not in self._problems:
            self._problems[key] = verify_run(self.store.run_dir(key), self.records[key])
        return self._problems[key]

    def add(self, record: Mapping[str, Any]) -> None:
        """Take in the record of a run just finished (intact by construction)."""
        self.records[record["key"]] = dict(record)
        self._problems[record["key"]] = []

    def is_stale(self, key: str) -> bool:
        """Whether the run of ``key`` (its record, else its archived row) was made by other solver code."""
        rec = self.records.get(key) or self.archived_rows.get(key) or {}
        return rec.get("code_hash") != self.code_hash

    def _with(self, pred) -> list[tuple[Point, str]]:
        return [(p, k) for p, k in zip(self.points, self.keys) if pred(k, self.records.get(k))]

    def _usable(self, k, r) -> bool:
        return r is not None and not self.problems(k) and not (self.rerun_stale and self.is_stale(k))

    @property
    def done(self):
        return self._with(lambda k, r: self._usable(k, r) and r.get("status") == "ok")

    @property
    def failed(self):
        return self._with(lambda k, r: self._usable(k, r) and r.get("status") != "ok")

    @property
    def pending(self):
        return self._with(lambda k, r: r is None and k not in self.archived_rows)

    @property
    def archived(self):
        """Points without a run folder here whose row is in the committed table."""
        return self._with(lambda k, r: r is None and k in self.archived_rows)

    def archived_status(self, status: str = "ok"):
        """The archived points whose committed row has ``status`` ("ok") or another one (any other value)."""
        ok = status == "ok"
        return [(p, k) for p, k in self.archived if (self.archived_rows[k].get("status") == "ok") == ok]

    @property
    def damaged(self):
        return self._with(lambda k, r: r is not None and bool(self.problems(k)))

    @property
    def stale(self):
        """Intact runs and archived rows made by other solver code (rerun by run_campaign only with rerun_stale)."""
        return self._with(lambda k, r: (r is not None and not self.problems(k) or k in self.archived_rows)
                          and self.is_stale(k))

    @property
    def misclassified(self):
        """Done runs labelled by sweep.regimes.classify of other classifier code (kept; relabelled only by
        ``run_campaign(relabel=True)`` or ``reclassify``)."""
        return [(p, k) for p, k in self.done
                if self.records[k].get("classifier_hash") not in (None, self.classifier_hash)]

    def damage_text(self) -> str:
        """One line per damaged run: key, swept values, problems."""
        return "\n".join(f"  damaged {k} ({_swept_text(p)}): {'; '.join(self.problems(k))}" for p, k in self.damaged)


def _swept_text(p: Point) -> str:
    return ", ".join(f"{a}={v}" for a, v in p.swept.items())


def _keys(points: Sequence[Point]) -> list[str]:
    return [run_key(p.params, p.options) for p in points]


def plan_campaign(spec, root=DEFAULT_ROOT, *, code_hash: str | None = None, points: Sequence[Point] | None = None,
                  rerun_stale: bool = False, verify: bool = True) -> Plan:
    """Expand the spec's initial points and look their keys up in the store and the committed table.

    root : results root (a relative one is resolved against the spec's project root:
        :func:`sweep.campaign.paths.results_root`).
    code_hash : the current solver code (default :func:`sweep.campaign.store.current_code_hash`); records of
        other code are stale. rerun_stale : count stale runs with a record as neither done nor failed (to be
        rerun). verify : check each stored run's files against its record (:func:`sweep.campaign.store.verify_run`).
    """
    from sweep.campaign.archived import match_committed, read_committed_table, row_values

    spec = as_spec(spec)
    root = results_root(spec, root)
    code_hash = current_code_hash() if code_hash is None else code_hash
    pts = list(points) if points is not None else samplers()[spec.sampler["kind"]]().initial(spec)
    store = ResultsStore(root, spec.name)
    keys = _keys(pts)
    recs = {k: r for k in keys if (r := store.read_record(k)) is not None}
    if points is None and spec.sampler["kind"] != "grid":  # the runs a sampler added in earlier rounds
        for k, r in store.records().items():
            if k not in recs and k not in keys:
                pts.append(Point(r["params"], r["options"], {}, ("refined",), len(pts)))
                keys.append(k)
                recs[k] = r
    plan = Plan(spec, store, pts, keys, recs, code_hash, current_classifier_hash(), rerun_stale, verify)
    for k in keys:
        if k not in recs and store.run_dir(k).exists():  # a finished folder whose record was lost or broken
            recs[k] = {"key": k, "status": "damaged"}
            plan._problems[k] = ["record.json is missing or does not parse"]
    committed = read_committed_table(store.dir)
    if committed is not None:
        rows = [row_values(r) for r in committed.to_dict("records")]
        here = set(recs) | {r["key"] for r in rows if isinstance(r.get("key"), str) and store.run_dir(r["key"]).is_dir()}
        from sweep.campaign.replicates import REPLICATE_KEYS

        identity = [REPLICATE_KEYS[k] for k in sorted(getattr(spec, "replicates", None) or {})]
        plan.archived_rows, unmatched = match_committed(pts, keys, set(recs), [r for r in rows if r.get("key") not in here],
                                                        identity, _held(spec, store, pts, keys, recs), _written(spec))
        plan.unmatched_rows = unmatched
    return plan


def _written(spec: CampaignSpec) -> list[tuple[str, str]]:
    """(namespace, name) of the fields the spec sets: its and its blocks' parameters (a preset's and a model
    file's included), ``[derived]`` and the run options that change a run's result (``solver.options.keyed``)."""
    from solver.options import keyed

    params = {k for t in (spec, *spec.blocks) for k in t.params} | set(spec.derived)
    options = keyed({k: None for t in (spec, *spec.blocks) for k in t.options})
    return sorted({("params", k) for k in params} | {("options", k) for k in options})


def _held(spec: CampaignSpec, store: ResultsStore, pts, keys, recs) -> list[tuple[Point, str]]:
    """(point, key) of the runs here: the plan's points with a record and, for a sampler, every other record of
    the store (the runs of earlier rounds).  A point rebuilt from a record has no swept values: they are its
    values of the spec's axes (one block: a sampler's)."""
    out = [(p, k) for p, k in zip(pts, keys) if k in recs]
    if spec.sampler["kind"] != "grid":
        out += [(Point(r["params"], r["options"], {}, ("refined",), -1), k)
                for k, r in store.records().items() if k not in recs]
    axes = spec.blocks[0].axes if len(spec.blocks) == 1 else ()

    def swept(p: Point) -> dict:
        return {a.name: (p.params if a.target == "params" else p.options).get(a.name) for a in axes}

    return [(p if p.swept else replace(p, swept=swept(p)), k) for p, k in out]


def check_intact(plan: Plan, allow_damaged: bool = False) -> None:
    """Raise DamagedRunsError naming the plan's damaged runs (a warning on stderr with ``allow_damaged``)."""
    if not plan.damaged:
        return
    msg = (f"campaign {plan.spec.name}: {len(plan.damaged)} damaged run(s) (files missing, changed or unreadable "
           f"since their record was written); `dchfrac campaign run {plan.spec.source}` reruns them:\n"
           + plan.damage_text())
    if not allow_damaged:
        raise DamagedRunsError(msg)
    print(f"warning: {msg}\n  (left out)", file=sys.stderr)


def _todo(plan: Plan, retry_failed: bool, rerun_archived: bool = False) -> list[tuple[Point, str]]:
    """Points to execute, in grid order: pending, damaged, stale (with ``plan.rerun_stale``), failed (if
    retried; archived failed rows too), archived (with ``rerun_archived``)."""
    stale = plan.stale if plan.rerun_stale else []
    failed = plan.failed + plan.archived_status("failed") if retry_failed else []
    todo = plan.pending + plan.damaged + stale + failed + (plan.archived if rerun_archived else [])
    unique = {k: (p, k) for p, k in todo}  # a point both stale and failed is run once
    return sorted(unique.values(), key=lambda pk: pk[0].index)


def _counts_text(plan: Plan) -> str:
    """"a done, b failed, c pending" plus the stale (made by other code) and damaged counts."""
    text = f"{len(plan.done)} done, {len(plan.failed)} failed, {len(plan.pending)} pending"
    if plan.stale:
        text += (f", {len(plan.stale)} made by other code (stale: to rerun)" if plan.rerun_stale
                 else f", {len(plan.stale)} made by other code (stale: kept)")
    if plan.damaged:
        text += f", {len(plan.damaged)} damaged"
    return text


class EmptierResultError(RuntimeError):
    """A report or plot would replace a committed table with one of fewer rows."""


def check_not_emptier(store: ResultsStore, table) -> None:
    """Raise EmptierResultError when ``table`` has fewer rows than the campaign's committed table."""
    from sweep.campaign.archived import read_committed_table

    old = read_committed_table(store.dir)
    if old is not None and len(table) < len(old):
        raise EmptierResultError(
            f"campaign {store.name}: the table rebuilt from the spec has {len(table)} rows, the committed "
            f"{store.table_csv} {len(old)}: nothing written (the spec no longer asks for the missing runs, "
            f"or their run folders are damaged; `dchfrac campaign status` lists them)")


def _archived_text(plan: Plan) -> str:
    """"N (a ok, b failed)" of the archived points and, for a sampler, the committed rows of the runs it added."""
    extra = plan.unmatched_rows if plan.spec.sampler["kind"] != "grid" else []
    rows = [plan.archived_rows[k] for _, k in plan.archived] + list(extra)
    ok = sum(r.get("status") == "ok" for r in rows)
    text = f"{len(rows)} ({ok} ok, {len(rows) - ok} failed)"
    if extra:
        text += f", {len(extra)} of them runs the sampler added"
    elif plan.unmatched_rows:
        text += f"; {len(plan.unmatched_rows)} committed rows match no point of the spec (left out)"
    return text


def code_counts(plan: Plan) -> dict[str, int]:
    """{solver code hash: runs of the plan made by it (records, archived rows)}; "pre-hash" for records
    without a hash."""
    out: dict[str, int] = {}
    extra = plan.unmatched_rows if plan.spec.sampler["kind"] != "grid" else []
    recs = [plan.records.get(k) or plan.archived_rows.get(k) for k in plan.keys] + list(extra)
    for r in recs:
        if r is not None:
            h = r.get("code_hash") or "pre-hash"
            out[h] = out.get(h, 0) + 1
    return out


def provenance_lines(plan: Plan) -> list[str]:
    """Markdown lines stating the code that made the stored runs, against the current code."""
    lines = [f"Current code: solver code hash `{plan.code_hash}`, classifier hash `{plan.classifier_hash}` "
             "(`python -m solver.codehash`)."]
    for h, n in code_counts(plan).items():
        who = "pre-hash code (made before runs recorded their code)" if h == "pre-hash" else f"code hash `{h}`"
        lines.append(f"- {n} run(s) made by {who}{' (current)' if h == plan.code_hash else ' (other code: stale)'}")
    lines.append("Stale runs are used like the others; `dchfrac campaign run SPEC --rerun-stale` reruns them.")
    return lines


def check_same_campaign(spec: CampaignSpec, store: ResultsStore, keys) -> None:
    """Refuse a grid spec that would take over another campaign of the same name: the folder holds a spec.toml
    of other text and runs that this spec's grid (run keys ``keys``) does not hold, which its table and spec
    copy would drop.  A spec that keeps every stored run (an extended grid, an edited comment) goes on.  ValueError
    naming the folder, the count and what to do."""
    old = store.dir / "spec.toml"
    src = Path(spec.source)
    if spec.sampler["kind"] != "grid" or not old.is_file() or not src.is_file() or old.read_text() == src.read_text():
        return
    lost = set(store.records()) - set(keys)
    if lost:
        raise ValueError(f"campaign name {spec.name!r} must be new or name the same campaign: {store.dir} holds "
                         f"{len(lost)} run(s) of another spec ({old}) outside this spec's grid, which its table would "
                         f"drop (allowed: another name in {spec.source}, or another --results folder)")

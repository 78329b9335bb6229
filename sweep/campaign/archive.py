"""Prune a campaign's finished runs to what their labels were read from, so that a campaign can be kept small.

A run folder holds every snapshot its spec asked for (``snapshot_times``), each with every field of
``solver.output.SNAPSHOT_FIELDS``: several MB a run at h = 1 mm.  A campaign's table, its diagrams, its
threshold-sensitivity study (``sweep.studies.threshold_sensitivity``) and its relabelling (``dchfrac campaign classify``)
read one snapshot a run, the one the classifier judged, and of it only the fields of :data:`LABEL_FIELDS`.
Pruning keeps that snapshot with those fields, the mesh, the time series, the summary and the inputs; it removes
the other snapshots and the ParaView copy of them all (:data:`FIELD_COPIES`). The run's record lists the files
that remain (with their SHA-256, so :func:`sweep.campaign.store.verify_run` checks them as before) and says what was
removed (``record["pruned"]``).

A pruned run is a finished run: a resumed campaign reuses it, relabels it with a changed classifier on request (``--relabel``) (as long as
the classifier reads no other field), and draws it in every diagram; a grid of field maps of another field leaves
it out with a warning. The removed snapshots are gone: to have them again, rerun the run.

Usage::

    dchfrac campaign prune campaigns/studies/ca_star_boundary_h1_floor.toml --results /scratch/campaigns
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from sweep.campaign.store import ResultsStore, file_manifest, verify_run, write_json_atomic

__all__ = ["LABEL_FIELDS", "FIELD_COPIES", "PruneReport", "prune_run", "prune_campaign"]

# The snapshot fields sweep.regimes.classify.classify_run (and select_snapshot, the diagram thumbnails and the
# threshold sensitivity) read: the time (s), the nodal saturation S (-) and the elemental porosity phi (-).
# tests/test_archive.py checks that a run pruned to them classifies exactly as before.
LABEL_FIELDS = ("t", "S", "phi")

# the ParaView copy of every snapshot (solver/output.py: fields.xdmf with its arrays in fields.h5)
FIELD_COPIES = ("fields.xdmf", "fields.h5")

# relative tolerance between a snapshot's time and the record's t_classified (both written from the same float)
_T_MATCH = 1e-9


@dataclass
class PruneReport:
    """What :func:`prune_campaign` did: runs pruned, bytes freed, and runs left as they were (key: why)."""

    pruned: list[str] = field(default_factory=list)
    bytes_freed: int = 0
    skipped: dict[str, str] = field(default_factory=dict)


def _classified_snapshot(run_dir: Path, record: Mapping) -> Path:
    """The snapshot file the record's label was read from (its time is ``classification.t_classified``, s)."""
    from sweep.regimes.classify import list_snapshots

    t_cls = (record.get("classification") or {}).get("t_classified")
    if t_cls is None:
        raise ValueError("the record has no t_classified (no label to keep)")
    snaps = list_snapshots(run_dir)
    t, path = min(snaps, key=lambda tp: abs(tp[0] - float(t_cls)))
    if abs(t - float(t_cls)) > _T_MATCH * max(1.0, abs(float(t_cls))):
        raise ValueError(f"no snapshot at t_classified = {t_cls} s (nearest {t} s)")
    return path


def _strip_snapshot(path: Path, fields: tuple[str, ...]) -> None:
    """Rewrite a snapshot with ``fields`` only, with the run folders' own atomic NPZ writer (solver.output)."""
    from solver.output import _atomic_npz

    with np.load(path) as z:
        missing = [f for f in fields if f not in z.files]
        if missing:
            raise ValueError(f"{path.name} lacks the fields {missing}")
        kept = {f: np.asarray(z[f]) for f in fields}
    _atomic_npz(path, **kept)


def prune_run(run_dir, record: Mapping, *, fields: tuple[str, ...] = LABEL_FIELDS) -> dict:
    """Prune one finished, labelled run folder; returns its new record (also written to ``record.json``).

    Keeps the classified snapshot with ``fields`` and every file that is no snapshot; removes the other
    ``snapshots/snap_*.npz`` and :data:`FIELD_COPIES`. Raises ValueError, before touching anything, for a run
    that is not "ok", has no label, is already pruned, or whose files fail :func:`sweep.campaign.store.verify_run`.
    """
    run_dir = Path(run_dir)
    if record.get("status") != "ok":
        raise ValueError(f"status {record.get('status')!r}: only finished ('ok') runs are pruned")
    if "pruned" in record:
        raise ValueError("already pruned")
    problems = verify_run(run_dir, record)
    if problems:
        raise ValueError(f"damaged run: {'; '.join(problems)}")
    keep = _classified_snapshot(run_dir, record)
    removed = sorted(p for p in (run_dir / "snapshots").glob("snap_*.npz") if p != keep)
    removed += [run_dir / f for f in FIELD_COPIES if (run_dir / f).is_file()]
    freed = sum(p.stat().st_size for p in removed) + keep.stat().st_size
    _strip_snapshot(keep, fields)
    for p in removed:
        p.unlink()
    new = dict(record)
    new["files"] = file_manifest(run_dir)
    new["pruned"] = {"snapshot_kept": keep.name, "fields_kept": list(fields),
                     "removed": [p.relative_to(run_dir).as_posix() for p in removed],
                     "bytes_freed": freed - keep.stat().st_size}
    write_json_atomic(run_dir / "record.json", new)
    return new


def prune_campaign(spec, root) -> PruneReport:
    """Prune every finished, labelled run of a campaign (``root/<name>/runs``); see :func:`prune_run`.

    Holds the campaign folder's lock, so it refuses to work on a campaign that is running. Runs it cannot
    prune (failed, unlabelled, damaged, already pruned) are left as they are and listed with the reason.
    """
    from sweep.campaign.plan import as_spec
    from sweep.campaign.paths import results_root

    spec = as_spec(spec)
    store = ResultsStore(results_root(spec, root), spec.name)
    if not store.runs_dir.is_dir():
        raise ValueError(f"results={str(root)!r}: no runs of campaign {spec.name!r} in {store.runs_dir}")
    report = PruneReport()
    store.acquire_lock()
    try:
        for key, rec in store.records().items():
            try:
                new = prune_run(store.run_dir(key), rec)
            except ValueError as e:
                report.skipped[key] = str(e)
                continue
            report.pruned.append(key)
            report.bytes_freed += int(new["pruned"]["bytes_freed"])
    finally:
        store.release_lock()
    return report

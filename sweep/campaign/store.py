"""Results store of a campaign: one folder per run, written atomically, and the campaign table.

Layout under a configurable root (default ``results/``)::

    <root>/<campaign>/spec.toml            copy of the spec last run
    <root>/<campaign>/base_models/*.toml   copies of its [base] model files, which the copy names (base_model.py)
    <root>/<campaign>/runs/<key>/          one run: record.json + the solver's run folder
    <root>/<campaign>/table.csv            one row per run, typed (sweep.campaign.columns); also table.parquet
    <root>/<campaign>/columns.csv          column dictionary of the table: name, unit, dtype, meaning
    <root>/<campaign>/figures/*.png        diagrams
    <root>/<campaign>/report.md            Markdown summary

``key`` = first 16 hex digits of the SHA-256 of the canonical JSON of the resolved
parameters and run options (floats at 12 significant digits, so 0.1 and 0.1000000000001
give one key). A run is executed in ``runs/.tmp-<key>-<uuid>/`` and renamed to
``runs/<key>/`` once its ``record.json`` (status "ok" | "failed", reason, metrics, ...)
is written: a folder named by its key is always complete.  A campaign process killed part-way leaves the
folders of its runs in flight; those holding a checkpoint of the current solver code (``solver.checkpoint``) are
kept, and the next execution of their key resumes in them.

The record states the code that made the run (``code_hash``: the solver's source;
``classifier_hash``: the classifier's, when sweep.regimes.classify labelled it) and the size and
SHA-256 of each of the run's files (``files``): a record whose code hash is not the current
one is stale (made by other code), and :func:`verify_run` finds a damaged run folder.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import uuid
from pathlib import Path
from typing import Any, Mapping

from solver.output import atomic_path
from solver.output import atomic_write_text as write_text_atomic  # the project's one atomic writer
from sweep.campaign.spec_model import canonical_json

__all__ = ["run_key", "KEY_FORMAT", "current_code_hash", "current_classifier_hash", "file_manifest", "verify_run", "ResultsStore", "write_json_atomic", "write_text_atomic", "to_json"]

_KEY_RE = re.compile(r"^[0-9a-f]{16}$")


# The key names a run's inputs only, so that a run's folder keeps its name when the code changes
# (the code that made a run is recorded in it, see current_code_hash). The constant is the
# format of the keys of every run stored so far; it changes only if the key's recipe does.
KEY_FORMAT = "0.1.0"


def run_key(params: Mapping[str, Any], options: Mapping[str, Any], key_format: str = KEY_FORMAT) -> str:
    """Hash of canonical (params, options): 16 hex digits, the name of the run's folder.  The options that do
    not change a run's result (``solver.options.keyed``: checkpoint_interval) are no part of it."""
    from solver.options import keyed

    text = canonical_json({"params": dict(params), "options": keyed(dict(options)), "solver_version": str(key_format)})
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def current_code_hash() -> str:
    """Hash of the solver source of this process (:func:`solver.codehash.code_hash`)."""
    from solver import codehash

    return codehash.code_hash()


def current_classifier_hash() -> str:
    """Hash of the classifier source of this process (:func:`sweep.regimes.provenance.classifier_code_hash`)."""
    from sweep.regimes.provenance import classifier_code_hash

    return classifier_code_hash()


def _default(o):
    if hasattr(o, "item"):
        try:
            return o.item()
        except (TypeError, ValueError):
            pass
    if hasattr(o, "tolist"):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    if isinstance(o, Path):
        return str(o)
    return repr(o)


def to_json(obj) -> str:
    """JSON text (numpy scalars/arrays converted; NaN kept as NaN)."""
    return json.dumps(obj, indent=1, sort_keys=True, default=_default)


def write_json_atomic(path, obj) -> None:
    write_text_atomic(path, to_json(obj) + "\n")


RECORD_NAME = "record.json"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _run_files(run_dir: Path) -> list[Path]:
    """The run's files (recursive), hidden ones (temporary) and the record itself excepted."""
    return sorted(p for p in run_dir.rglob("*") if p.is_file() and p.name != RECORD_NAME
                  and not any(part.startswith(".") for part in p.relative_to(run_dir).parts))


def file_manifest(run_dir) -> dict[str, dict]:
    """{relative path: {"size": bytes, "sha256": hex}} of every file of a finished run folder."""
    run_dir = Path(run_dir)
    return {p.relative_to(run_dir).as_posix(): {"size": p.stat().st_size, "sha256": _sha256(p)}
            for p in _run_files(run_dir)}


def _parse_problem(path: Path) -> str | None:
    """Why a run file does not parse (JSON, CSV and NPZ files are read), or None."""
    try:
        if path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".csv":
            import pandas as pd

            pd.read_csv(path, nrows=2)
        elif path.suffix == ".npz":
            import numpy as np

            with np.load(path) as z:
                z.files  # noqa: B018 - reads the archive's directory
    except Exception as e:  # noqa: BLE001 - any reading error is damage
        return f"{path.name} does not parse ({type(e).__name__}: {e})"
    return None


def _manifest_problems(run_dir: Path, files: Mapping[str, Mapping], checksums: bool) -> list[str]:
    out = []
    for rel, want in files.items():
        p = run_dir / rel
        if not p.is_file():
            out.append(f"{rel} is missing")
        elif p.stat().st_size != want.get("size"):
            out.append(f"{rel} has {p.stat().st_size} bytes, the record wrote {want.get('size')}")
        elif checksums and want.get("sha256") and _sha256(p) != want["sha256"]:
            out.append(f"{rel} differs from the file the record wrote (SHA-256)")
    return out


def _legacy_problems(run_dir: Path, record: Mapping) -> list[str]:
    """Files a solver run folder must hold, for a record without a file list (made before records had one)."""
    if not (run_dir / "params.toml").is_file() or record.get("status") != "ok":
        return []
    need = ["summary.json", "timeseries.csv"]
    if (record.get("classification") or {}).get("regime") is not None:
        need.append("snapshots/mesh.npz")  # the regime was read from the snapshots
    return [f"{rel} is missing" for rel in need if not (run_dir / rel).is_file()]


def verify_run(run_dir, record: Mapping, *, checksums: bool = True) -> list[str]:
    """Problems of a stored run folder ([] = intact): files of the record's list missing, of another
    size or (``checksums``) other content; JSON, CSV and NPZ files that do not parse. A record
    without a file list gets the presence check of a solver run's main files."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return ["the run folder is missing"]
    files = record.get("files")
    out = _manifest_problems(run_dir, files, checksums) if isinstance(files, Mapping) else \
        _legacy_problems(run_dir, record)
    for p in _run_files(run_dir):
        if p.suffix in (".json", ".csv", ".npz") and (why := _parse_problem(p)):
            out.append(why)
    return out


class ResultsStore:
    """Folder of one campaign's results (``root/name``)."""

    def __init__(self, root, name: str):
        self.root = Path(root)
        self.name = name
        self.dir = self.root / name
        self.runs_dir = self.dir / "runs"

    # -- runs -----------------------------------------------------------------
    def run_dir(self, key: str) -> Path:
        return self.runs_dir / key

    def new_tmp_dir(self, key: str) -> Path:
        """A fresh private folder for executing run ``key``."""
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        d = self.runs_dir / f".tmp-{key}-{uuid.uuid4().hex[:8]}"
        d.mkdir()
        return d

    def resumable_tmp_dir(self, key: str) -> Path | None:
        """The folder of an interrupted execution of run ``key`` that holds a checkpoint of the current solver code
        (``solver.checkpoint.resumable``; the newest when several do), or None."""
        from solver.checkpoint import NAME, resumable

        if not self.runs_dir.is_dir():
            return None
        found = [d for d in self.runs_dir.glob(f".tmp-{key}-*") if resumable(d)]
        return max(found, key=lambda d: (d / NAME).stat().st_mtime) if found else None

    def finalize(self, tmp_dir: Path, key: str) -> Path:
        """Move a finished run's folder (record.json written) to ``runs/<key>`` (replacing an old one)."""
        final = self.run_dir(key)
        trash = None
        if final.exists():
            trash = self.runs_dir / f".trash-{key}-{uuid.uuid4().hex[:8]}"
            os.rename(final, trash)
        os.rename(tmp_dir, final)
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)
        return final

    def read_record(self, key: str) -> dict | None:
        p = self.run_dir(key) / "record.json"
        try:
            return json.loads(p.read_text())
        except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
            return None

    def records(self) -> dict[str, dict]:
        """All complete run records {key: record}."""
        out = {}
        if not self.runs_dir.is_dir():
            return out
        for d in sorted(self.runs_dir.iterdir()):
            if _KEY_RE.match(d.name):
                r = self.read_record(d.name)
                if r is not None:
                    out[d.name] = r
        return out

    def clean_tmp(self) -> int:
        """Remove folders of runs that were in flight when a previous campaign process died, except those holding
        a checkpoint of the current solver code (``solver.checkpoint``): the next execution of their key resumes
        there (:meth:`resumable_tmp_dir`).  Returns the number removed."""
        from solver.checkpoint import resumable

        n = 0
        if self.runs_dir.is_dir():
            for d in self.runs_dir.iterdir():
                if d.name.startswith(".trash-") or (d.name.startswith(".tmp-") and not resumable(d)):
                    shutil.rmtree(d, ignore_errors=True)
                    n += 1
        return n

    # -- campaign files -------------------------------------------------------
    @property
    def table_csv(self) -> Path:
        return self.dir / "table.csv"

    @property
    def table_parquet(self) -> Path:
        return self.dir / "table.parquet"

    @property
    def figures_dir(self) -> Path:
        return self.dir / "figures"

    @property
    def report_md(self) -> Path:
        return self.dir / "report.md"

    @property
    def columns_csv(self) -> Path:
        return self.dir / "columns.csv"

    def write_table(self, df, swept=(), *, csv: bool = True) -> list[Path]:
        """Write the campaign table, typed by its column dictionary (``sweep.campaign.columns``): ``table.csv``
        (unless not ``csv``), ``table.parquet`` (pyarrow: real lists, every column typed, units and meanings in
        its schema metadata) and ``columns.csv`` (name, unit, dtype, swept, meaning; ``swept``: the spec's axis
        names), each atomically. ``run_dir`` is written relative to the campaign folder."""
        from sweep.campaign.columns import column_dictionary, to_csv_frame, typed_table

        self.dir.mkdir(parents=True, exist_ok=True)
        df = self._relative_run_dirs(df)
        dictionary = column_dictionary(df, swept=swept)
        typed = typed_table(df, dictionary)
        write_text_atomic(self.columns_csv, dictionary.to_csv(index=False))
        if csv:
            write_text_atomic(self.table_csv, to_csv_frame(typed, dictionary).to_csv(index=False))
        self._write_parquet(typed, dictionary)
        return [self.table_csv, self.table_parquet, self.columns_csv]

    def _relative_run_dirs(self, df):
        if "run_dir" not in df.columns:
            return df
        df = df.copy()
        df["run_dir"] = [v if not isinstance(v, str) or not os.path.isabs(v) else os.path.relpath(v, self.dir.resolve())
                         for v in df["run_dir"]]
        return df

    @staticmethod
    def load_writers() -> None:
        """Import what :meth:`write_table` needs (pandas, pyarrow.parquet: seconds on a loaded machine) now, so
        that the table written on the way out of an interrupted campaign (Ctrl-C) imports nothing: an import cut
        by the interrupt, then made again on the way out, was what made an interrupted campaign slow to exit."""
        import pyarrow.parquet  # noqa: F401

        import sweep.campaign.columns  # noqa: F401

    def _write_parquet(self, typed, dictionary) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        from sweep.campaign.columns import arrow_schema

        typed = typed.copy()
        typed.attrs = {}  # a loader's attrs (campaign folder, units) belong to the reader, not the file
        table = pa.Table.from_pandas(typed, schema=arrow_schema(typed, dictionary), preserve_index=False)
        with atomic_path(self.table_parquet) as tmp:
            pq.write_table(table, tmp)

    # -- single-writer lock ----------------------------------------------------
    def acquire_lock(self) -> None:
        """Refuse to run two campaign processes on one campaign folder (stale locks are taken over)."""
        self.dir.mkdir(parents=True, exist_ok=True)
        lock = self.dir / ".lock"
        for _ in range(2):
            try:
                fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                try:
                    pid = int(lock.read_text().strip() or "0")
                except (ValueError, FileNotFoundError):
                    pid = 0
                if pid and pid != os.getpid() and _pid_alive(pid):
                    raise RuntimeError(
                        f"campaign folder {self.dir} is in use by process {pid} (remove {lock} if that is wrong)"
                    ) from None
                lock.unlink(missing_ok=True)
                continue
            with os.fdopen(fd, "w") as f:
                f.write(str(os.getpid()))
            return
        raise RuntimeError(f"could not lock {lock}")

    def release_lock(self) -> None:
        lock = self.dir / ".lock"
        try:
            if int(lock.read_text().strip() or "0") == os.getpid():
                lock.unlink()
        except (FileNotFoundError, ValueError):
            pass


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True

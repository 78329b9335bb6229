"""Hashes of the source code that produces results: the key of every stored result's provenance.

``code_hash()`` is the SHA-256 (first 16 hex digits) of the solver package's ``*.py`` files,
sorted by name, each hashed by content (never by modification time), found next to this
module through ``__file__``: an installed (non-editable) copy hashes its own files.
The classifier's hash lives beside the classifier (``sweep.regimes.provenance``): the solver never imports
``sweep``.

A result stored with a hash other than the current one was made by other code (stale).
Both hashes are computed once per process.

Command line (prints the hashes of this copy, or of a git revision of a checkout)::

    python -m solver.codehash [--git REV [--repo DIR]]     (the classifier's: python -m sweep.regimes.provenance)
"""
from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Iterable

__all__ = ["source_hash", "directory_hash", "code_hash", "git_code_hash", "hash_command", "HASH_DIGITS"]

HASH_DIGITS = 16
SOLVER_DIR = Path(__file__).resolve().parent


def source_hash(files: Iterable[tuple[str, bytes]]) -> str:
    """Hash of (name, content) pairs, order-independent (sorted by name): 16 hex digits."""
    h = hashlib.sha256()
    for name, data in sorted(files):
        h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    return h.hexdigest()[:HASH_DIGITS]


def directory_hash(directory, pattern: str = "*.py") -> str:
    """Hash of the files of ``directory`` matching ``pattern`` (not recursive), by name and content."""
    d = Path(directory)
    files = sorted(p for p in d.glob(pattern) if p.is_file())
    if not files:
        raise FileNotFoundError(f"no {pattern} files in {d} to hash")
    return source_hash((p.name, p.read_bytes()) for p in files)


@functools.lru_cache(maxsize=None)
def code_hash() -> str:
    """Hash of the solver's source (every ``solver/*.py`` of the imported package)."""
    return directory_hash(SOLVER_DIR)


def git_code_hash(rev: str, repo=".") -> str:
    """Hash of the solver's sources at git revision ``rev`` of the checkout ``repo``: what a result made by
    that commit's code records as ``code_hash``."""
    names = _git(repo, "ls-tree", "--name-only", rev, "solver/").decode().split()
    return source_hash((Path(n).name, _git(repo, "show", f"{rev}:{n}")) for n in names if n.endswith(".py"))


def _git(repo, *args) -> bytes:
    import subprocess

    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True).stdout


def hash_command(argv, *, prog: str, description: str, current, at_revision) -> int:
    """The command line of a hash module: print one ``name hash`` line per hash of this copy (``current()``), or with
    ``--git REV [--repo DIR]`` of that git revision (``at_revision(rev, repo)``); both return {name: hash}.
    Exit status 2, with git's message, when the revision cannot be read."""
    import argparse
    import subprocess
    import sys

    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("--git", metavar="REV", help="hash the sources at this git revision instead of this copy")
    ap.add_argument("--repo", default=".", metavar="DIR", help="git checkout for --git (default: .)")
    a = ap.parse_args(argv)
    try:
        hashes = at_revision(a.git, a.repo) if a.git else current()
    except subprocess.CalledProcessError as e:
        print(f"error: --git {a.git}: {e.stderr.decode(errors='replace').strip()}", file=sys.stderr)
        return 2
    for k, v in hashes.items():
        print(f"{k} {v}")
    return 0


def main(argv=None) -> int:
    return hash_command(argv, prog="python -m solver.codehash", description=__doc__.split("\n")[0],
                        current=lambda: {"code_hash": code_hash()},
                        at_revision=lambda rev, repo: {"code_hash": git_code_hash(rev, repo)})


if __name__ == "__main__":
    raise SystemExit(main())

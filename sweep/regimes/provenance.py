"""Hash of the regime classifier's source: the ``classifier_hash`` every stored label records.

The classifier is ``sweep/regimes/classify.py`` with the solver module it imports (``solver/tomlio.py``, which
reads a run's parameters).  Each file enters the hash under its *logical* name, the path it had when labels were
first stored (``sweep/classify.py``), so a move of the file leaves the hash, and every committed label, unchanged;
only a change of content changes it (``solver.codehash.source_hash``).

Command line (the solver's and the classifier's hashes of this copy, or of a git revision of a checkout)::

    python -m sweep.regimes.provenance [--git REV [--repo DIR]]
"""
from __future__ import annotations

import functools
import subprocess
from pathlib import Path

from solver.codehash import SOLVER_DIR, code_hash, git_code_hash, hash_command, source_hash

__all__ = ["CLASSIFIER_FILES", "classifier_code_hash", "git_hashes"]

# logical name -> path relative to the folder holding the solver and sweep packages (today's place)
CLASSIFIER_FILES = {"sweep/classify.py": "sweep/regimes/classify.py", "solver/tomlio.py": "solver/tomlio.py"}


@functools.lru_cache(maxsize=None)
def classifier_code_hash() -> str:
    """Hash of the classifier source of this process (16 hex digits)."""
    from sweep.regimes import classify

    paths = {"sweep/classify.py": Path(classify.__file__).resolve(), "solver/tomlio.py": SOLVER_DIR / "tomlio.py"}
    return source_hash((name, paths[name].read_bytes()) for name in CLASSIFIER_FILES)


def git_hashes(rev: str, repo=".") -> dict:
    """{"code_hash", "classifier_hash"} of the sources at git revision ``rev`` of the checkout ``repo``: what a
    result made by that commit's code records.  The classifier is read at today's path, or at its logical name
    for revisions made before the move."""

    def show(path: str) -> bytes:
        return subprocess.run(["git", "-C", str(repo), "show", f"{rev}:{path}"], check=True,
                              capture_output=True).stdout

    def read(name: str, path: str) -> bytes:
        try:
            return show(path)
        except subprocess.CalledProcessError:
            return show(name)

    classifier = [(name, read(name, path)) for name, path in CLASSIFIER_FILES.items()]
    return {"code_hash": git_code_hash(rev, repo), "classifier_hash": source_hash(classifier)}


def main(argv=None) -> int:
    return hash_command(argv, prog="python -m sweep.regimes.provenance", description=__doc__.split("\n")[0],
                        current=lambda: {"code_hash": code_hash(), "classifier_hash": classifier_code_hash()},
                        at_revision=git_hashes)


if __name__ == "__main__":
    raise SystemExit(main())

"""The paper's reported figures (``shared/data/paper_reported.toml``; units mm, s, kPa), read by the campaign
reports, the studies and the discrepancy workflow alike: a leaf module that imports only ``solver``."""
from __future__ import annotations

from pathlib import Path

__all__ = ["PAPER_TOML_CANDIDATES", "PACKAGED_PAPER_TOML", "paper_reported"]

PAPER_TOML_CANDIDATES = ("../shared/data/paper_reported.toml", "shared/data/paper_reported.toml")
# the copy shipped with the package (sweep/data/), so that an installed copy finds the figures;
# tests/test_reference_data.py holds it equal to the shared file whenever that is present
PACKAGED_PAPER_TOML = Path(__file__).resolve().parent / "data" / "paper_reported.toml"


def paper_reported(path=None) -> dict:
    """The paper's reported figures (TOML): ``path`` when given, else the shared file beside the project,
    else the copy shipped with the package (``sweep/data/paper_reported.toml``)."""
    from solver.tomlio import read_toml

    if path:
        if not Path(path).is_file():
            raise FileNotFoundError(f"paper figures {str(path)!r} not found")
        return read_toml(path)
    cands = [Path(p) for p in PAPER_TOML_CANDIDATES] + [Path(__file__).resolve().parents[2] / "shared/data/paper_reported.toml",
                                                        PACKAGED_PAPER_TOML]
    for c in cands:
        if c.is_file():
            return read_toml(c)
    raise FileNotFoundError(f"paper_reported.toml not found (not even the packaged {PACKAGED_PAPER_TOML}); pass --paper PATH")

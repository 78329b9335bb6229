"""The paper's reported figures ship with the package, equal to the shared source file."""
from pathlib import Path

import pytest

from sweep.paper import PACKAGED_PAPER_TOML, paper_reported

SHARED = next((d / "shared" / "data" / "paper_reported.toml" for d in Path(__file__).resolve().parents
               if (d / "shared" / "data" / "paper_reported.toml").is_file()), Path("/nonexistent"))


def test_packaged_copy_equals_the_shared_file():
    if not SHARED.is_file():
        pytest.skip("shared/data/paper_reported.toml not beside the repository")
    assert PACKAGED_PAPER_TOML.read_bytes() == SHARED.read_bytes()


def test_packaged_copy_is_found_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no shared/ relative to the working directory
    monkeypatch.setattr("sweep.paper.PAPER_TOML_CANDIDATES", ())
    ref = paper_reported()["reference_experiment"]
    assert ref == paper_reported(PACKAGED_PAPER_TOML)["reference_experiment"] and len(ref) > 0


def test_package_data_declares_the_figures():
    """pyproject.toml ships sweep/data/*.toml with the package, and that glob holds the figures."""
    from solver.tomlio import read_toml

    root = Path(__file__).resolve().parents[1]
    globs = read_toml(root / "pyproject.toml")["tool"]["setuptools"]["package-data"]["sweep"]
    shipped = {p for g in globs for p in (root / "sweep").glob(g)}
    assert PACKAGED_PAPER_TOML in shipped

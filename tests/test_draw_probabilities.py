"""sweep.studies.draw_probabilities regenerates the committed results/uncertain_diagrams/draws_h2/ summary from the
committed table of the h = 2 draws line, without any run."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from sweep.studies.draw_probabilities import summarize

ROOT = Path(__file__).resolve().parents[1]


def test_the_committed_draws_summary_regenerates(tmp_path):
    committed = json.loads((ROOT / "results/uncertain_diagrams/draws_h2/summary.json").read_text())
    got = summarize(ROOT / "results/ca_star_boundary_h2_draws", tmp_path)
    assert (got["runs"], got["points"], got["points_draws_agree"]) == (committed["runs"], committed["points"],
                                                                        committed["points_draws_agree"])
    assert got["drawn"] == committed["drawn"]
    for k in ("B_per_percent", "lr"):  # optimizer tolerance of the penalized fit
        assert got["separatrix"][k] == pytest.approx(committed["separatrix"][k], rel=1e-4)
    assert (tmp_path / "points.csv").is_file()

"""sweep.studies.protocols / `dchfrac judge`: the boundary lines' declared protocols regenerate their committed
summaries byte for byte from the committed tables; bad input is refused in one line before any work."""
from pathlib import Path

import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies import protocols as pr

RESULTS = Path(__file__).resolve().parents[1] / "results"


def test_paired_keeps_the_sampler_runs_at_the_mesh_stage_points_then_the_stage():
    sampler = pd.DataFrame({"mesh_seed": 0, "cement": [1.0, 2.0, 3.0], "eta_o": [0.1, 0.2, 0.3],
                            "crack_length": [5.0, 6.0, 7.0]})
    meshes = pd.DataFrame({"mesh_seed": 1, "cement": [3.0, 1.0], "eta_o": [0.3, 0.1], "crack_length": [7.5, 4.5]})
    both = pr.paired(sampler, meshes)
    assert both["mesh_seed"].tolist() == [0, 0, 1, 1]
    assert both["crack_length"].tolist() == [5.0, 7.0, 7.5, 4.5]  # the sampler's point at C = 2 % has no pair


@pytest.mark.parametrize("argv, msg", [
    (["judge", "draws", "RES/ca_star_boundary_h2_draws", "RES/ca_star_boundary_h2_pockets"],
     "only these protocols take a second campaign: pockets (its mesh stage); experiment_lines"),
    (["judge", "draws", "RES/no_such_campaign"], "no_such_campaign: no table.csv"),
])
def test_bad_input_is_one_line_and_exit_2(argv, msg, capsys):
    assert main([a.replace("RES", str(RESULTS)) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1


@pytest.mark.slow
@pytest.mark.parametrize("protocol, dirs", [
    ("draws", ["ca_star_boundary_h2_draws"]),
    ("pockets", ["ca_star_boundary_h2_pockets", "ca_star_boundary_h2_pockets_meshes"]),
    ("nf_nb_quadrants", ["nf_vs_nb_h2_wall_floor", "nf_vs_nb_h2_wall"]),
    ("nf_nb_quadrants", ["nf_vs_nb_h2"]),
    ("nf_nb_quadrants", ["nf_vs_nb_h2_wall"]),
    ("nf_nb_quadrants", ["experiment_nf_vs_nb", "nf_vs_nb_h2_wall_floor",
                         "--fallback", "experiment_nf_vs_nb_upwind_fallback"]),
])
def test_committed_summary_regenerates_byte_for_byte(protocol, dirs, tmp_path, capsys):
    out = tmp_path / "summary.json"
    args = [d if d.startswith("--") else str(RESULTS / d) for d in dirs]
    assert main(["judge", protocol, *args, "--out", str(out)]) == 0
    assert out.read_bytes() == (RESULTS / dirs[0] / "summary.json").read_bytes()

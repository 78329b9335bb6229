"""sweep.studies.nf_nb_draws / `dchfrac judge nf_nb_draws`: the N_f-N_b map's replicate measures (issue #51 item 5).
Known answers: counts of mixed points built by hand, on each side of the delimiters and near them; incomplete
points counted and not judged; the replicates read from the spec."""
import json

import numpy as np
import pandas as pd
import pytest

from sweep.cli import main
from sweep.studies import nf_nb_draws as nd


def _points() -> pd.DataFrame:
    """Six points with three draws: N_f over 0.01 .. 100, N_b = 10 / N_f; mixed regimes at N_f = 0.5 and 2 (near
    N_f = 1), one mixed fracturing label at 2; a seventh point with two of its three runs ok."""
    n_f = np.array([0.01, 0.5, 2.0, 5.0, 30.0, 100.0, 1.0])
    return pd.DataFrame({
        "N_f": n_f, "N_b": 10.0 / n_f, "n_runs": 3, "n_ok": [3, 3, 3, 3, 3, 3, 2],
        "mixed": [False, True, True, False, False, False, True],
        "p_fracturing": [0.0, 0.0, 2 / 3, 1.0, 1.0, 1.0, 0.5]})


def test_the_shares_count_mixed_points_on_each_side_and_near_each_delimiter():
    out = nd.judge(_points(), replicates=3)
    assert (out["points"], out["complete"], out["not_complete"]) == (7, 6, 1)
    one = out["agreement"]["one_regime"]
    assert (one["all"]["k"], one["all"]["n"]) == (4, 6)
    assert (one["N_f < 1"]["k"], one["N_f < 1"]["n"]) == (1, 2)      # 0.01 one regime, 0.5 mixed
    assert (one["N_f >= 1"]["k"], one["N_f >= 1"]["n"]) == (3, 4)    # 2 mixed
    assert (one["N_b < 1"]["k"], one["N_b < 1"]["n"]) == (2, 2)      # N_f = 30, 100: N_b = 0.33, 0.1
    frac = out["agreement"]["one_fracturing_label"]["all"]
    assert (frac["k"], frac["n"]) == (5, 6)
    near_f = out["near_delimiters"]["N_f"]
    assert (near_f["within_one_decade"]["k"], near_f["within_one_decade"]["n"]) == (2, 3)  # 0.5, 2, 5
    assert (near_f["farther"]["k"], near_f["farther"]["n"]) == (0, 3)                      # 0.01, 30, 100
    near_b = out["near_delimiters"]["N_b"]  # N_b = 1000, 20, 5, 2, 0.333, 0.1
    assert (near_b["within_one_decade"]["k"], near_b["within_one_decade"]["n"]) == (1, 4)
    assert (near_b["farther"]["k"], near_b["farther"]["n"]) == (1, 2)


def test_a_share_carries_its_wilson_interval():
    s = nd.share([True, True, True])
    assert s["share"] == 1.0 and s["wilson_95"][1] == 1.0
    assert s["wilson_95"][0] == pytest.approx(0.4385, abs=1e-4)  # 3/3: the header's [0.44, 1]
    assert nd.share([])["share"] is None


def test_a_point_without_a_delimiter_value_is_counted_not_placed():
    p = _points().assign(N_f=lambda d: d["N_f"].where(d.index != 0, np.nan))
    near_f = nd.judge(p, 3)["near_delimiters"]["N_f"]
    assert near_f["without_value"] == 1 and near_f["farther"]["n"] == 2


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="replicates=1"):
        nd.judge(_points(), replicates=1)
    with pytest.raises(ValueError, match="lacks"):
        nd.judge(_points().drop(columns="N_b"), replicates=3)


def test_cli_reads_the_points_and_the_declared_replicates(tmp_path, capsys):
    d = tmp_path / "camp"
    d.mkdir()
    _points().to_csv(d / "points.csv", index=False)
    pd.DataFrame({"status": ["ok"]}).to_csv(d / "table.csv", index=False)
    (d / "spec.toml").write_text('name = "x"\n[replicates]\nporosity_seed = 3\n')
    out = tmp_path / "summary.json"
    assert main(["judge", "nf_nb_draws", str(d), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["complete"] == 6
    (d / "spec.toml").write_text('name = "x"\n')
    assert main(["judge", "nf_nb_draws", str(d), "--out", str(out)]) == 2
    assert "replicates=1" in capsys.readouterr().err
    assert json.loads(out.read_text())["complete"] == 6  # the earlier summary is left as it was

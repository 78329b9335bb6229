"""sweep.studies.balance: the volume balance by phase of a run (issue #47, item 5) closes on a real run and is plotted."""
import numpy as np
import pytest

from solver import RunOptions, preset_parameters, simulate
from sweep.studies.balance import phase_balance, plot_phase_balance


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    res = simulate(preset_parameters("experiment", line_compliance=1.0), RunOptions(h=4.0, t_end=0.05,
                   snapshot_times=[], write_xdmf=False, newton_rtol=1e-10), out_dir=out)
    assert res.status == "ok", res.reason
    return out, res.timeseries


def test_each_phase_closes_and_the_parts_add_up_to_the_pump(short_run):
    _, ts = short_run
    b = phase_balance(ts)
    inj = ts["injected_volume"].to_numpy()
    # each phase's in − out − stored change − source vanishes to the balance tolerance (1e-9 of the pumped volume)
    assert np.all(np.abs(b["water_closure"]) <= 1e-9 * inj) and np.all(np.abs(b["oil_closure"]) <= 1e-9 * inj)
    # pumped = water in + oil in + line storage, by construction of the columns; and the line holds C p_inj
    np.testing.assert_allclose(b["water_in"] + b["oil_in"] + b["line"], inj, rtol=1e-12)
    assert b["line"].iloc[-1] > 0 and b["water_stored"].iloc[-1] > 0
    # the experiment preset's inlet admits the pumped water only: no oil crosses r_i
    assert np.all(np.abs(b["oil_in"]) <= 1e-12 * inj)
    with pytest.raises(ValueError, match="lacks the column"):
        phase_balance(ts.drop(columns=["stored_volume"]))


def test_cli_plots_the_balance(short_run, tmp_path):
    from sweep.cli import main

    folder, _ = short_run
    out = tmp_path / "balance.png"
    assert main(["balance", str(folder), str(folder), "--labels", "a,b", "--out", str(out)]) == 0
    assert out.stat().st_size > 1000
    assert main(["balance", str(folder), "--labels", "a,b", "--out", str(out)]) == 2

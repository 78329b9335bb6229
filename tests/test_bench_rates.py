"""The cost rates that ``dchfrac bench`` writes (``sweep.studies.bench._cost_rates``): from the longest run made at
each mesh size, never from a failed run; ``solver.budget.REFERENCE`` copies the h = 2 rate (tests/test_budget.py) and the
dry run reads the shared-run factor back (``sweep.campaign.cost.shared_run_factor``)."""
import json

import pytest

from sweep.studies.bench import _cost_rates
from sweep.campaign.cost import shared_run_factor


def _run(t_end, wall, status="ok"):
    return {"t_end_s": t_end, "wall_s": wall, "status": status, "wall_s_per_sim_s": wall / t_end}


def test_the_longest_run_at_each_size_sets_the_rate():
    result = {"coupled_run_h2": _run(0.2, 9.4), "reference_run_h2": _run(2.0, 25.5), "reference_run_h1": _run(2.0, 134.0)}
    _cost_rates(result)
    assert result["coupled_run_h2_wall_s_per_sim_s"] == 25.5 / 2.0
    assert result["coupled_run_h1_wall_s_per_sim_s"] == 134.0 / 2.0
    assert result["coupled_run_h2_wall_s_per_sim_s_from"] == "2 s run at h = 2 mm"


def test_without_the_long_runs_the_short_one_sets_it_and_a_failed_run_never_does():
    result = {"coupled_run_h2": _run(0.05, 5.8)}
    _cost_rates(result)
    assert result["coupled_run_h2_wall_s_per_sim_s"] == 5.8 / 0.05 and "coupled_run_h1_wall_s_per_sim_s" not in result
    result = {"coupled_run_h2": _run(0.2, 9.4), "reference_run_h2": _run(2.0, 1.0, status="failed"),
              "reference_run_h1": _run(2.0, 1.0, status="failed")}
    _cost_rates(result)
    assert result["coupled_run_h2_wall_s_per_sim_s"] == 9.4 / 0.2 and "coupled_run_h1_wall_s_per_sim_s" not in result


def test_the_shared_run_sets_the_factor_for_more_than_one_job():
    """The factor is the shared run's rate over the lone reference run's (h = 2 to 2 s), read back for jobs > 1
    only; a failed shared run sets none, and the estimate then takes the documented default."""
    result = {"reference_run_h2": _run(2.0, 13.1), "shared_run_h2": _run(2.0, 20.0)}
    _cost_rates(result)
    assert result["shared_run_factor"] == (20.0 / 2.0) / (13.1 / 2.0)
    assert shared_run_factor(2, result) == (result["shared_run_factor"], "bench")
    assert shared_run_factor(1, result) == (1.0, "one job")
    result = {"reference_run_h2": _run(2.0, 13.1), "shared_run_h2": _run(2.0, 20.0, status="failed")}
    _cost_rates(result)
    assert "shared_run_factor" not in result and shared_run_factor(2, result)[1] == "default"


def _profiled(wall, p_inj, status="ok"):
    return {"status": status, "wall_s": wall, "p_inj_end_kPa": p_inj, "newton_iterations": 10, "factorizations": 3}


def test_side_by_side_comparison_sums_the_pairs_and_reports_the_change_of_p_inj():
    from sweep.studies.bench import _comparison

    c = _comparison(2.0, {"jacobian_reuse": 0.5}, [_profiled(10.0, 400.0), _profiled(14.0, 400.0)],
                    [_profiled(9.0, 400.0004), _profiled(9.0, 400.0004)])
    assert c["wall_ratio"] == 18.0 / 24.0 and c["status"] == "ok"
    assert c["p_inj_end_rel_change"] == abs(400.0004 - 400.0) / 400.0
    failed = _comparison(2.0, {}, [_profiled(10.0, 400.0)], [_profiled(9.0, None, status="failed")])
    assert failed["status"] == "failed" and failed["wall_ratio"] is None and failed["p_inj_end_rel_change"] is None


def test_a_profile_keeps_each_finished_run_when_a_later_one_does_not_finish(tmp_path, monkeypatch):
    """``dchfrac bench --profile --h 2 --h 0.5``: the h = 2 run is in the JSON even if the h = 0.5 run is stopped."""
    from sweep.studies import bench

    monkeypatch.setattr(bench, "_refactorization_h1", lambda: {"refactorization_s": 0.3})

    def run(h, t_end, options=None, model=None):
        if h < 1:
            raise KeyboardInterrupt
        return {"h_mm": h, "wall_s": 1.0, "profile": {"total": {"seconds": 1.0}}}

    monkeypatch.setattr(bench, "profiled_run", run)
    out = tmp_path / "p.json"
    with pytest.raises(KeyboardInterrupt):
        bench.run_profile(out, sizes=(2.0, 0.5))
    assert [r["h_mm"] for r in json.loads(out.read_text())["runs"]] == [2.0]

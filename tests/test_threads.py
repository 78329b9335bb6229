"""A run holds numpy's and scipy's OpenBLAS pools to one thread and gives them back (solver.simulate).

MKL (PARDISO) keeps its threads: only the OpenBLAS libraries are limited.
"""
import importlib

import pytest

from solver import Parameters, RunOptions, simulate

threadpoolctl = pytest.importorskip("threadpoolctl")


def _openblas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"]


def test_a_run_holds_openblas_to_one_thread_and_restores_it(monkeypatch):
    sim_mod = importlib.import_module("solver.simulate")
    before = _openblas_threads()
    assert before, "numpy's OpenBLAS is not visible to threadpoolctl"
    seen = {}
    run = sim_mod._run

    def spying(*args, **kwargs):
        seen["during"] = _openblas_threads()
        return run(*args, **kwargs)

    monkeypatch.setattr(sim_mod, "_run", spying)
    res = simulate(Parameters(), RunOptions(h=6.0, t_end=0.003, snapshot_times=[], write_xdmf=False))
    assert res.status == "ok"
    assert seen["during"] and all(n == 1 for n in seen["during"])
    assert _openblas_threads() == before

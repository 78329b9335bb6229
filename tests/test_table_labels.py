"""Silent wrong answers around a campaign's table: dimensionless numbers, missing labels, the separatrix count."""
from __future__ import annotations

import pandas as pd
import pytest

from sweep.campaign import table as table_mod
from sweep.campaign.boundary import BoundarySampler, _observations
from sweep.campaign.boundary_picks import coord_key, missing_label
from sweep.campaign.spec import spec_from_dict


def _spec():
    return spec_from_dict({"name": "labels_test", "base": {"eta_w": 1e-6, "kbar": 0.0015}, "options": {"h": 4.0},
                           "axes": {"cement": {"linear": [0.5, 3.0, 3]}, "eta_o": {"log": [1e-3, 1.0, 3]}},
                           "sampler": {"kind": "boundary", "label": "fracturing", "budget": 20,
                                       "tolerance": 0.25}})


def test_numbers_of_solver_parameters_and_of_a_custom_runner():
    table_mod._numbers_cache.clear()
    nums = table_mod._numbers({"eta_o": 0.1, "w_i": 50.0})
    assert nums["Ca_star"] > 0 and nums["N_b"] > 0          # the solver's parameters: the numbers
    assert table_mod._numbers({"my_toy_knob": 3.0}) == {}    # a custom runner's: none, by design


def test_a_failure_of_the_numbers_is_raised_not_an_empty_row(monkeypatch):
    import sweep.regimes.numbers as numbers

    def broken(_):
        raise ZeroDivisionError("a bug in the numbers")

    table_mod._numbers_cache.clear()
    monkeypatch.setattr(numbers, "dimensionless_numbers", broken)
    with pytest.raises(ZeroDivisionError, match="a bug"):
        table_mod._numbers({"eta_o": 0.2, "w_i": 50.0})


@pytest.mark.parametrize("v, missing", [(None, True), (pd.NA, True), (float("nan"), True), (False, False),
                                        (True, False), ("fracturing", False)])
def test_missing_label(v, missing):
    assert missing_label(v) is missing


def test_a_na_label_is_no_observation_for_the_boundary_sampler():
    spec = _spec()
    cfg = BoundarySampler()._config(spec)
    t = pd.DataFrame({"cement": [0.5, 3.0], "eta_o": [0.01, 0.1], "status": ["ok", "ok"],
                      "fracturing": pd.array([True, pd.NA], dtype="boolean")})
    obs = _observations(t, cfg)
    assert obs[coord_key([0.5, 0.01])] == "True" and obs[coord_key([3.0, 0.1])] is None   # never the label "<NA>"


def test_the_separatrix_section_counts_the_runs_it_fits():
    from sweep.campaign.report import _separatrix_lines

    spec = spec_from_dict({"name": "sep_test", "base": {"eta_w": 1e-6}, "axes": {"cement": [0.5, 3.0]},
                           "diagrams": [{"kind": "ca_star_vs_cement"}]})
    t = pd.DataFrame({"status": ["ok"] * 5, "cement": [0.5, 1.0, 2.0, 3.0, 1.5],
                      "Ca_star": [1e6, 1e7, 1e5, 1e8, 0.0], "fracturing": [True, False, True, False, True]})
    text = "\n".join(_separatrix_lines(spec, t))
    assert "4 finished runs with a label, 2 fracturing (1 finished run(s) without a fracturing label or a " \
           "positive Ca* left out)." in text

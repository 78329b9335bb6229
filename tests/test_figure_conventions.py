"""Figures fit for a paper (issue #52): one regime palette with labels in words, and a separatrix drawn only when
its fit is significant (likelihood-ratio test against a constant fracturing rate)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sweep.regimes import diagrams as dg


def test_labels_are_words_in_one_palette():
    assert dg.regime_style(True)["label"] == "fracturing" and dg.regime_style("True") == dg.regime_style(True)
    assert "porous invasion" in dg.regime_style(False)["label"]
    assert dg.regime_style(True)["color"] == dg.REGIME_STYLE["invasive_fracturing"]["color"]
    assert dg.regime_style(False)["color"] == dg.REGIME_STYLE["uniform_invasion"]["color"]
    assert dg.regime_style(None)["label"].startswith("failed")
    for name in dg.REGIME_STYLE:
        assert "_" not in dg.regime_style(name)["label"] and "True" not in dg.regime_style(name)["label"]


def _grid(labels):
    C, ca = np.meshgrid(np.linspace(0.5, 3.0, 4), np.logspace(3, 6, 4))
    return pd.DataFrame({"cement": C.ravel(), "Ca_star": ca.ravel(), "fracturing": labels(C.ravel(), ca.ravel())})


def test_a_separatrix_that_explains_the_labels_is_drawn(tmp_path):
    df = _grid(lambda C, ca: np.log10(ca) > 3.5 + 0.8 * C)
    # 16 separable labels: the penalized (Jeffreys) likelihood ratio stays finite, p = 0.0015
    assert dg.separatrix_test(df.cement, df.Ca_star, df.fracturing).p_value < 0.01
    res = dg.plot_ca_star_vs_cement(df, tmp_path / "d.png", formats=())
    assert res["fit"] is not None and res["no_fit_reason"] is None


def test_labels_independent_of_the_axes_give_no_separatrix(tmp_path):
    # a checkerboard over C and Ca*: half the runs fracture at every C and every Ca*, so no line explains them
    df = _grid(lambda C, ca: (np.round(C / 0.8333).astype(int) + np.round(np.log10(ca)).astype(int)) % 2 == 0)
    p = dg.separatrix_test(df.cement, df.Ca_star, df.fracturing).p_value
    assert p > dg.SEPARATRIX_P_MAX
    res = dg.plot_ca_star_vs_cement(df, tmp_path / "d.png", formats=())
    assert res["fit"] is None and ("none found" in res["no_fit_reason"] or "do not locate" in res["no_fit_reason"]
                                   or "does not increase" in res["no_fit_reason"])

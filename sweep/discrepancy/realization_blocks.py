"""The blocks of the mesh-realization covariance (realizations.py): which rows share a block and its kernel.

One data set is one realization of mesh and porosity field for every condition, so its deviation from the
check realizations' mean is shared between the conditions of an observable.  ``[noise] realization_blocks``:

- ``"series"``: one block per series (condition × observable), C_s[i, j] = √(v_i v_j) exp(−|t_i − t_j|/τ_o);
  the series independent of one another.
- ``"observable"``: one block per observable over all its conditions (series),

      C[(c, i), (c', j)] = √(v_i v_j) exp(−|t_i − t_j|/τ_o) · (ρ_o + (1 − ρ_o) δ_cc'),

  ρ_o ∈ [0, 0.99] the correlation between conditions of the realizations' deviation curves
  (:func:`cross_condition_correlation`).  A sum of two PSD kernels (ρ_o · the exponential kernel over all
  rows, (1 − ρ_o) · its block-diagonal part), so PSD, and PD with the diagonal noise beside it.  With
  ρ_o = 0 the kernel is block-diagonal and the observable's series stay separate blocks (each its own
  scale, exactly the "series" covariance).

The correlation across observables of one condition (p_inj and the front move together in one realization)
is not modelled: the observables' correlation times differ, and a cross kernel between two exponential
kernels of different τ with a free correlation is not PSD in general; each observable keeps its own blocks.
Units: times s, τ s; ρ dimensionless.
"""
from __future__ import annotations

import numpy as np

__all__ = ["BLOCK_MODES", "block_rows", "block_kernel", "cross_condition_correlation", "series_labels"]

BLOCK_MODES = ("series", "observable")


def block_rows(layout, mode: str, rho_cond: dict) -> dict:
    """{block key: rows}: per series {series (int): its rows in time order} for ``mode`` "series"; for
    "observable", per observable o with ρ_o = ``rho_cond[o]`` > 0 and more than one series {o (str): the rows
    of its series, series after series in the order of their index, each in time order}, its series kept
    separate otherwise."""
    if mode not in BLOCK_MODES:
        raise ValueError(f"realization covariance: realization_blocks={mode!r} is not allowed: one of {BLOCK_MODES}")
    series_rows = layout.series_rows()
    if mode == "series":
        return dict(series_rows)
    out = {}
    for o in np.unique(layout.obs):
        members = [(s, rows) for s, rows in series_rows.items() if layout.obs[rows[0]] == o]
        if len(members) > 1 and rho_cond.get(str(o), 0.0) > 0.0:
            out[str(o)] = np.concatenate([rows for _, rows in members])
        else:
            out.update(members)
    return out


def series_labels(layout, key, rows: np.ndarray) -> np.ndarray:
    """The series of each of ``rows`` (the layout's; ``key`` for every row without a layout)."""
    return np.asarray(layout.series)[rows] if layout is not None else np.full(rows.size, key)


def block_kernel(layout, rows: np.ndarray, tau: float, rho_c: float) -> np.ndarray:
    """exp(−|t_i − t_j|/τ) · (ρ_c + (1 − ρ_c) δ_ss') between ``rows`` (s, s' their series); the plain
    exponential kernel (:meth:`CurveLayout.exp_correlation`) when the rows are one series."""
    corr = layout.exp_correlation(rows, tau)
    ser = np.asarray(layout.series)[rows]
    if np.all(ser == ser[0]):
        return corr
    return corr * np.where(ser[:, None] == ser[None, :], 1.0, rho_c)


def _matched_points(t_a: np.ndarray, t_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i, j) with t_a[i] = t_b[j] (to 1e-9 relative; ``t_b`` sorted, non-empty): the two series'
    common observation times."""
    hi = np.clip(np.searchsorted(t_b, t_a), 0, t_b.size - 1)
    lo = np.clip(hi - 1, 0, t_b.size - 1)
    j = np.where(np.abs(t_b[lo] - t_a) < np.abs(t_b[hi] - t_a), lo, hi)
    ok = np.isclose(t_b[j], t_a, rtol=1e-9, atol=1e-12)
    return np.flatnonzero(ok), j[ok]


def _effective_points(t: np.ndarray, tau: float) -> float:
    """n² / Σ_ij exp(−2|t_i − t_j|/τ): independent points among n correlated ones for a mean of products
    (Satterthwaite, the product of two deviations correlated as ρ_ij² in time); n when τ <= 0."""
    if tau <= 0:
        return float(t.size)
    return float(t.size**2 / np.exp(-2.0 * np.abs(t[:, None] - t[None, :]) / tau).sum())


def cross_condition_correlation(dev: np.ndarray, layout, obs: str, tau: float) -> tuple[float, float]:
    """The pooled correlation ρ_o between conditions of observable ``obs`` and its degrees of freedom.

    ``dev`` (k, n): the k realizations' deviations from their mean on the rows of ``layout``.  For every
    pair of the observable's series (conditions) and every common observation time, the sample
    correlation over the k realizations of the two deviations; ρ_o is their mean over times and pairs,
    clipped to [0, 0.99] (0 without two series or common times).  Degrees of freedom ν = (k − 1) n_eff,
    n_eff the effective number of independent points of one pair (:func:`_effective_points` with the
    observable's τ, the largest over pairs): the pairs share the same k curves and are not counted as
    independent, so ν is conservative.  ρ_o's sampling sd is about (1 − ρ_o²)/√ν."""
    series_rows = [rows for rows in layout.series_rows().values() if layout.obs[rows[0]] == obs]
    k = dev.shape[0]
    corr, n_eff = [], 0.0
    for a in range(len(series_rows)):
        for b in range(a + 1, len(series_rows)):
            ra, rb = series_rows[a], series_rows[b]
            i, j = _matched_points(layout.t[ra], layout.t[rb])
            da, db = dev[:, ra[i]], dev[:, rb[j]]
            den = np.sqrt(np.sum(da * da, axis=0) * np.sum(db * db, axis=0))
            good = den > 0
            corr.append(np.sum(da * db, axis=0)[good] / den[good])
            n_eff = max(n_eff, _effective_points(layout.t[ra[i[good]]], tau))
    pooled = np.concatenate(corr) if corr else np.zeros(0)
    if pooled.size == 0:
        return 0.0, 0.0
    return float(np.clip(pooled.mean(), 0.0, 0.99)), float((k - 1) * n_eff)

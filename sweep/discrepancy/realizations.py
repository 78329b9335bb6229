"""Mesh realizations in the discrepancy workflow: the fine check runs on several meshes and porosity fields.

The measured data are one realization of mesh and porosity field that the workflow cannot know.  The fine
check realizations give the discretization correction (their mean) and the uncertainty of which
realization the data are: per point (:func:`realization_mean_spread`) or as a covariance correlated in time,
per series or per observable over its conditions (:class:`RealizationCovariance`, realization_blocks.py).
Units those of the observables (kPa, mm), times s.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import stats
from .layout import CurveLayout, correlation_time
from .realization_blocks import block_kernel, block_rows, cross_condition_correlation, series_labels

__all__ = ["realizations", "realization_mean_spread", "RealizationCovariance", "SeriesNull"]


def realizations(fine_forward) -> list:
    """The fine forward models as a list: None -> [], one model -> [model], a list/tuple -> its models."""
    if fine_forward is None:
        return []
    return list(fine_forward) if isinstance(fine_forward, (list, tuple)) else [fine_forward]


@dataclass
class RealizationCovariance:
    """Covariance of the data's mesh-realization deviation, in blocks per series (condition × observable) or
    per observable over its conditions (``mode``, realization_blocks.py).

    The data are one realization of mesh and porosity field; its deviation from the k check realizations'
    mean is a random curve that wanders over stretches of several observation times, which per-point
    variances read as a systematic misfit.  Few curves (k = 3 to 6) cannot estimate its covariance freely (a
    rank-(k − 1) sample covariance gives no variance to a deviation outside their span), so a model with few
    parameters, estimated from the k curves:

        C_s[i, j] = √(v_i v_j) exp(−|t_i − t_j| / τ_o),

    v_i = (1 + 1/k) s_i² averaged over ``window`` neighbouring points of the series (s_i the sample std of
    the realizations at that point; 1 + 1/k: one more realization about a k-sample mean), τ_o per
    observable from the lag-1 autocorrelation ρ of the realizations' deviation curves pooled over
    conditions (estimator ``lag1``, [noise] lag1: :func:`stats.lag1_estimate`), τ = −Δt/ln ρ (Δt the median
    time step; ρ clipped to [0, 0.99]; ρ = 0: C diagonal).
    ``mode`` "series": series are independent of one another.  ``mode`` "observable": an observable's series
    (its conditions) are one block, correlated between conditions at ρ_o, the pooled correlation between
    conditions of the deviation curves (realization_blocks.py); the jitter term stays per series, embedded
    in its block.  Units: v in kPa², mm²; τ in s.
    """

    blocks: dict        # block key (series, or observable) -> (rows, each series in time order, C (n_b, n_b))
    tau: dict           # observable -> correlation time, s
    rho: dict           # observable -> pooled lag-1 autocorrelation of the deviations
    k: int = 0          # number of realizations the covariance was estimated from
    layout: CurveLayout | None = None   # the rows' series, observables and times (s): for scale_dof
    window: int = 5                 # points the per-point variance was averaged over
    # the coarse model's jitter in its parameters (sweep/discrepancy/jitter.py), series -> (rows, C_j): a known
    # covariance added to the realizations' (not scaled by their estimate's uncertainty); None: not modelled
    jitter: dict | None = None
    # the realizations the mean correction in use is taken over (0: all k; [profile] correction_realizations)
    mean_of: int = 0
    mode: str = "series"            # [noise] realization_blocks
    rho_cond: dict | None = None    # observable -> pooled correlation between conditions of the deviations
    rho_cond_dof: dict | None = None    # observable -> its degrees of freedom
    lag1: str = "pooled"            # [noise] lag1: the estimator of rho (stats.LAG1_ESTIMATORS)

    @classmethod
    def empty(cls, layout: CurveLayout) -> "RealizationCovariance":
        """No realization term (k = 0): zero blocks on the series of ``layout``, to carry a jitter term alone."""
        blocks = {s: (rows, np.zeros((rows.size, rows.size))) for s, rows in layout.series_rows().items()}
        return cls(blocks, {}, {}, 0, layout)

    def _series_slots(self) -> dict:
        """{series: (block key, its positions in the block's rows)}."""
        out = {}
        for g, (rows, _) in self.blocks.items():
            lab = series_labels(self.layout, g, rows)
            for s in np.unique(lab):
                out[s.item() if hasattr(s, "item") else s] = (g, np.flatnonzero(lab == s))
        return out

    def with_jitter(self, jitter_blocks: dict | None) -> "RealizationCovariance":
        """This covariance plus the jitter term ``jitter_blocks`` (series -> (rows, C_j), the series' rows in
        its block)."""
        slots = self._series_slots()
        for s, (rows, C) in (jitter_blocks or {}).items():
            g, pos = slots.get(s, (None, None))
            if g is None or not np.array_equal(self.blocks[g][0][pos], rows):
                raise ValueError(f"with_jitter: series {s} rows differ from the realization covariance's")
        return replace(self, jitter=jitter_blocks)

    def _jitter_block(self, g) -> np.ndarray | None:
        """The jitter term on block ``g``'s rows (its series' C_j on the diagonal), None without one."""
        if not self.jitter:
            return None
        rows = self.blocks[g][0]
        parts = [(s, pos) for s, (gs, pos) in self._series_slots().items() if gs == g and s in self.jitter]
        if len(parts) == 1 and parts[0][1].size == rows.size:
            return self.jitter[parts[0][0]][1]
        if not parts:
            return None
        J = np.zeros((rows.size, rows.size))
        for s, pos in parts:
            J[np.ix_(pos, pos)] = self.jitter[s][1]
        return J

    def for_mean_of(self, m: int) -> "RealizationCovariance":
        """This covariance for a correction that is the mean of m of the k realizations (m >= 2; 0: all k):
        the realization term is (1 + 1/k) s² for a k-mean, (1 + 1/m) s² for an m-mean (one more realization
        about an m-sample mean), so every block is scaled by (1 + 1/m)/(1 + 1/k') with k' the mean it was
        made for (calling it twice with the same m changes nothing); the jitter term is kept as is.  Points
        with fewer finite realizations than k take the same factor."""
        if self.k < 2:
            return self
        cur, new = self.mean_of or self.k, m or self.k
        if new < 2 or new > self.k:
            raise ValueError(f"RealizationCovariance.for_mean_of: m={m} is not allowed: 0 or 2..{self.k} (the "
                             "realizations the covariance was estimated from)")
        f = (1.0 + 1.0 / new) / (1.0 + 1.0 / cur)
        return replace(self, blocks={s: (rows, C * f) for s, (rows, C) in self.blocks.items()}, mean_of=m)

    def total(self, g) -> np.ndarray:
        """The covariance of block ``g``: realization term plus jitter term (kPa², mm²)."""
        J = self._jitter_block(g)
        return self.blocks[g][1] + J if J is not None else self.blocks[g][1]

    @classmethod
    def estimate(cls, fines: np.ndarray, layout: CurveLayout, window: int = 5,
                 mode: str = "series", lag1: str = "pooled") -> "RealizationCovariance":
        """From the realizations' predictions ``fines`` (k, n) on the rows of ``layout``, in blocks of ``mode``
        (realization_blocks.py), ρ by the estimator ``lag1`` ([noise] lag1, :func:`stats.lag1_estimate`; a
        point with fewer than 2 finite realizations, or a realization's missing value, left out).  ρ_o
        (``rho_cond``) is estimated in either mode; "series" does not use it."""
        fines = np.atleast_2d(np.asarray(fines, float))
        ok = np.isfinite(fines)
        cnt = ok.sum(axis=0)
        mean, spread = realization_mean_spread(fines)
        with np.errstate(invalid="ignore", divide="ignore"):
            var = np.where(cnt >= 2, (1.0 + 1.0 / cnt) * spread**2, 0.0)
        dev = np.where(ok & (cnt >= 2), fines - np.where(np.isfinite(mean), mean, 0.0), np.nan)
        series_rows = layout.series_rows()
        rho = {str(o): stats.lag1_estimate([dev[:, r] for r in series_rows.values() if layout.obs[r[0]] == o], lag1)
               for o in np.unique(layout.obs)}
        dev = np.where(np.isfinite(dev), dev, 0.0)
        tau = {o: correlation_time(rho[o], layout, o) for o in rho}
        cross = {o: cross_condition_correlation(dev, layout, o, tau[o]) for o in rho}
        rho_c = {o: c[0] for o, c in cross.items()}
        blocks = {}
        for g, rows in block_rows(layout, mode, rho_c).items():
            o = str(layout.obs[rows[0]])
            v = np.concatenate([stats.moving_average(var[r], window) for r in _series_runs(layout, rows)])
            blocks[g] = (rows, np.sqrt(np.outer(v, v)) * block_kernel(layout, rows, tau[o], rho_c[o]))
        return cls(blocks, tau, rho, int(fines.shape[0]), layout, window, mode=mode, rho_cond=rho_c,
                   rho_cond_dof={o: c[1] for o, c in cross.items()}, lag1=lag1)

    def _kernel_squared(self, rows: np.ndarray) -> np.ndarray:
        """ρ_ij² between the block's ``rows``: the kernel with τ/2 and ρ_o² (identity without a layout)."""
        if self.layout is None:
            return np.eye(rows.size)
        o = str(self.layout.obs[rows[0]])
        return block_kernel(self.layout, rows, self.tau.get(o, 0.0) / 2.0, (self.rho_cond or {}).get(o, 0.0) ** 2)

    def variance(self, n: int) -> np.ndarray:
        """Per-point realization variance (the blocks' diagonals) on n rows, kPa² / mm²."""
        out = np.zeros(n)
        for s, (rows, _) in self.blocks.items():
            out[rows] = np.diag(self.total(s))
        return out

    def dense(self, sel: np.ndarray) -> np.ndarray:
        """The covariance on the rows ``sel`` (sorted global indices) as a dense matrix."""
        out = np.zeros((sel.size, sel.size))
        for s, (rows, _) in self.blocks.items():
            C = self.total(s)
            keep = np.isin(rows, sel)
            if keep.any():
                ix = np.searchsorted(sel, rows[keep])
                out[np.ix_(ix, ix)] = C[np.ix_(keep, keep)]
        return out

    def whiteners(self, mask: np.ndarray, sig_diag: np.ndarray) -> list:
        """[(positions in the masked vector, W)] per block with rows in ``mask``: W = R^(−1/2),
        R = I + D^(−1/2) C D^(−1/2) (D = σ_diag²) on those rows (a subset's marginal covariance is the
        sub-block)."""
        rows_m = np.flatnonzero(mask)
        out = []
        for s, (rows, _) in self.blocks.items():
            C = self.total(s)
            keep = mask[rows]
            if not keep.any():
                continue
            r = rows[keep]
            d = sig_diag[r]
            R = np.eye(r.size) + C[np.ix_(keep, keep)] / np.outer(d, d)
            out.append((np.searchsorted(rows_m, r), stats.symmetric_whitener(R)))
        return out

    def _scaled_blocks(self, mask: np.ndarray, sig_diag: np.ndarray):
        """Per series with rows in ``mask``: (series, its rows, the kept rows, A, J), A and J the realization
        and jitter terms on the kept rows over σ_diag² (D^(−1/2) C D^(−1/2)); J None without a jitter term."""
        for s, (rows, C) in self.blocks.items():
            keep = mask[rows]
            if not keep.any():
                continue
            r = rows[keep]
            dd = np.outer(sig_diag[r], sig_diag[r])
            J = self._jitter_block(s)
            yield s, rows, r, C[np.ix_(keep, keep)] / dd, (J[np.ix_(keep, keep)] / dd if J is not None else None)

    def mixture_members(self, mask: np.ndarray, sig_diag: np.ndarray, n_nodes: int = 32) -> list:
        """The whitening's covariance and its scale mixture's members per block (series or observable) with
        rows in ``mask``.

        The realization covariance is estimated from k realizations: the data's true one is λ C with
        λ = v_true/v_est ~ ν/χ²_ν per block (ν from :meth:`scale_dof`, as :meth:`null_calibration`); the
        jitter term is known.  Over σ_diag² (D^(−1/2) · D^(−1/2), dimensionless) the block's covariance is
        R = I + A + J and the m-th member's R(λ_m) = I + λ_m A + J, λ_m the mid quantiles of ``n_nodes``
        equal-probability nodes.  Returns [(positions in the masked vector, R (m, m), R(λ) (n_nodes, m, m))];
        [] when k < 2 (no estimated scale)."""
        from scipy.stats import chi2

        if self.k < 2:
            return []
        rows_m = np.flatnonzero(mask)
        out = []
        for s, rows, r, A, J in self._scaled_blocks(mask, sig_diag):
            J = 0.0 if J is None else J
            nu = self.scale_dof(rows)
            lam = nu / chi2.ppf(1.0 - (np.arange(n_nodes) + 0.5) / n_nodes, nu)
            out.append((np.searchsorted(rows_m, r), np.eye(r.size) + A + J,
                        np.eye(r.size) + lam[:, None, None] * A + J))
        return out

    def scale_mixture(self, mask: np.ndarray, sig_diag: np.ndarray, n_nodes: int = 32) -> list:
        """Terms of the whitened residuals' likelihood with the realization term's scale integrated out.

        With the members R(λ) of :meth:`mixture_members`, a whitened residual r = R^(−1/2) e has
        −2 ln p(r) = −2 ln E_λ[exp(−(eᵀ R(λ)⁻¹ e + ln det R(λ))/2)] + const, e = R^(1/2) r.  The expectation is a
        mean over the ``n_nodes`` equal-probability nodes of λ.  Returns, per block with rows in ``mask``,
        (positions in the masked vector, Q (n_nodes, m, m) with eᵀR(λ)⁻¹e = rᵀ Q r,
        ln det R(λ) − ln det R (n_nodes,)); [] when k < 2 (no estimated scale)."""
        out = []
        for pos, R, Rl in self.mixture_members(mask, sig_diag, n_nodes):
            w, V = np.linalg.eigh(R)
            half = (V * np.sqrt(np.maximum(w, 1e-300))) @ V.T                 # R^(1/2)
            sign, logdet = np.linalg.slogdet(Rl)
            Q = half @ np.linalg.solve(Rl, np.broadcast_to(half, Rl.shape))
            out.append((pos, Q, logdet - np.sum(np.log(np.maximum(w, 1e-300)))))
        return out

    def realization_form(self, x: np.ndarray, mask: np.ndarray, sig_diag: np.ndarray) -> float:
        """xᵀ A x for ``x`` on ``mask``'s rows, A = D^(−1/2) C D^(−1/2) the realization term alone (no jitter;
        D = σ_diag²): the part of a whitened direction's variance estimated from the k realizations.
        Dimensionless."""
        x_full = np.zeros(mask.size)
        x_full[mask] = x
        total = 0.0
        for _, rows, r, A, _ in self._scaled_blocks(mask, sig_diag):
            xb = x_full[r]
            total += float(xb @ A @ xb)
        return total

    def scale_dof(self, rows: np.ndarray) -> float:
        """Degrees of freedom ν of the block's realization-variance scale (the mean of its smoothed v).

        Each point's v is a sample variance over the k realizations (k − 1 degrees of freedom), averaged
        over ``window`` neighbours of its series (the estimate's); points are correlated (ρ_ij = exp(−|t_i −
        t_j|/τ), times ρ_o between conditions in an observable's block), so the block's mean v̄ = Σ c_j s_j²
        (c_j the share of point j in it) has Var(v̄)/E(v̄)² = 2 Σ c_i c_j ρ_ij² / (k − 1) (Isserlis), i.e.
        ν = (k − 1) / Σ c_i c_j ρ_ij² (Satterthwaite): k − 1 for a fully correlated block, up to (k − 1) n for
        independent points.  ``rows``: the block's rows, each series in time order."""
        # the share of each point in the block's mean of the smoothed variances: column sums of each series'
        # moving-average matrix (stats.moving_average applied to the unit vectors)
        runs = _series_runs(self.layout, rows) if self.layout is not None else [rows]
        c = np.concatenate([np.apply_along_axis(stats.moving_average, 0, np.eye(r.size), self.window).sum(axis=0)
                            for r in runs]) / rows.size
        return float((self.k - 1) / (c @ self._kernel_squared(rows) @ c))

    def null_calibration(self, mask: np.ndarray, sig_diag: np.ndarray, n_draws: int = 4000, seed: int = 0) -> dict:
        """Null distributions of the per-series residual statistics when the whitening covariance is estimated.

        The realization covariance is estimated from k realizations: its scale is a sample variance, with
        ν degrees of freedom per block (:meth:`scale_dof`: k − 1 to (k − 1) n).  Under the null (the model
        right, the data one more realization plus noise) the data's true realization covariance is λ C with
        λ = v_true / v_est ~ ν/χ²_ν (mean ν/(ν − 2): a sample variance underestimates 1/v), so the whitened
        residuals are not N(0, I) but a scale mixture with heavier tails, common to the whole block.
        Treated as known, a series whose realization variance came out too small reads as systematic
        (χ² excess z > 3) more often than z_crit says.

        For each block with rows in ``mask``: R = I + D^(−1/2) C D^(−1/2) = U diag(1 + a) Uᵀ (D = σ_diag²),
        the whitened residuals under the null are r = U diag(√((1 + λ a)/(1 + a))) Uᵀ ξ, ξ ~ N(0, I) (λ = 1:
        r = ξ, the known-covariance null).  ``n_draws`` common draws of ξ (and of λ) over the block give both
        distributions of each of its series' (χ² excess z, mean z) (:func:`stats.series_statistics` on the
        series' rows); returns {str(series): SeriesNull} whose
        ``adjust`` maps an observed statistic to the known-covariance value of the same tail probability.
        Deterministic (``seed``).  Empty when k < 2."""
        if self.k < 2:
            return {}
        rng = np.random.default_rng(seed)
        rows_m = np.flatnonzero(mask)
        out = {}
        for s, rows, r, A, J in self._scaled_blocks(mask, sig_diag):
            a, U = np.linalg.eigh(A)
            a = np.maximum(a, 0.0)
            nu = self.scale_dof(rows)
            lam = nu / rng.chisquare(nu, size=n_draws)
            order = np.argsort(np.searchsorted(rows_m, r), kind="stable")   # the residual vector's order
            xi = rng.standard_normal((n_draws, r.size))
            if J is not None:
                mix = _mixture_with_jitter(xi, lam, A, J)
            else:
                mix = ((xi @ U) * np.sqrt((1.0 + lam[:, None] * a) / (1.0 + a))) @ U.T
            lab = series_labels(self.layout, s, r[order])
            for ser in np.unique(lab):
                cols = order[lab == ser]
                _, z0, m0 = stats.series_statistics(xi[:, cols])
                _, z1, m1 = stats.series_statistics(mix[:, cols])
                out[str(ser)] = SeriesNull(np.sort(z0), np.sort(z1), np.sort(m0), np.sort(m1))
        return out


def _series_runs(layout, rows: np.ndarray) -> list:
    """``rows`` split into their series' runs (consecutive rows of one series), in order."""
    ser = np.asarray(layout.series)[rows]
    cut = np.flatnonzero(ser[1:] != ser[:-1]) + 1
    return np.split(rows, cut)


def _mixture_with_jitter(xi: np.ndarray, lam: np.ndarray, A: np.ndarray, J: np.ndarray, n_bins: int = 64) -> np.ndarray:
    """Whitened null residuals when only the realization part A of R = I + A + J is scaled by λ (the jitter
    term J is not estimated from the realizations): given λ, r ~ N(0, R^(−1/2) (I + λA + J) R^(−1/2)), drawn
    as R^(−1/2) (I + λA + J)^(1/2) ξ with λ rounded to the mid-quantile of its bin (``n_bins`` equal-count
    bins; A and J no longer commute, so each bin needs its own square root)."""
    n = A.shape[0]
    Winv = stats.symmetric_whitener(np.eye(n) + A + J)
    order = np.argsort(lam, kind="stable")
    out = np.empty_like(xi)
    for idx in np.array_split(order, min(n_bins, lam.size)):
        if idx.size == 0:
            continue
        w, V = np.linalg.eigh(np.eye(n) + float(np.median(lam[idx])) * A + J)
        M = Winv @ (V * np.sqrt(np.maximum(w, 0.0))) @ V.T
        out[idx] = xi[idx] @ M.T
    return out


@dataclass
class SeriesNull:
    """Sorted null draws of a series' (χ² excess z, mean z): under a known covariance (``*_known``) and
    under the estimated one (``*_mixture``), from common random numbers."""

    z_known: np.ndarray
    z_mixture: np.ndarray
    mean_known: np.ndarray
    mean_mixture: np.ndarray

    @staticmethod
    def _qq(x: float, mixture: np.ndarray, known: np.ndarray) -> float:
        """Quantile map mixture -> known (linear between order statistics, shifted beyond the extremes)."""
        if x > mixture[-1]:
            return float(known[-1] + (x - mixture[-1]))
        if x < mixture[0]:
            return float(known[0] + (x - mixture[0]))
        return float(np.interp(x, mixture, known))

    def adjust(self, z: float, mean_z: float) -> tuple[float, float]:
        """(z, mean z) mapped to the values with the same tail probability under a known covariance."""
        return self._qq(z, self.z_mixture, self.z_known), self._qq(mean_z, self.mean_mixture, self.mean_known)


def realization_mean_spread(fines: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-point mean and sample standard deviation (ddof = 1) over realizations, rows of ``fines`` (k, n).

    Only finite values count (a realization that failed at a point is left out there); the mean is NaN
    where none is finite, the spread 0 where fewer than 2 are.  Units those of ``fines`` (kPa, mm)."""
    fines = np.atleast_2d(np.asarray(fines, float))
    ok = np.isfinite(fines)
    cnt = ok.sum(axis=0)
    vals = np.where(ok, fines, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, vals.sum(axis=0) / cnt, np.nan)
        ss = np.where(ok, (fines - mean) ** 2, 0.0).sum(axis=0)
        spread = np.where(cnt >= 2, np.sqrt(ss / (cnt - 1)), 0.0)
    return mean, spread

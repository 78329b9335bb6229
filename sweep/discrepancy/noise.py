"""The noise model of the discrepancy workflow: what the coarse model is compared with, and with which
covariance.

The comparison is y − err against the coarse model, with err the discretization correction (fine − coarse
at one set of parameter values, the mean over the fine mesh realizations), and the residuals are whitened
with

    Σ_s = diag(σ_diag²) + C_s,     σ_diag² = σ_measured² + (disc_error_fraction · err)²,

per series s (condition × observable) or per observable over its conditions ([noise] realization_blocks), C_s
the mesh-realization covariance (realizations.py) plus the
coarse model's jitter (jitter.py) when those are modelled.  :class:`NoiseModel` holds this state and is
owned by the fitting problem; every change to it bumps ``version``, which the problem's residual cache is
keyed on.  The correction is a vector (``err``: :meth:`NoiseModel.set_discretization`,
:meth:`NoiseModel.shift_correction`) or, inside :meth:`NoiseModel.following`, a function of the parameter values
each model is evaluated at (the profile's linear model, linear_correction.StrengthCorrection): the data a model at θ is
compared with are then y − err(θ) (:meth:`NoiseModel.data_for`), so a fit under it sees the correction's own
derivative.  The functions below compute its pieces from forward runs.  Units: kPa, mm (observables), s.
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from . import stats
from .jitter import ModelJitter, estimate_model_jitter
from .layout import CurveLayout
from .observables import CURVES
from .realizations import RealizationCovariance, realization_mean_spread, realizations

__all__ = ["NoiseModel", "ScaledCovariance", "ScaledMixture", "add_discretization_error", "correction_at", "correction_from",
           "coarse_and_fines", "add_model_jitter", "model_jitter_at",
           "rms_per_observable"]


class NoiseModel:
    """The data the coarse model is compared with and their covariance (see the module docstring).

    y : corrected data (y_measured − err; refused while the correction follows the parameters: use
    :meth:`data_for`); follows : the correction as a function of the parameter values, or None; sig_diag : σ without the realization and jitter terms; sig :
    marginal σ of each point (all terms; figures and held-out gaps); real_cov : the per-series covariance
    (:class:`RealizationCovariance`, jitter included) or None; jitter : :class:`ModelJitter` or None;
    realization_spread : per-point sample std of the fine realizations (0 without them)."""

    def __init__(self, y: np.ndarray, sig: np.ndarray, layout: CurveLayout):
        self.layout = layout
        self.y_measured, self.sig_measured = np.asarray(y, float), np.asarray(sig, float)
        self._y, self.sig, self.sig_diag = self.y_measured, self.sig_measured, self.sig_measured
        self.follows = None
        self.real_cov: RealizationCovariance | None = None
        self.jitter: ModelJitter | None = None
        self.realization_spread = np.zeros(self.y.size)
        self.version = 0
        self.cov_version = 0
        self._whiteners: dict = {}

    def _changed(self, covariance: bool) -> None:
        self.version += 1
        if covariance:
            self.cov_version += 1
            self._whiteners.clear()

    def set_discretization(self, err: np.ndarray, fines: np.ndarray, fraction: float,
                           blocks: str = "series", lag1: str = "pooled") -> None:
        """Compare with y_measured − ``err`` (0 where not finite) and widen σ by ``fraction``·err; ``fines``
        (k, n): the realizations' predictions.  With k >= 2 their deviations enter as a covariance correlated
        in time, in blocks per series or per observable over its conditions (``blocks``, [noise]
        realization_blocks), its correlation time from the lag-1 estimator ``lag1`` ([noise] lag1;
        :meth:`RealizationCovariance.estimate`), else their per-point spread (0 for one model) in
        quadrature.  Replaces any earlier correction; keeps the jitter term."""
        fines = np.atleast_2d(np.asarray(fines, float))
        err = np.where(np.isfinite(err), err, 0.0)
        spread = realization_mean_spread(fines)[1]
        self._y = self.y_measured - err
        sig_diag = np.sqrt(self.sig_measured**2 + (fraction * err) ** 2)
        if fines.shape[0] >= 2:
            self.real_cov = RealizationCovariance.estimate(fines, self.layout, mode=blocks, lag1=lag1)
            self.sig_diag = sig_diag
        else:
            self.real_cov = None
            self.sig_diag = np.sqrt(sig_diag**2 + spread**2)
        self.realization_spread = spread
        self._attach()

    def correction_mean_of(self, m: int) -> None:
        """The correction in use is the mean of the first m of the k realizations (m >= 2; 0: all):
        the realization covariance carries that mean's error (:meth:`RealizationCovariance.for_mean_of`).
        Nothing to do without a realization covariance (k < 2)."""
        if self.real_cov is None or self.real_cov.k < 2:
            return
        self.real_cov = self.real_cov.for_mean_of(m)
        self._attach()

    def set_jitter(self, jitter: ModelJitter | None) -> None:
        """Use ``jitter``'s covariance (None: no jitter term) beside the realization covariance."""
        self.jitter = jitter
        self._attach()

    def _attach(self) -> None:
        """The covariance: the realizations' term (or an empty one, k = 0) plus the jitter term; marginal σ."""
        rc = self.real_cov
        if rc is not None and rc.k == 0:
            rc = None                                 # a jitter-only covariance from an earlier call
        if self.jitter is not None:
            rc = (rc if rc is not None else RealizationCovariance.empty(self.layout)).with_jitter(
                self.jitter.blocks(self.layout))
        elif rc is not None:
            rc = rc.with_jitter(None)
        self.real_cov = rc
        self.sig = (np.sqrt(self.sig_diag**2 + rc.variance(self.sig_diag.size)) if rc is not None
                    else self.sig_diag)
        self._changed(covariance=True)

    @property
    def y(self) -> np.ndarray:
        """The data corrected by the correction vector in use (kPa, mm)."""
        if self.follows is not None:
            raise RuntimeError("NoiseModel.y: the correction follows the parameters here; the data a model is "
                               "compared with are data_for(its values)")
        return self._y

    def data_for(self, values: dict) -> np.ndarray:
        """The data a model at ``values`` ({name: value}, each parameter's unit) is compared with, on every
        row: y_measured − err(values) inside :meth:`following`, else y (kPa, mm)."""
        return self._y if self.follows is None else self.y_measured - self.follows(values)

    @contextmanager
    def following(self, correction):
        """Inside: the correction is ``correction(values)`` (a callable of the parameter values, kPa / mm per
        row) at each model's own values (:meth:`data_for`), σ and the covariance unchanged; the vector in
        use before applies again after.  Not nested."""
        if self.follows is not None:
            raise RuntimeError("NoiseModel.following: a correction already follows the parameters")
        self.follows = correction
        self._changed(covariance=False)
        try:
            yield self
        finally:
            self.follows = None
            self._changed(covariance=False)

    def shift_correction(self, err: np.ndarray | None) -> np.ndarray:
        """Compare with y_measured − ``err`` (σ and the covariance unchanged); None changes nothing.
        Returns the correction vector in use before (to restore it)."""
        old = self.y_measured - self._y
        if err is not None:
            self._y = self.y_measured - err
            self._changed(covariance=False)
        return old

    def standardize(self, diff: np.ndarray, mask: np.ndarray, nan_value: float) -> np.ndarray:
        """Standardized residuals of differences ``diff`` (data − model, kPa / mm) on the rows of ``mask``.

        e = diff/σ_diag (non-finite entries set to ``nan_value``), whitened per series when a covariance is
        modelled: with Σ_s = diag(σ_diag²) + C_s, r_s = (D^(−1/2) Σ_s D^(−1/2))^(−1/2) e_s, so
        r·r = diffᵀ Σ⁻¹ diff (generalized least squares).  Without it this is e itself."""
        e = diff / self.sig_diag[mask]
        e = np.where(np.isfinite(e), e, nan_value)
        if self.real_cov is None:
            return e
        key = mask.tobytes()
        if key not in self._whiteners:
            self._whiteners[key] = self.real_cov.whiteners(mask, self.sig_diag)
        out = e.copy()
        for pos, W in self._whiteners[key]:
            out[pos] = W @ e[pos]
        return out

    def correlation(self, mask: np.ndarray) -> np.ndarray:
        """R = I + D^(−1/2) C D^(−1/2) on ``mask``'s rows (dense; D = σ_diag², C the realization and jitter
        covariance, none: R = I): the covariance of e = diff/σ_diag."""
        key = ("dense", mask.tobytes())
        if key not in self._whiteners:
            sel = np.flatnonzero(mask)
            d = self.sig_diag[sel]
            C = self.real_cov.dense(sel) if self.real_cov is not None else np.zeros((sel.size, sel.size))
            self._whiteners[key] = np.eye(sel.size) + C / np.outer(d, d)
        return self._whiteners[key]

    def with_scaled(self, mask: np.ndarray, extra: np.ndarray) -> "ScaledCovariance":
        """Whitening on ``mask``'s rows with the modelled covariance plus s × ``extra`` (kPa², mm²), any s >= 0
        (:class:`ScaledCovariance`; valid until the covariance changes: ``cov_version``)."""
        return ScaledCovariance(self.sig_diag[mask], self.correlation(mask), extra)

    def marginal_deviance(self, r: np.ndarray, mask: np.ndarray) -> float:
        """−2 ln of the likelihood of standardized residuals ``r`` (:meth:`standardize` on ``mask``'s rows)
        with the realization covariance's scale integrated over its sampling distribution
        (:meth:`RealizationCovariance.scale_mixture`), up to a constant that does not depend on r; r·r without
        an estimated realization covariance (k < 2), where the Gaussian likelihood is exact.  The mixture's
        tails are heavier than the Gaussian's: a series whose realization variance came out too small costs
        less than r·r says, as the finite number of realizations warrants."""
        from scipy.special import logsumexp

        r = np.asarray(r, float)
        terms = self._whiteners.get(("mixture", mask.tobytes()))
        if terms is None:
            terms = self.real_cov.scale_mixture(mask, self.sig_diag) if self.real_cov is not None else []
            self._whiteners[("mixture", mask.tobytes())] = terms
        total = float(r @ r)
        for pos, Q, logdet in terms:
            rs = r[pos]
            q = np.einsum("i,mij,j->m", rs, Q, rs)
            total += -2.0 * (logsumexp(-0.5 * (q + logdet)) - np.log(q.size)) - float(rs @ rs)
        return total

    def with_scaled_mixture(self, mask: np.ndarray, extra: np.ndarray) -> "ScaledMixture":
        """The marginal deviance (:meth:`marginal_deviance`) on ``mask``'s rows with s × ``extra`` (kPa², mm²)
        added to every member of the scale mixture, any s >= 0 (:class:`ScaledMixture`; valid until the
        covariance changes: ``cov_version``)."""
        members = self.real_cov.mixture_members(mask, self.sig_diag) if self.real_cov is not None else []
        return ScaledMixture(self.with_scaled(mask, extra), members, extra)

    def threshold_dof(self, kind: str, J: np.ndarray, j: int, mask: np.ndarray) -> float:
        """Degrees of freedom of the profile threshold F(1, ν) for ``[profile] threshold`` = ``kind``: ∞ for
        "chi2" and without an estimated realization covariance (k < 2); k − 1 for "f_realizations" (the
        strength's variance counted as estimated from the k realizations: its realization part along the
        strength's direction is, and when that part dominates the variance this is the whole variance's dof,
        see :meth:`strength_dof`); the Welch–Satterthwaite ν of :meth:`strength_dof` for "f_welch".  ``J``,
        ``j``, ``mask``: as :meth:`strength_dof`."""
        rc = self.real_cov
        if kind not in stats.THRESHOLDS:
            raise ValueError(f"threshold_dof: kind={kind!r} is not allowed: one of {stats.THRESHOLDS}")
        if kind == "chi2" or rc is None or rc.k < 2:
            return math.inf
        return float(rc.k - 1) if kind == "f_realizations" else self.strength_dof(J, j, mask)

    def strength_dof(self, J: np.ndarray, j: int, mask: np.ndarray) -> float:
        """Degrees of freedom ν of the variance of parameter ``j``'s estimate, its realization part known to
        k − 1 (``[profile] threshold = "f_welch"``; ∞ without an estimated realization covariance).

        ``J`` (n, p): the Jacobian of the standardized residuals (:meth:`standardize` on ``mask``'s rows) in
        the fit's coordinates.  The estimate moves by aᵀe for standardized data errors e (e = diff/σ_diag),
        a = W u with u = J (JᵀJ)⁻¹ e_j and W = R^(−1/2) the whitener, and its variance V = aᵀ R a = uᵀu splits
        into the realization term's part V_r = aᵀ A a (A = D^(−1/2) C D^(−1/2), estimated from the k
        realizations) and the known rest (measurement noise, the disc_error_fraction term, the jitter term).  The
        data's realization deviation enters a as one random curve about the k-mean; the sample variance of
        any fixed projection of it over k realizations has k − 1 degrees of freedom, so V_r is known to k − 1.
        The covariance model pools per-point variances over time and conditions and claims up to (k − 1)·n_eff
        for its scale (:meth:`RealizationCovariance.scale_dof`), but the strength's direction is a slow,
        shared one whose variance it extrapolates from the lag-1 correlation and ρ_o rather than measures
        (results/discrepancy/shared_realization/README.md, "Few realizations").  V's degrees of freedom are
        then the Welch–Satterthwaite ν = (k − 1)(V/V_r)² (:func:`stats.welch_dof`): k − 1 when the realization
        term is all of V, whereupon (θ̂ − θ)²/V̂ is F(1, k − 1), the prediction interval of one more
        realization (Student 1908; Hahn & Meeker 1991, Statistical Intervals, §4.7); ∞ as k → ∞ or V_r → 0.
        V_r here is the model's estimate: where it is low (few realizations, the lag-1 τ̂ short), its share and
        so ν come out too high (plug-in Satterthwaite is anti-conservative at small k), which "f_realizations"
        (ν = k − 1 for the whole variance) avoids."""
        rc = self.real_cov
        if rc is None or rc.k < 2:
            return math.inf
        J = np.asarray(J, float)
        u = J @ np.linalg.pinv(J.T @ J)[:, j]
        a = self.standardize(u * self.sig_diag[mask], mask, 0.0)          # W u
        return stats.welch_dof(float(u @ u), rc.realization_form(a, mask, self.sig_diag), rc.k - 1)

    def null_calibration(self, mask: np.ndarray, seed: int) -> dict | None:
        """The residual test's null for the estimated realization covariance on ``mask``'s rows (None
        without one): :meth:`RealizationCovariance.null_calibration`."""
        if self.real_cov is None:
            return None
        return self.real_cov.null_calibration(mask, self.sig_diag, seed=seed)


class ScaledCovariance:
    """Residuals whitened with Σ + s·X for a fixed added covariance X (an emulator's, kPa², mm²) and any
    scalar s >= 0, each in O(n²): with W₀ = R^(−1/2) (the modelled covariance over σ_diag², R) and
    W₀ X_e W₀ = Q Γ Qᵀ (X_e = D^(−1/2) X D^(−1/2)), the whitener W_s = Q (I + sΓ)^(−1/2) Qᵀ W₀ has
    W_sᵀ W_s = (R + s X_e)⁻¹ and is W₀ (:meth:`NoiseModel.standardize`) at s = 0, so r·r = diffᵀ(Σ + sX)⁻¹diff
    and the rows keep their meaning for small s."""

    def __init__(self, d: np.ndarray, R: np.ndarray, extra: np.ndarray):
        self.d = np.asarray(d, float)
        self.W0 = stats.symmetric_whitener(R)
        B = self.W0 @ (np.asarray(extra, float) / np.outer(self.d, self.d)) @ self.W0
        g, self.Q = np.linalg.eigh(0.5 * (B + B.T))
        self.gamma = np.maximum(g, 0.0)
        self.QtW0 = self.Q.T @ self.W0

    def standardize(self, diff: np.ndarray, s: float) -> tuple[np.ndarray, float]:
        """Whitened residuals of ``diff`` (data − model, finite; kPa, mm) with Σ + s·X, and the
        log-determinant the added term adds, ln det(Σ + sX) − ln det Σ (its part of −2 ln L)."""
        z = self.QtW0 @ (np.asarray(diff, float) / self.d)
        return self.Q @ (z / np.sqrt(1.0 + s * self.gamma)), float(np.sum(np.log1p(s * self.gamma)))

    def sd_norm(self, s: float) -> float:
        """√tr(Σ⁻¹ s X): the expected norm of a deviation of covariance s·X whitened with Σ alone."""
        return float(math.sqrt(max(s * float(np.sum(self.gamma)), 0.0)))


class ScaledMixture:
    """The marginal deviance (:meth:`NoiseModel.marginal_deviance`) with a fixed added covariance X (an
    emulator's, kPa², mm²) scaled by any s >= 0 in every Gaussian term: for the m-th member of a series'
    scale mixture the covariance is Σ_m + s·X_ss instead of Σ_m.

    Over σ_diag² (e = diff/σ_diag) a series' members are R_m = I + λ_m A + J and X_e its block of
    D^(−1/2) X D^(−1/2).  With R_m = L_m L_mᵀ (Cholesky) and L_m⁻¹ X_e L_m⁻ᵀ = U_m Γ_m U_mᵀ,

        eᵀ (R_m + s X_e)⁻¹ e = Σ_i z_mi² / (1 + s γ_mi),   z_m = U_mᵀ L_m⁻¹ e,
        ln det(R_m + s X_e) = ln det R_m + Σ_i ln(1 + s γ_mi),

    exact for any s, O(n³) per member once and O(n²) per member and evaluation.  The deviance is

        D(diff, s) = r·r + Σ_series [−2 ln mean_m exp(−(q_m + ln det(R_m + sX_e) − ln det(R + sX_e))/2) − q_R],

    r the residuals whitened with the whole Σ + sX (:class:`ScaledCovariance`: the emulator's covariance
    across series kept), q_m and q_R the quadratic forms of the series' members and of R = I + A + J, its
    covariance in the whitening.  It is −2 ln of the marginal likelihood with covariance Σ_m + sX per member
    up to ln det(2π(Σ + sX)) (left out as in the profile's Gaussian Δχ², :class:`ScaledCovariance`), exactly
    when X has no cross-series terms (one series, or a block-diagonal X); with cross-series terms the Gaussian
    part is exact and each series' mixture correction uses its own block of X.  With s = 0 it is
    :meth:`NoiseModel.marginal_deviance`; without mixture terms (k < 2) the Gaussian r·r with Σ + sX.
    Dimensionless."""

    def __init__(self, gauss: ScaledCovariance, members: list, extra: np.ndarray):
        self.gauss = gauss
        X_e = np.asarray(extra, float) / np.outer(gauss.d, gauss.d)
        self.series = []
        for pos, R, Rl in members:
            stack = np.concatenate([R[None], Rl])                      # the reference R first, then R(λ_m)
            L = np.linalg.cholesky(stack)
            Linv = np.linalg.inv(L)
            B = Linv @ X_e[np.ix_(pos, pos)] @ np.swapaxes(Linv, 1, 2)
            g, U = np.linalg.eigh(0.5 * (B + np.swapaxes(B, 1, 2)))
            ld0 = 2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)), axis=1)
            self.series.append((pos, np.swapaxes(U, 1, 2) @ Linv, np.maximum(g, 0.0), ld0))

    def deviance(self, diff: np.ndarray, s: float) -> float:
        """D(``diff``, ``s``) of the class docstring for differences ``diff`` (data − model, finite; kPa, mm)."""
        from scipy.special import logsumexp

        diff = np.asarray(diff, float)
        r = self.gauss.standardize(diff, s)[0]
        e = diff / self.gauss.d
        total = float(r @ r)
        for pos, T, g, ld0 in self.series:
            z = T @ e[pos]                                             # (1 + n_nodes, m)
            q = np.sum(z * z / (1.0 + s * g), axis=1)
            ld = ld0 + np.sum(np.log1p(s * g), axis=1)
            mix = -2.0 * (logsumexp(-0.5 * (q[1:] + ld[1:] - ld[0])) - np.log(q.size - 1))
            total += mix - float(q[0])
        return total


def rms_per_observable(layout: CurveLayout, v: np.ndarray) -> dict:
    """RMS of the per-row values ``v`` per observable (their unit)."""
    return {o: float(np.sqrt(np.mean(v[layout.obs == o] ** 2))) for o in CURVES if np.any(layout.obs == o)}


def coarse_and_fines(problem, fines_fw: list, values: dict) -> tuple[np.ndarray, np.ndarray]:
    """The coarse model (n,) and each fine model (k, n) at ``values`` on every curve row of ``problem``."""
    ids = problem.data.ids
    allm = np.ones(problem.y.size, bool)
    coarse = problem.model_vector(problem.predict([values], ids)[0], allm)
    jobs = [(problem.overrides(cid, values), problem.times[cid]) for cid in ids]
    fines = np.vstack([problem.model_vector(dict(zip(ids, f.predict_many(jobs))), allm) for f in fines_fw])
    return coarse, fines


def correction_at(problem, fine_forward, values: dict) -> np.ndarray:
    """Mesh correction err = mean_k(fine_k) − coarse at ``values`` on every curve row (0 where not finite)."""
    coarse, fines = coarse_and_fines(problem, realizations(fine_forward), values)
    return correction_from(coarse, fines)


def correction_from(coarse: np.ndarray, fines: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
    """err = mean_k(fine_k) − coarse per row (0 where not finite) from the coarse run (n,) and fine
    realizations (m, n) at one point.  With ``ref`` (k, n; k >= m), the same realizations at another point,
    the first m of them in the same order: err = mean(ref) + mean_k<m(fine_k − ref_k) − coarse, the mean over
    all k realizations carried to this point by the change of the m run here (common random numbers: each
    realization's own deviation cancels in its change).  kPa / mm."""
    mean = realization_mean_spread(fines)[0]
    if ref is not None:
        ref = np.atleast_2d(np.asarray(ref, float))
        fines = np.atleast_2d(np.asarray(fines, float))
        mean = realization_mean_spread(ref)[0] + realization_mean_spread(fines - ref[: len(fines)])[0]
    err = mean - coarse
    return np.where(np.isfinite(err), err, 0.0)


def add_discretization_error(problem, fine_forward, values: dict | None = None) -> dict:
    """Correct ``problem``'s data for the model's discretization error and widen the uncertainties.

    err = mean_k(fine_k) − coarse per point, at ``values`` (default: the baseline at its initial values),
    over ``fine_forward`` (one forward model or a list of k mesh realizations: other perturbed meshes and
    element-wise porosity fields).  The data are one such realization and the model cannot know which, so
    the mean is the correction and the realizations' deviations are an uncertainty of the comparison
    (:meth:`NoiseModel.set_discretization`).  Non-finite values are left out per point.  Always applied to
    the data as measured: a second call replaces the first.  Returns the RMS of err per observable."""
    fines_fw = realizations(fine_forward)
    if not fines_fw:
        raise ValueError("add_discretization_error: no fine forward model")
    vals = values if values is not None else {p.name: p.initial for p in problem.spec.calibrate}
    coarse, fines = coarse_and_fines(problem, fines_fw, vals)
    err = realization_mean_spread(fines)[0] - coarse
    err = np.where(np.isfinite(err), err, 0.0)
    opts = problem.spec.noise
    problem.noise.set_discretization(err, fines, opts.disc_error_fraction, opts.realization_blocks, opts.lag1)
    return rms_per_observable(problem.layout, err)


def model_jitter_at(problem, values: dict, params, n_steps: int | None = None,
                    rel_step: float | None = None) -> ModelJitter | None:
    """The coarse model's jitter at ``values`` in the directions of ``params`` (CalibParam), over every
    condition (training and held out: the held-out gap is measured with the same σ); ``runs`` booked.
    ``n_steps``, ``rel_step``: the spec's ``[noise] model_jitter_steps``, ``model_jitter_rel_step`` unless given."""
    opts = problem.spec.noise
    allm = np.ones(problem.y.size, bool)
    before = int(getattr(problem.forward, "n_runs", 0))

    def evaluate(vlist):
        return np.vstack([problem.model_vector(pr, allm) for pr in problem.predict(vlist, problem.data.ids)])

    mj = estimate_model_jitter(evaluate, problem.layout, values, params,
                               n_steps=opts.model_jitter_steps if n_steps is None else n_steps,
                               rel_step=opts.model_jitter_rel_step if rel_step is None else rel_step, lag1=opts.lag1)
    if mj is not None:
        mj.runs = int(getattr(problem.forward, "n_runs", 0)) - before
    return mj


def add_model_jitter(problem, values: dict, params) -> dict | None:
    """Estimate the coarse model's jitter at ``values`` (:func:`model_jitter_at`) and whiten with it.
    Returns its summary (RMS per observable in kPa / mm, correlation times in s, runs spent), None when
    nothing could be stepped."""
    problem.noise.set_jitter(model_jitter_at(problem, values, params))
    j = problem.noise.jitter
    return j.summary(problem.layout) if j is not None else None

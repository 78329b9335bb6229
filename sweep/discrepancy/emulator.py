"""A Gaussian-process emulator of the coarse model's curves over the fitted parameters, for the profile
likelihood (``[profile] emulator = "gp"``) and the refits of whole models (``[profile] emulate_refits``,
emulated.py).

Each profile point refits the calibrated parameters at a held strength; with the real model every residual
evaluation of those refits is one forward run per training condition.  The emulator replaces them: it is
built from a small space-filling design of real runs around the fit (in the parameters' fit coordinates,
log10 or linear), and refined with real runs where the profile goes.

The model (a separable, "multi-output" Gaussian process: Conti & O'Hagan 2010, with the outputs in units of
the measurement noise): every output row k (a condition's observable at one time, over its σ) is

    z_k(u) = h(u)ᵀ β_k + ε_k(u),    Cov(ε_k(u), ε_l(u')) = Σ_kl (ρ(u, u') + g δ_uu')

with h = (1, u) a linear mean in the design box's unit coordinates u, ρ a Matérn-5/2 correlation with one
length per parameter, g a nugget (the model's own jitter between nearby parameters), and Σ the outputs'
covariance.  The lengths and g maximize the restricted likelihood pooled over the outputs (every output in
noise units weighs as much as its variation); β and Σ are their generalized-least-squares estimates, Σ with
n − q − 2 degrees of freedom (the posterior mean under a flat prior, so the Student-t predictive's variance).
The prediction at u is the kriging mean and the covariance

    V(u) = (c(u) + g) Σ,    c(u) = 1 − kᵀK⁻¹k + (h − HᵀK⁻¹k)ᵀ (HᵀK⁻¹H)⁻¹ (h − HᵀK⁻¹k),

the error of the emulator against a real run there (c: the smooth part's posterior variance, g: the run's
jitter about it, with the outputs' covariance Σ too: conservative along the parameters' directions, where Σ
is largest).  V enters the likelihood: residuals are whitened with Σ_noise + V
(:class:`~.noise.ScaledCovariance`), or, with ``[profile] likelihood = "marginal"``, V is added to every
member of the realization scale's mixture (:class:`~.noise.ScaledMixture`), so the emulator's error only
widens the profile's interval (profile.py leaves the log-determinant of Σ_noise + V out).  Units: each output's own (kPa, mm) in and out; the design in the
parameters' fit coordinates.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import least_squares, minimize

from . import stats
from .problem import Fit

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["GaussianProcess", "CurveEmulator", "space_filling", "AGREE_SD", "wald_box", "design_points", "fill_design",
           "fit_on_emulator"]

AGREE_SD = 2.0            # a real run agrees with the emulator when within this many of its predicted sd
_LOG_LEN = (math.log(0.1), math.log(5.0))      # correlation lengths in the design box's unit coordinates
_LOG_NUGGET = (math.log(1e-9), math.log(1.0))  # the nugget, relative to the outputs' variance


def _matern52(a: np.ndarray, b: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Matérn-5/2 correlation between the rows of ``a`` (m, d) and ``b`` (n, d), one length per column."""
    d = np.sqrt(np.sum(((a[:, None, :] - b[None, :, :]) / lengths) ** 2, axis=-1))
    s = math.sqrt(5.0) * d
    return (1.0 + s + s * s / 3.0) * np.exp(-s)


def _basis(u: np.ndarray) -> np.ndarray:
    """The mean's regressors h(u) = (1, u) per row."""
    return np.column_stack([np.ones(len(u)), u])


class GaussianProcess:
    """The separable Gaussian process of the module docstring, fitted to a design ``U`` (n, d) in [0, 1]^d
    (unit coordinates) and outputs ``Z`` (n, r) (in noise units).  Needs n >= d + 4 points."""

    def __init__(self, U: np.ndarray, Z: np.ndarray, start: np.ndarray | None = None):
        self.U, self.Z = np.atleast_2d(np.asarray(U, float)), np.atleast_2d(np.asarray(Z, float))
        n, d = self.U.shape
        self.q = d + 1
        if n < self.q + 3:
            raise ValueError(f"GaussianProcess: {n} design points for {d} parameters; needs >= {self.q + 3}")
        self.H = _basis(self.U)
        self.lengths, self.nugget = self._hyper(start)
        self._condition()

    def _parts(self, lengths: np.ndarray, g: float):
        """Cholesky of K = ρ + g I, K⁻¹H, the Cholesky of HᵀK⁻¹H, β̂ and the GLS residuals."""
        K = _matern52(self.U, self.U, lengths) + g * np.eye(len(self.U))
        cK = cho_factor(K, lower=True)
        KiH = cho_solve(cK, self.H)
        cA = cho_factor(self.H.T @ KiH, lower=True)
        beta = cho_solve(cA, KiH.T @ self.Z)
        return cK, KiH, cA, beta, self.Z - self.H @ beta

    def _reml(self, theta: np.ndarray) -> float:
        """−2 ln of the restricted likelihood pooled over the outputs (one variance for all, noise units)."""
        d = self.U.shape[1]
        try:
            cK, _, cA, _, E = self._parts(np.exp(theta[:d]), math.exp(theta[d]))
        except np.linalg.LinAlgError:
            return 1e300
        n, r = self.Z.shape
        s = float(np.sum(E * cho_solve(cK, E)))
        logdet = 2 * np.sum(np.log(np.diag(cK[0]))) + 2 * np.sum(np.log(np.diag(cA[0])))
        return (n - self.q) * r * math.log(max(s, 1e-300) / ((n - self.q) * r)) + r * logdet

    def _hyper(self, start) -> tuple[np.ndarray, float]:
        """Lengths and nugget by the pooled restricted likelihood (L-BFGS-B) from a few starts, or from
        ``start`` (log lengths and log nugget of an earlier fit: a design grown by a point) and one other."""
        d = self.U.shape[1]
        bounds = [_LOG_LEN] * d + [_LOG_NUGGET]
        starts = [np.array([math.log(l0)] * d + [math.log(1e-6)]) for l0 in (0.2, 0.6, 2.0)]
        if start is not None:
            starts = [np.clip(start, [b[0] for b in bounds], [b[1] for b in bounds]), starts[1]]
        best = None
        for x0 in starts:
            res = minimize(self._reml, x0, method="L-BFGS-B", bounds=bounds)
            if best is None or res.fun < best.fun:
                best = res
        return np.exp(best.x[:d]), float(math.exp(best.x[d]))

    def _condition(self) -> None:
        """The fitted model's fixed parts: K's factor, β̂, K⁻¹(Z − Hβ̂) and the outputs' covariance Σ."""
        self._cK, self._KiH, self._cA, self.beta, E = self._parts(self.lengths, self.nugget)
        self._alpha = cho_solve(self._cK, E)
        n = len(self.U)
        self.out_cov = E.T @ self._alpha / (n - self.q - 2)

    def predict(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean (m, r) and the posterior variance factor c(u) (m,) of the smooth part at the rows of ``u``
        (m, d): the outputs' covariance there is c Σ (``out_cov``), a real run's (c + nugget) Σ."""
        u = np.atleast_2d(np.asarray(u, float))
        k = _matern52(u, self.U, self.lengths)                   # (m, n)
        h = _basis(u)
        mean = h @ self.beta + k @ self._alpha
        Kik = cho_solve(self._cK, k.T)                           # (n, m)
        rr = h.T - self._KiH.T @ k.T                             # (q, m)
        c = 1.0 - np.sum(k.T * Kik, axis=0) + np.sum(rr * cho_solve(self._cA, rr), axis=0)
        return mean, np.maximum(c, 0.0)

    def sd(self, u: np.ndarray, run: bool = False) -> np.ndarray:
        """Predictive sd (m, r) of each output at the rows of ``u``: of the smooth part, or of a real run
        there (``run``: the nugget added)."""
        c = self.predict(u)[1] + (self.nugget if run else 0.0)
        return np.sqrt(np.outer(c, np.maximum(np.diag(self.out_cov), 0.0)))

    @property
    def theta(self) -> np.ndarray:
        """Log lengths and log nugget (a start for the next fit)."""
        return np.append(np.log(self.lengths), math.log(self.nugget))


def space_filling(n: int, lo: np.ndarray, hi: np.ndarray, seed: int) -> np.ndarray:
    """``n`` points of a scrambled Halton sequence (low discrepancy for any n) in the box [lo, hi]."""
    from scipy.stats import qmc

    u = qmc.Halton(d=len(lo), scramble=True, seed=seed).random(n)
    return lo + u * (hi - lo)


class CurveEmulator:
    """The coarse model's curves on the rows of conditions ``ids`` as a function of ``params`` (a fit's
    CalibParam tuple) in their fit coordinates: a :class:`GaussianProcess` on real runs.

    box : (lo, hi) of the design in fit coordinates; the emulator is refitted after every added run (a
    design point whose run failed, non-finite anywhere, is kept out of the fit and counted in ``failed``; the
    process is fitted once there are parameters + 4 points).
    ``runs``: forward runs the emulator asked for."""

    def __init__(self, problem, params: tuple, ids, box: tuple):
        self.problem, self.params, self.ids = problem, tuple(params), list(ids)
        self.mask = problem.mask(self.ids)
        self.lo, self.hi = (np.asarray(b, float) for b in box)
        self.scale = np.array(problem.sig_diag[self.mask], float)   # outputs in noise units for the fit
        self.X = np.zeros((0, len(self.params)))
        self.M = np.zeros((0, int(self.mask.sum())))
        self.failed = 0
        self.runs = 0
        self.refinements = 0
        self.gp: GaussianProcess | None = None
        self._w, self._wkey = None, None
        self._m, self._mkey = None, None

    def _unit(self, x) -> np.ndarray:
        return (np.atleast_2d(np.asarray(x, float)) - self.lo) / (self.hi - self.lo)

    def model_vectors(self, xs: list) -> np.ndarray:
        """The real coarse model at each x of ``xs`` on the rows (one batch of runs; the problem's cache
        serves the points it holds, so the fit's own point costs nothing)."""
        problem = self.problem
        held, problem.fixed = problem.fixed, {}
        before = int(getattr(problem.forward, "n_runs", 0))
        try:
            problem.residual_batch(self.params, [np.asarray(x, float) for x in xs], self.ids)
            out = np.vstack([problem.model_vector(problem.prediction(self.params, x, self.ids), self.mask)
                             for x in xs])
        finally:
            problem.fixed = held
        self.runs += int(getattr(problem.forward, "n_runs", 0)) - before
        return out

    def add(self, xs: list, ms: np.ndarray | None = None) -> None:
        """Add the points ``xs`` (fit coordinates) with their real runs (run now unless given as ``ms``)
        to the design and refit the process."""
        ms = self.model_vectors(xs) if ms is None else np.atleast_2d(ms)
        ok = np.all(np.isfinite(ms), axis=1)
        self.failed += int((~ok).sum())
        self.X = np.vstack([self.X, np.atleast_2d(np.asarray(xs, float))[ok]])
        self.M = np.vstack([self.M, ms[ok]])
        if len(self.X) >= len(self.params) + 4:     # enough points for the process (failed runs left out)
            self.gp = GaussianProcess(self._unit(self.X), self.M / self.scale,
                                      start=self.gp.theta if self.gp is not None else None)

    def has(self, x) -> bool:
        """Whether ``x`` (fit coordinates) is a design point already (within 1e-9 of the box)."""
        return bool(np.any(np.all(np.abs(self.X - np.asarray(x, float)) <= 1e-9 * (self.hi - self.lo), axis=1)))

    def predict(self, x) -> tuple[np.ndarray, float]:
        """The emulated model vector (rows,) at ``x`` (fit coordinates) and the scale s of the covariance
        s·``out_cov()`` of a real run about it (s = c(u) + nugget)."""
        mean, c = self.gp.predict(self._unit(x))
        return mean[0] * self.scale, float(c[0]) + self.gp.nugget

    def out_cov(self) -> np.ndarray:
        """The outputs' covariance Σ of the process in the outputs' units (kPa², mm²)."""
        return self.gp.out_cov * np.outer(self.scale, self.scale)

    def whitener(self):
        """The noise model's whitening with the emulator's covariance added (:class:`~.noise.ScaledCovariance`),
        rebuilt when the process or the noise model's covariance changed."""
        key = (id(self.gp), self.problem.noise.cov_version)
        if self._wkey != key:
            self._w, self._wkey = self.problem.noise.with_scaled(self.mask, self.out_cov()), key
        return self._w

    def mixture(self):
        """The noise model's marginal deviance with the emulator's covariance added to every member of its
        scale mixture (:class:`~.noise.ScaledMixture`), rebuilt when the process or the noise model's
        covariance changed."""
        key = (id(self.gp), self.problem.noise.cov_version)
        if self._mkey != key:
            self._m, self._mkey = self.problem.noise.with_scaled_mixture(self.mask, self.out_cov()), key
        return self._m

    def marginal_deviance(self, x) -> float:
        """The marginal deviance (dimensionless) of the data against the emulated model at ``x`` (fit
        coordinates), with the covariance s·Σ_out of a real run about it in every Gaussian term
        (:meth:`mixture`)."""
        mean, s = self.predict(x)
        return self.mixture().deviance(self.problem.data_at(self.params, x)[self.mask] - mean, s)

    def sd_norm(self, x, run: bool = False) -> float:
        """√tr(Σ⁻¹ V) at ``x`` (Σ the noise model's covariance on the rows, V the emulator's): its predictive
        sd as the expected norm of the whitened error, of the smooth part (what more runs nearby reduce) or,
        with ``run``, of a real run there (the nugget's jitter included)."""
        s = self.predict(x)[1]
        return self.whitener().sd_norm(s if run else max(s - self.gp.nugget, 0.0))

    def jitter_norm(self) -> float:
        """The nugget's part of :meth:`sd_norm` (a run's jitter about the smooth part, the same everywhere):
        the floor below which more runs do not bring the smooth part's sd in practice."""
        return self.whitener().sd_norm(self.gp.nugget)

    def deviation(self, x, m_real: np.ndarray) -> float:
        """|whitened(m_real − emulated mean)| at ``x`` (whitened with the noise model alone)."""
        mean, _ = self.predict(x)
        r = self.problem.noise.standardize(np.asarray(m_real, float) - mean, self.mask, 0.0)
        return float(np.sqrt(r @ r))

    def summary(self) -> dict:
        g = self.gp
        return {"design_points": int(len(self.X)), "failed_runs": self.failed, "forward_runs": self.runs,
                "refinements": self.refinements,
                "lengths": [float(v) for v in g.lengths] if g else None, "nugget": g.nugget if g else None,
                "box": [[float(a), float(b)] for a, b in zip(self.lo, self.hi)]}


def fit_on_emulator(em: CurveEmulator, j: int, xj: float, x0_free: np.ndarray, max_nfev: int = 200) -> Fit:
    """The refit of the parameters other than ``j`` with parameter ``j`` held at ``xj`` (fit coordinates),
    on the emulator: robust least squares (the spec's [fit] loss) on the residuals whitened with the noise
    model's covariance plus the emulator's (:class:`~.noise.ScaledCovariance`), with √(log-determinant) that
    covariance adds as one more residual, as in the refits of whole models (emulated.py): the optimum of
    −2 ln L under the emulator's predictive distribution.  Without the log-determinant the whitened residuals
    alone shrink where the emulator knows least, and the others drift there (to a bound, beyond the
    design) instead of to their conditional optimum.  The returned Fit's ``r`` and ``J`` are the whitened
    residuals and their Jacobian, its ``cost`` ½ r·r (the profile's Δχ² leaves the log-determinant out,
    profile.py), ``x_full`` the point in all the emulator's parameters and ``logdet`` the log-determinant the
    emulator's covariance adds there."""
    problem, fo = em.problem, em.problem.spec.fit
    free = [i for i in range(len(em.params)) if i != j]
    lb = np.array([em.params[i].x_bounds[0] for i in free])
    ub = np.array([em.params[i].x_bounds[1] for i in free])

    def full(xf):
        return np.insert(np.asarray(xf, float), j, xj)

    def resid(xf):
        mean, s = em.predict(full(xf))
        r, logdet = em.whitener().standardize(problem.data_at(em.params, full(xf))[em.mask] - mean, s)
        return np.append(r, math.sqrt(max(logdet, 0.0)))

    if free:
        res = least_squares(resid, np.clip(np.asarray(x0_free, float), lb, ub), bounds=(lb, ub), loss=fo.loss,
                            f_scale=fo.f_scale, max_nfev=max_nfev, x_scale=ub - lb, method="trf")
        xf, nfev, J = res.x, res.nfev, res.jac[:-1]
    else:
        xf, nfev, J = np.zeros(0), 1, np.zeros((int(em.mask.sum()), 0))
    mean, s = em.predict(full(xf))
    r, logdet = em.whitener().standardize(problem.data_at(em.params, full(xf))[em.mask] - mean, s)
    f = Fit(tuple(em.params[i] for i in free), xf, r, J, 0.5 * float(r @ r), nfev)
    f.logdet = logdet
    f.x_full = full(xf)
    return f


def wald_box(problem, fit: Fit, ids, reach: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) of ``reach`` Wald sd about ``fit`` in each of its parameters (fit coordinates; its
    whole range where the sd is undetermined, at least 1e-3 of it), clipped to the bounds; the sd under the
    profile's likelihood weights ("weighted": the series weights n_eff/n of the fit's residuals)."""
    x = np.asarray(fit.x, float)
    w = (stats.series_weights(fit.r, problem.series[problem.mask(ids)]) if problem.spec.profile.likelihood == "weighted"
         else np.ones(fit.r.size))
    lo, hi = [], []
    for i, p in enumerate(fit.params):
        a, b = p.x_bounds
        sd = stats.wald_interval(fit.J, fit.r, w, i, float(x[i]))[2]
        half = reach * sd if math.isfinite(sd) else (b - a)
        half = max(half, 1e-3 * (b - a))
        lo.append(max(a, x[i] - half))
        hi.append(min(b, x[i] + half))
    return np.array(lo), np.array(hi)


def fill_design(em: CurveEmulator, n: int, what: str, remedy: str = '[profile] emulator = "none"') -> None:
    """More space-filling points of the emulator's box while runs that failed left too few for the process
    (twice at most); a clear error naming ``what`` and the setting that does without it (``remedy``) when it
    still has too few."""
    for k in range(1, 3):
        if em.gp is not None:
            return
        em.add(list(space_filling(n, em.lo, em.hi, em.problem.spec.fit.seed + k)))
    if em.gp is None:
        raise RuntimeError(f"{what}: {em.failed} of its design runs failed, too few points left for "
                           f"{len(em.params)} parameters; set {remedy}")


def design_points(x: np.ndarray, done: list, lo: np.ndarray, hi: np.ndarray, n: int, seed: int) -> list:
    """The emulator's first design: the fit ``x`` and its d nearest neighbours among the points already run
    (``done``: the refits' and the refresh's, free) between 0.1 and 1 times the gap below (the fit's
    finite-difference steps among them: runs close together show the model's jitter, which the process's
    lengths and nugget must account for; closer ones, a converging optimizer's, show nothing), then the
    other points already run and space-filling points of the box [lo, hi], each kept only at least
    0.5 n^(−1/d) of the box (unit coordinates) from those chosen, the farthest first, until there are ``n``
    points; the runs already made count toward ``n`` only inside the box, and at most 2 n are taken."""
    d = len(x)
    gap = 0.5 * n ** (-1.0 / d)

    def unit(v):
        return (np.asarray(v, float) - lo) / (hi - lo)

    near = sorted((c for c in done if 0.1 * gap <= np.linalg.norm(unit(c) - unit(x)) < gap),
                  key=lambda c: np.linalg.norm(unit(c) - unit(x)))
    chosen = [np.asarray(x, float)] + [np.asarray(c, float) for c in near[:d]]

    def take(cands: list, limit: int) -> None:
        cands = list(cands)
        while cands and len(chosen) < limit:
            dist = [min(np.linalg.norm(unit(c) - unit(q)) for q in chosen) for c in cands]
            i = int(np.argmax(dist))
            if dist[i] < gap:
                return
            chosen.append(np.asarray(cands.pop(i), float))

    inside = [c for c in done if np.all(unit(c) >= -0.25) and np.all(unit(c) <= 1.25)]
    take(inside, 2 * n)
    take(list(space_filling(4 * n, lo, hi, seed)), max(n, len(chosen)))
    return chosen

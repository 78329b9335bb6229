"""Probabilistic classifier of a regime label over a campaign's axes (numpy + scipy only).

Multinomial logistic regression on a smooth basis with a Gaussian (L2) prior, fitted by
``scipy.optimize`` (maximum a posteriori), with a Laplace approximation of the posterior
for the predictive uncertainty:

    f_k(x) = w_k . phi(x),    P(label = k | x) = softmax_k f(x),    w ~ N(0, prior_sd^2 I)

``phi`` are products of Legendre polynomials of total degree <= ``degree`` in the unit
coordinates u in [-1, 1] of each axis (log10 of the value on a log axis). The boundary
between labels a and b is the zero line of g_ab = f_a - f_b where a and b are the two most
probable labels. Its location uncertainty at a point x is the Laplace standard deviation of
g_ab divided by the length of its gradient, measured in *tolerance units*: each axis is
divided by its tolerance (axis units, decades on a log axis), so 1 means one tolerance.

The prior sd of the slopes sets the sharpest transition between regimes the model expects. It
is a hyperparameter weighed by its Laplace evidence over a factor-2 grid (``prior_span``), and
the location uncertainty averages over that posterior: a fuzzy transition (labels mixed over a
width) keeps the soft members probable and widens the band, where a fixed sharp prior would
read a few mixed labels as a sharp boundary with a narrow band.

Units: the axes' own (model units, mm, s, kPa; decades on log axes); probabilities and
uncertainty ratios are dimensionless.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.optimize import minimize
from scipy.special import logsumexp, softmax
from scipy.stats import norm

__all__ = ["AxisScale", "RegimeModel", "fit_regime_model", "boundary_points", "boundary_uncertainty",
           "boundary_band", "project_to_boundary", "legendre_basis", "unit_grid"]


@dataclass(frozen=True)
class AxisScale:
    """One axis of the classifier: bounds ``lo`` < ``hi`` (axis units, > 0 on a log axis),
    ``log`` spacing, and the ``tolerance`` on the boundary location (axis units, decades on log)."""

    name: str
    lo: float
    hi: float
    log: bool
    tolerance: float

    def to_t(self, v: Any) -> np.ndarray:
        """Axis value -> transformed coordinate (log10 on a log axis)."""
        v = np.asarray(v, float)
        return np.log10(v) if self.log else v

    def from_t(self, t: Any) -> np.ndarray:
        t = np.asarray(t, float)
        return 10.0**t if self.log else t

    @property
    def t_lo(self) -> float:
        return float(self.to_t(self.lo))

    @property
    def t_hi(self) -> float:
        return float(self.to_t(self.hi))

    def to_u(self, v: Any) -> np.ndarray:
        """Axis value -> unit coordinate in [-1, 1]."""
        return 2.0 * (self.to_t(v) - self.t_lo) / (self.t_hi - self.t_lo) - 1.0

    def from_u(self, u: Any) -> np.ndarray:
        return self.from_t(self.t_lo + 0.5 * (np.asarray(u, float) + 1.0) * (self.t_hi - self.t_lo))

    @property
    def tol_per_u(self) -> float:
        """Tolerance units per unit of u (the span of u is 2)."""
        return 0.5 * (self.t_hi - self.t_lo) / self.tolerance


def _exponents(dim: int, degree: int) -> list[tuple[int, ...]]:
    return [e for e in itertools.product(range(degree + 1), repeat=dim) if sum(e) <= degree]


def legendre_basis(u: np.ndarray, degree: int, grad: bool = False):
    """Products of Legendre polynomials P_e1(u_1) ... P_ed(u_d), total degree <= ``degree``.

    u (n, d) in [-1, 1]. Returns Phi (n, p), and with ``grad`` also dPhi/du (n, p, d).
    """
    u = np.atleast_2d(np.asarray(u, float))
    n, d = u.shape
    P = np.empty((degree + 1, n, d))
    dP = np.zeros_like(P)
    P[0], P[min(1, degree)] = 1.0, u
    if degree >= 1:
        dP[1] = 1.0
    for k in range(1, degree):  # Bonnet: (k+1) P_{k+1} = (2k+1) u P_k - k P_{k-1}
        P[k + 1] = ((2 * k + 1) * u * P[k] - k * P[k - 1]) / (k + 1)
        dP[k + 1] = ((2 * k + 1) * (P[k] + u * dP[k]) - k * dP[k - 1]) / (k + 1)
    exps = _exponents(d, degree)
    cols = np.stack([np.prod([P[e[j], :, j] for j in range(d)], axis=0) for e in exps], axis=1)
    if not grad:
        return cols
    G = np.empty((n, len(exps), d))
    for i, e in enumerate(exps):
        for j in range(d):
            G[:, i, j] = np.prod([dP[e[m], :, m] if m == j else P[e[m], :, m] for m in range(d)], axis=0)
    return cols, G


def _pair_moments(W: np.ndarray, cov: np.ndarray, Phi: np.ndarray, G: np.ndarray, a: np.ndarray, b: np.ndarray,
                  scale: np.ndarray):
    """For one coefficient set: g = f_a - f_b at each point (pair a, b given per point), its Laplace sd, and
    the length of its gradient per tolerance unit."""
    K, p = W.shape
    dw = W[a] - W[b]                                                   # (n, p)
    g = np.einsum("np,np->n", dw, Phi)
    grad_t = np.einsum("np,npd->nd", dw, G) / scale                    # dg / d(tolerance unit)
    C = cov.reshape(K, p, K, p)
    var = np.empty(len(Phi))
    for ka, kb in {(int(i), int(j)) for i, j in zip(a, b)}:
        m = (a == ka) & (b == kb)
        S = C[ka, :, ka] - C[ka, :, kb] - C[kb, :, ka] + C[kb, :, kb]
        var[m] = np.einsum("np,pq,nq->n", Phi[m], S, Phi[m])
    return g, np.sqrt(np.maximum(var, 0.0)), np.maximum(np.linalg.norm(grad_t, axis=1), 1e-12)


@dataclass(frozen=True)
class RegimeModel:
    """A fitted classifier: ``labels`` (K,), coefficients ``W`` (K, p), Laplace covariance ``cov``
    (K p, K p) of vec(W) (row-major), the axes, the basis ``degree``, ``confidence`` of the band,
    ``prior_sd`` the prior scale sigma of the degree-1 coefficients in ``W`` (unit coordinates), and
    ``mixture``: the posterior over sigma, ((weight, W_k, cov_k, sigma_k), ...) with weights summing to
    1 (``W``, ``cov`` are its most probable member; see ``fit_regime_model``)."""

    labels: tuple
    W: np.ndarray
    cov: np.ndarray
    axes: tuple[AxisScale, ...]
    degree: int
    confidence: float = 0.95
    prior_sd: float = math.nan
    mixture: tuple = ()

    @property
    def z(self) -> float:
        """Two-sided normal quantile of the band's confidence."""
        return float(norm.ppf(0.5 + 0.5 * self.confidence))

    def unit(self, X: Any) -> np.ndarray:
        """Axis values (n, d) -> unit coordinates (n, d)."""
        X = np.atleast_2d(np.asarray(X, float))
        return np.stack([a.to_u(X[:, j]) for j, a in enumerate(self.axes)], axis=1)

    def latent(self, U: np.ndarray) -> np.ndarray:
        """f (n, K) at unit coordinates U."""
        return legendre_basis(U, self.degree) @ self.W.T

    def proba(self, X: Any) -> np.ndarray:
        """P(label | x) (n, K) at axis values X (n, d), MAP plug-in."""
        return softmax(self.latent(self.unit(X)), axis=1)

    def pair_stats(self, U: np.ndarray) -> dict[str, np.ndarray]:
        """At unit coordinates U: the two most probable labels (a, b), g = f_a - f_b >= 0 and its Laplace
        sd, ``dist`` = g / |grad g| (distance to the boundary, linearized) and ``sigma_loc``, the
        boundary-location sd, all lengths in tolerance units.

        sigma_loc is the root-mean-square deviation of the boundary of the pair (a, b) from this model's,
        under the posterior over the prior scale sigma (``mixture``): member k, whose boundary lies at
        signed distance dist_k - dist from this one with Laplace sd sd_k / |grad g_k|, contributes
        weight_k ((sd_k / |grad g_k|)^2 + (dist_k - dist)^2). With one member it is sd / |grad g|."""
        Phi, G = legendre_basis(U, self.degree, grad=True)
        F = Phi @ self.W.T
        order = np.argsort(-F, axis=1)
        a, b = order[:, 0], order[:, 1]
        scale = np.array([ax.tol_per_u for ax in self.axes])           # d(tol units)/du
        g, sd, gn = _pair_moments(self.W, self.cov, Phi, G, a, b, scale)
        members = self.mixture or ((1.0, self.W, self.cov, self.prior_sd),)
        msd = np.zeros(len(U))
        for weight, Wk, Ck, _ in members:
            gk, sdk, gnk = _pair_moments(Wk, Ck, Phi, G, a, b, scale)
            msd += weight * ((sdk / gnk) ** 2 + (gk / gnk - g / gn) ** 2)
        return {"a": a, "b": b, "g": g, "sd": sd, "sigma_loc": np.sqrt(msd), "dist": g / gn}


def project_to_boundary(model: RegimeModel, U: np.ndarray, steps: int = 3) -> np.ndarray:
    """Newton steps from each point U (n, d) towards the zero line of g = f_a - f_b of its two most
    probable labels (a, b fixed at the start), clipped to [-1, 1]: the nearest boundary point."""
    U = np.atleast_2d(np.asarray(U, float)).copy()
    F = legendre_basis(U, model.degree) @ model.W.T
    order = np.argsort(-F, axis=1)
    dw = model.W[order[:, 0]] - model.W[order[:, 1]]
    for _ in range(steps):
        Phi, G = legendre_basis(U, model.degree, grad=True)
        g = np.einsum("np,np->n", dw, Phi)
        grad = np.einsum("np,npd->nd", dw, G)
        U = np.clip(U - (g / np.maximum(np.einsum("nd,nd->n", grad, grad), 1e-300))[:, None] * grad, -1.0, 1.0)
    return U


def _prior_precision(axes_dim: int, degree: int, prior_sd: float, smoothness: float, intercept_sd: float) -> np.ndarray:
    """Prior precision of one label's coefficients: sd ``prior_sd * smoothness**(k - 1)`` for a term of
    total degree k >= 1, ``intercept_sd`` for the intercept."""
    tdeg = np.array([sum(e) for e in _exponents(axes_dim, degree)], float)
    sd = np.where(tdeg == 0, intercept_sd, prior_sd * smoothness ** np.maximum(tdeg - 1, 0))
    return 1.0 / sd**2


def _map_fit(Phi: np.ndarray, Y: np.ndarray, prec: np.ndarray, w0: np.ndarray):
    """MAP coefficients (K p,), Hessian of the negative log posterior there, and its value (without the
    prior's normalization), for the multinomial logistic model with independent normal coefficients of
    precisions ``prec`` (K p,)."""
    n, p = Phi.shape
    K = Y.shape[1]

    def nlp(w):
        F = Phi @ w.reshape(K, p).T
        return float(np.sum(logsumexp(F, axis=1)) - np.sum(F * Y) + 0.5 * np.sum(prec * w * w))

    def grad(w):
        P = softmax(Phi @ w.reshape(K, p).T, axis=1)
        return ((P - Y).T @ Phi).ravel() + prec * w

    outer = Phi[:, :, None] * Phi[:, None, :]                          # (n, p, p)

    def hess(w):
        P = softmax(Phi @ w.reshape(K, p).T, axis=1)
        Wkl = np.einsum("nk,kl->nkl", P, np.eye(K)) - P[:, :, None] * P[:, None, :]
        H = np.tensordot(Wkl, outer, axes=(0, 0)).transpose(0, 2, 1, 3)   # (k, p, l, q)
        return H.reshape(K * p, K * p) + np.diag(prec)

    res = minimize(nlp, w0, jac=grad, hess=hess, method="trust-exact", options={"gtol": 1e-8, "maxiter": 300})
    return res.x, hess(res.x), float(res.fun)


def _log_evidence(H: np.ndarray, prec: np.ndarray, nlp_min: float) -> float:
    """Laplace log marginal likelihood: -nlp(w*) + (1/2) log det(prior precision) - (1/2) log det H."""
    return -nlp_min + 0.5 * float(np.sum(np.log(prec))) - 0.5 * float(np.linalg.slogdet(H)[1])


def fit_regime_model(X: Any, y: Sequence, axes: Sequence[AxisScale], *, degree: int = 3,
                     prior_sd: float = 10.0, smoothness: float = 0.3, confidence: float = 0.95,
                     labels: Sequence | None = None, prior_span: float = 1.0) -> RegimeModel:
    """MAP fit and Laplace covariance of the multinomial logistic model.

    X (n, d) axis values (axis units); y (n,) labels; ``labels`` the label set (default: the
    sorted distinct y; at least two; labels outside it are ignored). Prior: independent normal
    coefficients, sd ``sigma`` for the degree-1 terms, ``sigma * smoothness**(k - 1)`` for a
    term of total degree k (a smoothness prior: without it a sharp boundary bends the cubic terms
    into spurious islands), 10 ``prior_sd`` for the intercept.

    ``sigma`` is the scale of the latent slopes, i.e. the inverse of the transition width between
    regimes (in unit coordinates), a hyperparameter with a flat prior on log sigma over the grid
    ``prior_sd / 2**k`` >= ``prior_sd / prior_span`` (``prior_span`` = 1: sigma = ``prior_sd``). Each
    sigma gets its MAP fit, Laplace covariance and Laplace evidence (marginal likelihood of the labels);
    the evidences give the posterior over sigma (``RegimeModel.mixture``). The returned ``W``, ``cov``
    are those of the most probable sigma (type-II maximum likelihood); the boundary-location sd
    (``RegimeModel.pair_stats``) averages over the posterior. Labels that change sharply favour the
    largest sigma, the sharpest transition the prior admits; labels mixed across a fuzzy transition
    favour the sigma of its width; a few labels that cannot tell the two apart keep both, and the band
    is then as wide as the softer transition allows.
    """
    X = np.atleast_2d(np.asarray(X, float))
    y = np.asarray([str(v) for v in y], dtype=object)
    labs = tuple(str(v) for v in (labels if labels is not None else sorted(set(y))))
    if len(labs) < 2:
        raise ValueError(f"labels={labs!r}: at least two labels are needed to locate a boundary")
    if not prior_span >= 1.0:
        raise ValueError(f"prior_span={prior_span!r}: must be >= 1 (ratio of the largest to the smallest prior sd)")
    idx = {lab: i for i, lab in enumerate(labs)}
    keep = np.array([v in idx for v in y], bool)
    X, y = X[keep], y[keep]
    axes = tuple(axes)
    U = np.stack([a.to_u(X[:, j]) for j, a in enumerate(axes)], axis=1) if len(X) else np.zeros((0, len(axes)))
    Phi = legendre_basis(U, degree)
    K = len(labs)
    Y = np.zeros((len(U), K))
    Y[np.arange(len(U)), [idx[v] for v in y]] = 1.0
    fits, w = [], np.zeros(K * Phi.shape[1])
    for k in range(int(math.floor(math.log2(prior_span) + 1e-9)) + 1):
        sigma = prior_sd / 2.0**k
        prec = np.tile(_prior_precision(len(axes), degree, sigma, smoothness, 10.0 * prior_sd), K)
        w, H, nlp_min = _map_fit(Phi, Y, prec, w)
        cov = np.linalg.inv(H)
        fits.append((_log_evidence(H, prec, nlp_min), w.reshape(K, -1), 0.5 * (cov + cov.T), sigma))
    ev = np.array([f[0] for f in fits])
    weights = np.exp(ev - ev.max()) / np.sum(np.exp(ev - ev.max()))
    mixture = tuple((float(q), Wk, Ck, sk) for q, (_, Wk, Ck, sk) in zip(weights, fits))
    _, W, cov, sigma = fits[int(np.argmax(ev))]
    return RegimeModel(labs, W, cov, axes, degree, confidence, sigma, mixture)


def unit_grid(dim: int, n: int) -> np.ndarray:
    """A regular grid of n points per axis over [-1, 1]^dim, (n^dim, dim)."""
    g = np.linspace(-1.0, 1.0, n)
    return np.stack([m.ravel() for m in np.meshgrid(*([g] * dim), indexing="ij")], axis=1)


def boundary_points(model: RegimeModel, n: int = 64) -> np.ndarray:
    """Unit coordinates of the grid points (n per axis) that have a neighbour of another MAP label:
    the estimated boundaries, one cell wide. (m, d); empty when one label covers the domain."""
    d = len(model.axes)
    U = unit_grid(d, n)
    lab = np.argmax(model.latent(U), axis=1).reshape((n,) * d)
    edge = np.zeros(lab.shape, bool)
    for ax in range(d):
        diff = np.diff(lab, axis=ax) != 0
        lo = [slice(None)] * d
        hi = [slice(None)] * d
        lo[ax], hi[ax] = slice(0, n - 1), slice(1, n)
        edge[tuple(lo)] |= diff
        edge[tuple(hi)] |= diff
    return U[edge.ravel()]


_GRID_PER_AXIS = {1: 512, 2: 64, 3: 20}   # evaluation grid of the boundaries, points per axis


def boundary_band(model: RegimeModel, n: int | None = None) -> dict[str, Any]:
    """The estimated boundaries and their uncertainty: grid points next to a label change (n per axis),
    projected onto the zero line of their pair; ``U`` (m, d) unit coordinates, ``half`` (m,) the band's
    half-width z sigma_loc (tolerance units), ``pair`` (m,) the two labels "a | b" (sorted)."""
    B = boundary_points(model, n or _GRID_PER_AXIS[len(model.axes)])
    if len(B) == 0:
        return {"U": B, "half": np.empty(0), "pair": np.empty(0, dtype=object)}
    P = project_to_boundary(model, B)
    st = model.pair_stats(P)
    pair = np.array([" | ".join(sorted((model.labels[a], model.labels[b]))) for a, b in zip(st["a"], st["b"])],
                    dtype=object)
    return {"U": P, "half": model.z * st["sigma_loc"], "pair": pair}


def boundary_uncertainty(model: RegimeModel, n: int | None = None) -> dict[str, Any]:
    """Largest z * sigma_loc over the estimated boundaries (tolerance units: <= 1 means the band of
    the model's confidence is within the tolerance everywhere), overall and per label pair."""
    band = boundary_band(model, n)
    if len(band["U"]) == 0:
        return {"max": math.inf, "pairs": {}, "n_points": 0}
    pairs: dict[str, float] = {}
    for key, v in zip(band["pair"], band["half"]):
        pairs[key] = max(pairs.get(key, 0.0), float(v))
    return {"max": float(band["half"].max()), "pairs": pairs, "n_points": int(len(band["U"]))}

"""Phase diagrams of the paper: Ca* vs cement ratio (Sec. 3.6) and N_f vs N_b (Sec. 3.8).

Matplotlib is used through the object API with the Agg canvas (no pyplot, no global
backend change). Each plot is written as PNG plus the vector formats requested
(default SVG). Inputs are pandas DataFrames with one row per run, so that the campaign
framework and the discrepancy workflow can reuse these functions.

Required columns
----------------
``plot_ca_star_vs_cement``: ``cement`` (C, %), ``Ca_star`` (-), ``fracturing`` (bool).
    Optional: ``source`` (e.g. "simulation" / "experiment"; one colour per source).
``plot_nf_vs_nb``: ``N_b`` (-), ``N_f`` (-), ``regime`` (one of sweep.regimes.classify.REGIMES).
    Optional: ``run_dir`` (run folder, for thumbnails).
Rows with missing / non-positive numbers or an unknown regime are dropped with a
count reported in the returned dict (``n_dropped``).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable, Mapping, NamedTuple, Sequence

import numpy as np

from .classify import REGIMES
from .numbers import logistic_fit

__all__ = [
    "REGIME_STYLE",
    "ExponentialSeparatrix",
    "fit_exponential_separatrix",
    "SeparatrixInterval",
    "separatrix_profile_interval",
    "regime_map",
    "plot_ca_star_vs_cement",
    "plot_nf_vs_nb",
    "plot_boundary_sampling",
    "regime_style",
    "separatrix_p_value",
    "SEPARATRIX_P_MAX",
]

BLUE = "#1f77b4"
ORANGE = "#ff7f0e"
# marker, colour, label, shading colour (paper's symbols, Sec. 3.8)
REGIME_STYLE: dict[str, dict[str, Any]] = {
    "uniform_invasion": dict(marker="o", color=BLUE, label="uniform invasion", shade="#c6dbef"),
    "viscous_fingering": dict(marker="*", color=BLUE, label="viscous fingering", shade="#9ecae1"),
    "invasive_fracturing": dict(marker="^", color=ORANGE, label="invasive fracturing", shade="#fdd0a2"),
    "non_invasive_fracturing": dict(marker="s", color=ORANGE, label="non-invasive fracturing",
                                    shade="#fdae6b"),
    "fracturing_fingering": dict(marker="x", color=ORANGE, label="fracturing/fingering",
                                 shade="#e7cb94"),
}
# the two labels of the Ca*-C diagram (the ``fracturing`` column: True/False) in the same palette
_TWO_LABELS = {
    "fracturing": dict(marker="^", color=ORANGE, label="fracturing", shade="#fdd0a2"),
    "porous_invasion": dict(marker="o", color=BLUE, label="porous invasion (no fracture)", shade="#c6dbef"),
}
_FAILED = dict(marker="X", color="0.45", label="failed (no label)", shade="#dddddd")


def regime_style(label: Any) -> dict[str, Any]:
    """marker, color, label (words, never True/False) and shade of a regime name or a ``fracturing`` value:
    the one palette of every figure (blue: invasion without fracture, orange: fracturing; grey: no label)."""
    if label is None or (isinstance(label, float) and label != label):
        return _FAILED
    if isinstance(label, (bool, np.bool_)) or str(label) in ("True", "False"):
        return _TWO_LABELS["fracturing" if str(label) == "True" else "porous_invasion"]
    name = str(label)
    if name in REGIME_STYLE:
        return REGIME_STYLE[name]
    if name in _TWO_LABELS:
        return _TWO_LABELS[name]
    return dict(marker="d", color="0.3", label=name.replace("_", " "), shade="#eeeeee")


# fitted separatrices are drawn only when they explain the labels better than a constant fracturing rate at
# this level (likelihood-ratio test, 2 degrees of freedom: the C and ln Ca* slopes)
SEPARATRIX_P_MAX = 0.05


def separatrix_p_value(C: Any, ca_star: Any, fracturing: Any, ridge: float = 1e-3) -> float:
    """p-value of the likelihood-ratio test of the logistic fit logit P = b0 + b1 C + b2 ln Ca* (the
    separatrix's model) against a constant fracturing rate: chi-squared with 2 degrees of freedom."""
    from scipy.stats import chi2

    fr = np.asarray(fracturing).astype(bool).ravel()
    X = np.c_[np.asarray(C, float).ravel(), np.log(np.asarray(ca_star, float).ravel())]
    fit = logistic_fit(X, fr, ridge=ridge)
    z = fit.beta[0] + X @ np.asarray(fit.beta[1:], float)
    ll_fit = float(np.sum(fr * -np.logaddexp(0.0, -z) + (~fr) * -np.logaddexp(0.0, z)))
    q = fr.mean()
    ll_null = float(fr.sum() * np.log(q) + (~fr).sum() * np.log(1.0 - q))
    return float(chi2.sf(max(0.0, 2.0 * (ll_fit - ll_null)), 2))


# --------------------------------------------------------------------------- separatrix
class ExponentialSeparatrix(NamedTuple):
    """Ca*_c(C) = A exp(B C); cov: 2x2 covariance of (A, B) (delta method).

    Also: ``sigma_A``, ``sigma_B``, ``cov_lnA_B`` (covariance of (ln A, B), in which the
    fit is close to Gaussian), ``separable`` (labels perfectly separated: then cov
    reflects the ridge penalty, not a sampling uncertainty).
    """

    A: float
    B: float
    cov: np.ndarray
    cov_lnA_B: np.ndarray | None = None
    separable: bool = False

    @property
    def sigma_A(self) -> float:
        return float(math.sqrt(max(self.cov[0, 0], 0.0)))

    @property
    def sigma_B(self) -> float:
        return float(math.sqrt(max(self.cov[1, 1], 0.0)))

    def __call__(self, C: Any) -> Any:
        """Ca*_c at cement ratio C (%)."""
        return self.A * np.exp(self.B * np.asarray(C, dtype=float))


def fit_exponential_separatrix(C: Any, ca_star: Any, fracturing: Any,
                               ridge: float = 1e-3) -> ExponentialSeparatrix:
    """Fit Ca*_c = A exp(B C) separating porous invasion from fracturing.

    Logistic regression of ``fracturing`` on (C, ln Ca*) (scipy.optimize, no sklearn):
    logit P = b0 + b1 C + b2 ln Ca*; the 50 % boundary is ln Ca* = -(b0 + b1 C)/b2, so
    A = exp(-b0/b2), B = -b1/b2, with covariance by the delta method from the inverse
    Hessian. C in %, Ca* dimensionless (> 0), fracturing bools. Needs both outcomes and
    fracturing increasing with Ca* (b2 > 0).
    """
    Ca = np.asarray(C, dtype=float).ravel()
    cs = np.asarray(ca_star, dtype=float).ravel()
    fr = np.asarray(fracturing).astype(bool).ravel()
    if not (Ca.size == cs.size == fr.size) or Ca.size < 3:
        raise ValueError(f"C, ca_star, fracturing lengths=({Ca.size}, {cs.size}, {fr.size}): "
                         "must be equal and >= 3")
    if not np.all(np.isfinite(Ca)):
        raise ValueError("C: contains non-finite values; all must be finite (%)")
    if not np.all(np.isfinite(cs)) or np.any(cs <= 0):
        raise ValueError("ca_star: must be finite and > 0")
    fit = logistic_fit(np.c_[Ca, np.log(cs)], fr, ridge=ridge)
    b0, b1, b2 = fit.beta
    if b2 <= 0:
        raise ValueError("fracturing: does not increase with Ca* (fitted coefficient <= 0); "
                         "no separatrix Ca*_c(C)")
    lnA, B = -b0 / b2, -b1 / b2
    J = np.array([[-1.0 / b2, 0.0, b0 / b2**2],
                  [0.0, -1.0 / b2, b1 / b2**2]])
    cov_lnAB = J @ fit.cov @ J.T
    A = float(np.exp(lnA))
    D = np.diag([A, 1.0])
    return ExponentialSeparatrix(A=A, B=float(B), cov=D @ cov_lnAB @ D, cov_lnA_B=cov_lnAB,
                                 separable=fit.separable)


class SeparatrixInterval(NamedTuple):
    """Profile-likelihood intervals of the separatrix Ca*_c = A exp(B C) at ``level``.

    A (-) and B (1/%) are the penalized maximum-likelihood values; ``A_interval``, ``B_interval`` their
    intervals (each parameter profiled over the other and the transition's sharpness); ``sharpness`` the
    fitted logistic slope s per unit of ln Ca* (-); ``separable``: every label lies on its side of the
    fitted separatrix (the data alone then bound s from below only; the Jeffreys penalty keeps it finite).
    """

    A: float
    B: float
    A_interval: tuple[float, float]
    B_interval: tuple[float, float]
    level: float
    separable: bool
    sharpness: float = math.nan


def _sep_objective(phi, M, X, y):
    """Negative Jeffreys-penalized log-likelihood of the logistic model z = X theta at theta = M phi, and
    its gradient in phi. Penalty: 0.5 log det of the full model's Fisher information X' W X (Firth 1993);
    its gradient gives the modified score X' (y - p + h (1/2 - p)), h the hat values."""
    theta = M @ phi
    z = X @ theta
    p = 0.5 * (1.0 + np.tanh(0.5 * z))
    w = np.maximum(p * (1.0 - p), 1e-300)
    info = (X * w[:, None]).T @ X
    sign, logdet = np.linalg.slogdet(info)
    if sign <= 0:
        return math.inf, np.zeros_like(phi)
    h = w * np.einsum("ni,ij,nj->n", X, np.linalg.inv(info), X)
    nll = float(np.sum(np.logaddexp(0.0, z) - y * z)) - 0.5 * logdet
    return nll, -(M.T @ (X.T @ (y - p + h * (0.5 - p))))


def _sep_fisher(phi, M, X, y):
    """Fisher information of the likelihood part in phi: the trust region's model Hessian."""
    z = X @ (M @ phi)
    p = 0.5 * (1.0 + np.tanh(0.5 * z))
    XM = X @ M
    return (XM * (p * (1.0 - p))[:, None]).T @ XM


def _sep_min(X, y, M):
    """Minimum negative penalized log-likelihood over theta = M phi, and theta at the minimum (Newton trust
    region on the Fisher information, from a unit sharpness). The Jeffreys penalty keeps the minimum finite
    on separable labels."""
    from scipy.optimize import minimize

    phi0 = np.linalg.lstsq(M, np.r_[1.0, np.zeros(X.shape[1] - 1)], rcond=None)[0]
    res = minimize(_sep_objective, phi0, args=(M, X, y), jac=True, hess=_sep_fisher, method="trust-exact",
                   options={"gtol": 1e-8, "maxiter": 500})
    return float(res.fun), M @ res.x


def _profile_bounds(rise, v0: float, step: float) -> tuple[float, float]:
    """Where rise(v) (< 0 at v0) crosses 0 on each side: doubling steps, then Brent."""
    from scipy.optimize import brentq

    out = []
    for sgn in (-1.0, 1.0):
        inner, d = v0, step
        while (r := rise(v0 + sgn * d)) < 0 and d < 1e3 * step:
            inner, d = v0 + sgn * d, 2.0 * d
        out.append(brentq(rise, inner, v0 + sgn * d, xtol=0.01 * step) if r >= 0 else v0 + sgn * d)
    return min(out), max(out)


def separatrix_profile_interval(C: Any, ca_star: Any, fracturing: Any, level: float = 0.95) -> SeparatrixInterval:
    """Fit Ca*_c = A exp(B C) with profile-likelihood intervals of A and B (scipy only).

    Model: P(fracturing) = expit(s (ln Ca* - ln A - B C)), s > 0 the transition's sharpness per unit of
    ln Ca*; linear in theta = (s, s B, s ln A). The likelihood carries Jeffreys' prior (Firth's penalty
    0.5 log det I(theta)), the reference prior of the model, with no scale to choose: on labels that a
    separatrix separates, the unpenalized likelihood grows without bound as s grows and its profile
    shrinks to the separating separatrices, whatever the true transition width; the penalty keeps s
    finite and the profile honest (Heinze and Schemper 2002: profile penalized likelihood intervals).
    ln A fixed (theta_3 = v theta_1) or B fixed (theta_2 = v theta_1) is a linear constraint on theta,
    so each profile point is a fit in a plane of theta. The interval is where twice the penalized
    profile's rise stays below the chi-square(1) quantile of ``level``. C in %, Ca* > 0 (-),
    fracturing bools (both outcomes needed).
    """
    from scipy.stats import chi2

    Cc = np.asarray(C, float).ravel()
    L = np.log(np.asarray(ca_star, float).ravel())
    y = np.asarray(fracturing).astype(bool).astype(float).ravel()
    if not (Cc.size == L.size == y.size) or Cc.size < 3 or y.min() == y.max():
        raise ValueError("C, ca_star, fracturing: need equal lengths >= 3 and both outcomes")
    if not 0 < level < 1:
        raise ValueError(f"level={level!r}: must be in (0, 1)")
    X = np.c_[L, -Cc, -np.ones_like(L)]
    full, th = _sep_min(X, y, np.eye(3))
    if not th[0] > 0:
        raise ValueError("fracturing: does not increase with Ca* (fitted sharpness <= 0); no separatrix Ca*_c(C)")
    B_hat, lnA_hat = th[1] / th[0], th[2] / th[0]
    thr = chi2.ppf(level, 1) / 2.0

    def rise_lnA(v):
        return _sep_min(X, y, np.array([[1.0, 0.0], [0.0, 1.0], [v, 0.0]]))[0] - full - thr

    def rise_B(v):
        return _sep_min(X, y, np.array([[1.0, 0.0], [v, 0.0], [0.0, 1.0]]))[0] - full - thr

    span_L, span_C = max(np.ptp(L), 1e-6), max(np.ptp(Cc), 1e-6)
    lo_a, hi_a = _profile_bounds(rise_lnA, lnA_hat, 0.02 * span_L)
    b_iv = _profile_bounds(rise_B, B_hat, 0.02 * span_L / span_C)
    separable = bool(np.all((X @ th > 0) == (y > 0.5)))
    return SeparatrixInterval(float(np.exp(lnA_hat)), float(B_hat), (float(np.exp(lo_a)), float(np.exp(hi_a))),
                              b_iv, level, separable, float(th[0]))


# --------------------------------------------------------------------------- helpers
def _require(df: Any, cols: Sequence[str], fn: str) -> None:
    import pandas as pd

    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"df={type(df).__name__}: {fn} needs a pandas DataFrame")
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise ValueError(f"df: missing column(s) {missing} required by {fn} "
                         f"(has {list(df.columns)})")


def _new_figure(size: tuple[float, float]):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=150)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, out_path: str | Path, formats: Iterable[str]) -> list[Path]:
    out = Path(out_path)
    stem = out.with_suffix("") if out.suffix.lower() in (".png", ".svg", ".pdf") else out
    stem.parent.mkdir(parents=True, exist_ok=True)
    fmts = ["png"] + [f for f in formats if f != "png"]
    written = []
    for f in fmts:
        if f not in ("png", "svg", "pdf"):
            raise ValueError(f"formats: {f!r} not allowed; use 'png', 'svg' or 'pdf'")
        p = stem.parent / f"{stem.name}.{f}"
        fig.savefig(p, format=f, bbox_inches="tight")
        written.append(p)
    return written


def _fmt_pm(v: float, s: float) -> str:
    if not math.isfinite(s) or s == 0:
        return f"{v:.3g}"
    return f"{v:.3g} ± {s:.2g}"


# --------------------------------------------------------------------------- Ca* vs C
def plot_ca_star_vs_cement(df: Any, out_path: str | Path, *, fit: bool = True,
                           formats: Sequence[str] = ("svg",), title: str | None = None,
                           ridge: float = 1e-3) -> dict[str, Any]:
    """Ca* vs cement ratio C (%) with the two regimes and the exponential separatrix.

    df columns: ``cement``, ``Ca_star``, ``fracturing`` (+ optional ``source``).
    Porous invasion: open circles; fracturing: filled triangles; one colour per source.
    With ``fit`` and both outcomes present, the separatrix Ca*_c = A exp(B C) is fitted
    (``fit_exponential_separatrix``) and drawn with A, B and their 1-sigma in the legend.
    Writes ``out_path`` as PNG plus ``formats``; returns {"paths", "fit", "n_dropped"}.
    """
    _require(df, ("cement", "Ca_star", "fracturing"), "plot_ca_star_vs_cement")
    C = df["cement"].to_numpy(dtype=float)
    cs = df["Ca_star"].to_numpy(dtype=float)
    fr = df["fracturing"].to_numpy()
    ok = np.isfinite(C) & np.isfinite(cs) & (cs > 0) & np.array([v in (True, False, 0, 1) for v in fr])
    n_drop = int((~ok).sum())
    C, cs, fr = C[ok], cs[ok], fr[ok].astype(bool)
    src = df["source"].astype(str).to_numpy()[ok] if "source" in df.columns else np.full(len(C), "simulation")

    fig = _new_figure((5.5, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    colours = [ORANGE, BLUE, "#2ca02c", "#d62728", "#9467bd"]
    one = len(set(src)) == 1
    for k, s in enumerate(sorted(set(src))):
        no, yes = regime_style(False), regime_style(True)
        col_no, col_yes = (no["color"], yes["color"]) if one else (colours[k % len(colours)],) * 2
        m = src == s
        ax.scatter(C[m & ~fr], cs[m & ~fr], marker=no["marker"], facecolors="none", edgecolors=col_no,
                   label=no["label"] if one else f"{s}: {no['label']}")
        ax.scatter(C[m & fr], cs[m & fr], marker=yes["marker"], color=col_yes,
                   label=yes["label"] if one else f"{s}: {yes['label']}")
    sep, no_fit = None, None
    if fit and fr.any() and (~fr).any() and len(C) >= 3:
        try:
            sep = fit_exponential_separatrix(C, cs, fr, ridge=ridge)
        except ValueError as exc:
            no_fit = str(exc)   # said on the figure: a missing line must not look like an omission
    elif fit:
        no_fit = "both regimes are needed to fit a separatrix"
    if sep is not None:
        no_fit = _unlocated_reason(sep, C, cs, fr)
        sep = None if no_fit else sep
    if no_fit:
        ax.text(0.5, -0.27, "no exponential separatrix: " + no_fit, transform=ax.transAxes, fontsize=6.5,
                va="top", ha="center", wrap=True)
    if sep is not None:
        cc = np.linspace(C.min(), C.max(), 200) if np.ptp(C) > 0 else np.array([C[0] - 0.5, C[0] + 0.5])
        note = " (separable)" if sep.separable else ""
        ax.plot(cc, sep(cc), "k-", lw=1.5,
                label=f"Ca*$_c$ = A exp(B C){note}\nA = {_fmt_pm(sep.A, sep.sigma_A)}, "
                      f"B = {_fmt_pm(sep.B, sep.sigma_B)}")
    ax.set_yscale("log")
    ax.set_xlabel("cement volume ratio C (%)")
    ax.set_ylabel("modified capillary number Ca*")
    if title:
        ax.set_title(title)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2,
              frameon=False)
    paths = _save(fig, out_path, formats)
    return {"paths": paths, "fit": sep, "no_fit_reason": no_fit, "n_dropped": n_drop}


def _unlocated_reason(sep, C, cs, fr) -> str | None:
    """Why the labels do not locate the separatrix Ca*_c(C) (None when they do); the line is then not drawn.

    Two cases: the line stays above or below every sampled Ca* over the sampled C (an extrapolation), or it
    separates no better than the base rate, i.e. the runs it puts on the wrong side (fracturing below it,
    porous invasion above) are at least as many as the minority regime's runs, so calling every run the
    majority regime would do as well and the line carries no information about where the regimes meet."""
    line = sep(np.linspace(C.min(), C.max(), 50))
    head = f"the fitted line (A = {sep.A:.3g}, B = {sep.B:.3g} /%)"
    if np.all(line < cs.min()) or np.all(line > cs.max()):
        return f"{head} lies outside the sampled Ca* range [{cs.min():.3g}, {cs.max():.3g}] over C: the labels do not locate it"
    wrong = int(np.sum((cs >= sep(C)) != fr))
    minority = int(min(fr.sum(), (~fr).sum()))
    if wrong >= minority:
        major = "fracturing" if fr.sum() > (~fr).sum() else "porous invasion"
        return (f"{head} puts {wrong} of {fr.size} runs on the wrong side, no fewer than calling every run "
                f"{major} ({minority}): the labels do not locate it")
    p = separatrix_p_value(C, cs, fr)
    if p >= SEPARATRIX_P_MAX:
        return (f"{head} is not significant: against a constant fracturing rate the likelihood-ratio test "
                f"gives p = {p:.2g} (>= {SEPARATRIX_P_MAX:g}); none found")
    return None


# --------------------------------------------------------------------------- N_f vs N_b
def regime_map(log_nb: Any, log_nf: Any, regimes: Sequence[str], grid_x: Any, grid_y: Any,
               k: int = 1) -> np.ndarray:
    """Regime of each grid point by k-nearest-neighbour vote in the (log10 N_b, log10 N_f) plane.

    log_nb, log_nf (n,) run coordinates (log10); regimes (n,) labels; grid_x, grid_y
    arrays of query coordinates (log10; same shape). Both axes are scaled by the spread
    of the runs so that one decade counts the same on each axis when their spans
    differ. Ties go to the nearest neighbour. Returns an array of labels, grid shape.
    """
    from scipy.spatial import cKDTree

    x = np.asarray(log_nb, float)
    y = np.asarray(log_nf, float)
    lab = np.asarray(regimes, dtype=object)
    if not (x.size == y.size == lab.size) or x.size == 0:
        raise ValueError(f"log_nb, log_nf, regimes lengths=({x.size}, {y.size}, {lab.size}): "
                         "must be equal and >= 1")
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k={k!r}: must be an integer >= 1")
    gx = np.asarray(grid_x, float)
    gy = np.asarray(grid_y, float)
    sx = max(float(np.ptp(x)), 1e-9)
    sy = max(float(np.ptp(y)), 1e-9)
    s = max(sx, sy)
    tree = cKDTree(np.c_[x / s, y / s])
    kk = min(k, x.size)
    _, idx = tree.query(np.c_[gx.ravel() / s, gy.ravel() / s], k=kk)
    if kk == 1:
        out = lab[idx]
    else:
        names, codes = np.unique(lab, return_inverse=True)
        votes = np.zeros((idx.shape[0], len(names)))
        w = 1.0 + 1e-6 * (kk - np.arange(kk))  # nearest wins ties
        np.add.at(votes, (np.arange(idx.shape[0])[:, None], codes[idx]), w[None, :])
        out = names[np.argmax(votes, axis=1)]
    return out.reshape(gx.shape)


_PALETTE = ("#c6dbef", "#fdd0a2", "#c7e9c0", "#dadaeb", "#fcbba1", "#d9d9d9")


def _label_shade(label: str, i: int) -> str:
    if label in REGIME_STYLE:
        return REGIME_STYLE[label]["shade"]
    if label in ("True", "False", "fracturing", "porous_invasion"):
        return regime_style(label)["shade"]
    return _PALETTE[i % len(_PALETTE)]


def _shade_classifier(ax, model, GX, GY, alpha: float = 0.75):
    """Colour the plane by the classifier: each label's shade weighted by its probability (a smooth map,
    white where no label is likely), and the borders of the most probable label as thin black lines."""
    from matplotlib.colors import to_rgb

    P = model.proba(np.c_[GX.ravel(), GY.ravel()])
    cols = np.array([to_rgb(_label_shade(lab, i)) for i, lab in enumerate(model.labels)])
    img = (P @ cols).reshape(GX.shape + (3,))
    ax.pcolormesh(GX, GY, img, shading="auto", alpha=alpha, zorder=0, rasterized=True)
    top = np.argmax(P, axis=1).reshape(GX.shape)
    for k in range(len(model.labels)):
        m = (top == k).astype(float)
        if 0 < m.mean() < 1:
            ax.contour(GX, GY, m, levels=[0.5], colors="k", linewidths=0.8, zorder=1)
    return P


def plot_boundary_sampling(model, points: Any, out_path: str | Path, *, band: Mapping[str, Any] | None = None,
                           title: str | None = None, formats: Sequence[str] = ("svg",), grid: int = 200,
                           axis_labels: Sequence[str] | None = None) -> dict[str, Any]:
    """The boundary sampler's view of a 2-axis campaign: classifier shading, probability contours, the
    50 % line (the boundary) with its uncertainty band, and the runs numbered and coloured by order.

    model : a ``sweep.regimes.regime_model.RegimeModel`` over two axes (axis units; log axes drawn in log).
    points : DataFrame with the two axis columns, ``order`` (0, 1, ...) and ``label`` (None: failed).
    band : ``sweep.regimes.regime_model.boundary_band(model)``; the band is the set of points closer to an
        estimated boundary point than its half-width (tolerance units), drawn hatched.
    Two labels: contours of P(second label) at 10, 30, 70, 90 % (thin) and 50 % (thick); more labels:
    the borders of the most probable label (thick). axis_labels : the two axis labels with units (default:
    the axis names). Writes PNG plus ``formats``; returns {"paths"}.
    """
    from scipy.spatial import cKDTree

    if len(model.axes) != 2:
        raise ValueError(f"model: {len(model.axes)} axes; the boundary figure draws two")
    ax0, ax1 = model.axes
    fig = _new_figure((6.0, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    u = np.linspace(-1.0, 1.0, grid)
    UX, UY = np.meshgrid(u, u)
    GX, GY = ax0.from_u(UX), ax1.from_u(UY)
    P = _shade_classifier(ax, model, GX, GY)
    if len(model.labels) == 2:
        cs = ax.contour(GX, GY, P[:, 1].reshape(GX.shape), levels=[0.1, 0.3, 0.7, 0.9], colors="0.3",
                        linewidths=0.5, linestyles="dotted", zorder=1)
        ax.clabel(cs, fmt=lambda v: f"{v:.0%}", fontsize=5)
        ax.contour(GX, GY, P[:, 1].reshape(GX.shape), levels=[0.5], colors="k", linewidths=1.8, zorder=2)
    if band is not None and len(band["U"]):
        tol = np.array([ax0.tol_per_u, ax1.tol_per_u])
        dist, j = cKDTree(band["U"] * tol).query(np.c_[UX.ravel(), UY.ravel()] * tol)
        inside = (dist <= np.asarray(band["half"])[j]).reshape(GX.shape).astype(float)
        ax.contourf(GX, GY, inside, levels=[0.5, 1.5], colors="none", hatches=["////"], zorder=1)
        ax.contour(GX, GY, inside, levels=[0.5], colors="0.35", linewidths=0.6, zorder=1)
    order = points["order"].to_numpy()
    x, y = points[ax0.name].to_numpy(float), points[ax1.name].to_numpy(float)
    labels = points["label"].to_numpy()
    markers = {lab: "o^sDvP"[i % 6] for i, lab in enumerate(model.labels)}
    for lab in list(model.labels) + [None]:
        m = np.array([(v is None or v != v) if lab is None else v == lab for v in labels])
        if m.any():
            sc = ax.scatter(x[m], y[m], c=order[m], cmap="viridis", vmin=0, vmax=max(order.max(), 1),
                            marker=markers.get(lab, "x"), s=28, edgecolor="k", linewidth=0.4, zorder=3,
                            label=regime_style(lab)["label"])
    for xv, yv, o in zip(x, y, order):
        ax.annotate(str(int(o)), (xv, yv), xytext=(3, 3), textcoords="offset points", fontsize=5, zorder=4)
    fig.colorbar(sc, ax=ax, label="order of the run", fraction=0.046, pad=0.04)
    for a, setter in ((ax0, ax.set_xscale), (ax1, ax.set_yscale)):
        if a.log:
            setter("log")
    ax.set_xlim(ax0.lo, ax0.hi)
    ax.set_ylim(ax1.lo, ax1.hi)
    names = tuple(axis_labels) if axis_labels else (ax0.name, ax1.name)
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    if title:
        ax.set_title(title, fontsize=8)
    from matplotlib.patches import Patch

    handles, _ = ax.get_legend_handles_labels()
    handles.append(Patch(facecolor="none", edgecolor="0.35", hatch="////",
                         label=f"{model.confidence:.0%} band of the boundary"))
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    return {"paths": _save(fig, out_path, formats)}


def _thumbnail(fig, ax, run_dir: str | Path, xy: tuple[float, float], pos: tuple[float, float],
               size: float, at: Any) -> None:
    """Circular inset of a run: porosity and the S = 0.5 contour in white.

    The fields are drawn from the classifier's raster (one image, light in SVG)."""
    from .classify import _load_mesh, build_raster, select_snapshot

    run_dir = Path(run_dir)
    points, tris = _load_mesh(run_dir)
    _, snap = select_snapshot(run_dir, at)
    with np.load(snap) as z:
        S = np.asarray(z["S"], float)
        phi = np.asarray(z["phi"], float)
    ras = build_raster(points, tris)
    phi_img = ras.elemental(phi) if phi.size == len(tris) and phi.size != len(points) else ras.nodal(phi)
    S_img = ras.nodal(S, fill=np.nan)
    ext = (ras.x[0] - ras.pixel / 2, ras.x[-1] + ras.pixel / 2,
           ras.y[0] - ras.pixel / 2, ras.y[-1] + ras.pixel / 2)
    ins = ax.inset_axes([pos[0] - size / 2, pos[1] - size / 2, size, size])
    ins.imshow(np.ma.masked_invalid(phi_img), origin="lower", extent=ext, cmap="viridis",
               vmin=0.2, vmax=1.0, interpolation="nearest")
    if np.nanmax(S_img) >= 0.5 > np.nanmin(S_img):
        ins.contour(ras.x, ras.y, np.ma.masked_invalid(S_img), levels=[0.5], colors="white",
                    linewidths=0.8)
    ins.set_aspect("equal")
    ins.axis("off")
    ax.annotate("", xy=xy, xycoords="data", xytext=pos, textcoords="axes fraction",
                arrowprops=dict(arrowstyle="-", color="0.3", lw=0.6))


def plot_nf_vs_nb(df: Any, out_path: str | Path, *, shade: bool | str = True, k: int = 1,
                  experimental_range: Mapping[str, float] | Sequence[float] | None = None,
                  thumbnails: Sequence[Mapping[str, Any]] | None = None,
                  dp_cri: float | None = None, formats: Sequence[str] = ("svg",),
                  title: str | None = None, grid: int = 300) -> dict[str, Any]:
    """Log-log phase diagram N_f vs N_b with the five regimes (Sec. 3.8, Fig. phase_diagram).

    df columns: ``N_b``, ``N_f``, ``regime`` (+ ``run_dir`` for thumbnails).
    Symbols: blue circle uniform invasion, blue star viscous fingering, orange triangle
    invasive fracturing, orange square non-invasive fracturing, orange cross
    fracturing/fingering. ``shade``: True or "classifier" colours the plane by the regime
    probabilities of ``sweep.regimes.regime_model`` (multinomial logistic regression on a cubic basis in
    the log plane: each regime's shade weighted by its probability, the most probable regime's
    borders drawn as thin lines); "nearest" by ``regime_map`` (k nearest runs, a staircase);
    False: no shading. ``order`` column (optional): each run numbered by it. Dashed lines N_f = 1 and N_b = 1. ``experimental_range``:
    (nb_min, nb_max, nf_min, nf_max) or a mapping with those keys, drawn as a red
    rectangle. ``thumbnails``: list of {"row": index label of df (or "run_dir": path
    and "xy": (N_b, N_f)), "pos": (x, y) axes fraction of the inset centre,
    "size": axes fraction (0.18), "at": snapshot selector (default "last")}.
    ``dp_cri`` (kPa) is written in the title when given. Writes PNG plus ``formats``;
    returns {"paths", "n_dropped", "counts"}.
    """
    _require(df, ("N_b", "N_f", "regime"), "plot_nf_vs_nb")
    nb = df["N_b"].to_numpy(dtype=float)
    nf = df["N_f"].to_numpy(dtype=float)
    rg = df["regime"].astype(str).to_numpy()
    ok = np.isfinite(nb) & np.isfinite(nf) & (nb > 0) & (nf > 0) & np.isin(rg, REGIMES)
    n_drop = int((~ok).sum())
    nb, nf, rg = nb[ok], nf[ok], rg[ok]
    if not isinstance(grid, (int, np.integer)) or grid < 10:
        raise ValueError(f"grid={grid!r}: must be an integer >= 10")

    fig = _new_figure((6.0, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    if nb.size:
        lx, ly = np.log10(nb), np.log10(nf)
        x0, x1 = min(lx.min(), 0.0) - 0.5, max(lx.max(), 0.0) + 0.5
        y0, y1 = min(ly.min(), 0.0) - 0.5, max(ly.max(), 0.0) + 0.5
    else:
        lx = ly = np.empty(0)
        x0, x1, y0, y1 = -2.0, 2.0, -2.0, 2.0
    _shade_regimes(ax, shade, lx, ly, rg, (x0, x1, y0, y1), grid, k)
    counts = {}
    for r in REGIMES:
        m = rg == r
        counts[r] = int(m.sum())
        st = REGIME_STYLE[r]
        if m.any():
            ax.scatter(nb[m], nf[m], marker=st["marker"], color=st["color"],
                       s=60 if st["marker"] == "*" else 30, label=st["label"], zorder=3)
    if "order" in df.columns:
        for xv, yv, o in zip(nb, nf, df["order"].to_numpy()[ok]):
            if o == o:
                ax.annotate(str(int(o)), (xv, yv), xytext=(3, 3), textcoords="offset points", fontsize=5, zorder=5)
    ax.axhline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    ax.axvline(1.0, color="0.2", ls="--", lw=1.0, zorder=2)
    if experimental_range is not None:
        x0, x1, y0, y1 = _experimental_box(ax, experimental_range, (x0, x1, y0, y1))
    ax.set_xlim(10**x0, 10**x1)
    ax.set_ylim(10**y0, 10**y1)
    ax.set_xlabel("branching number $N_b$")
    ax.set_ylabel("fracturing number $N_f$")
    t = title or ""
    if dp_cri is not None:
        t = (t + "\n" if t else "") + f"$\\delta p_{{cri}}$ = {dp_cri:.3g} kPa"
    if t:
        ax.set_title(t, fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3,
              frameon=False)
    _place_thumbnails(fig, ax, df, thumbnails or ())
    paths = _save(fig, out_path, formats)
    return {"paths": paths, "n_dropped": n_drop, "counts": counts}


def _shade_regimes(ax, shade, lx, ly, rg, bounds, grid: int, k: int) -> None:
    """Shade the (log N_b, log N_f) plane within ``bounds`` by regime: the classifier's probabilities
    (``shade`` True or "classifier") or the k-nearest-run staircase ("nearest")."""
    x0, x1, y0, y1 = bounds
    nb, nf = 10**lx, 10**ly
    if shade not in (True, False, "classifier", "nearest"):
        raise ValueError(f"shade={shade!r}: must be true/\"classifier\" (smooth, from the regime classifier), "
                         "\"nearest\" (nearest-neighbour staircase) or false")
    if shade == "nearest" and nb.size:
        from matplotlib.colors import ListedColormap

        gx, gy = np.meshgrid(np.linspace(x0, x1, grid), np.linspace(y0, y1, grid))
        lab = regime_map(lx, ly, rg, gx, gy, k=k)
        code = np.vectorize(REGIMES.index)(lab)
        cmap = ListedColormap([REGIME_STYLE[r]["shade"] for r in REGIMES])
        ax.pcolormesh(10**gx, 10**gy, code, cmap=cmap, vmin=-0.5, vmax=len(REGIMES) - 0.5,
                      shading="auto", alpha=0.6, zorder=0, rasterized=True)
    elif shade and len(set(rg)) >= 2:
        from .regime_model import AxisScale, fit_regime_model

        axes = (AxisScale("N_b", 10**x0, 10**x1, True, 0.1), AxisScale("N_f", 10**y0, 10**y1, True, 0.1))
        model = fit_regime_model(np.c_[nb, nf], rg, axes, degree=3, prior_sd=10.0)
        gx, gy = np.meshgrid(np.linspace(x0, x1, grid), np.linspace(y0, y1, grid))
        _shade_classifier(ax, model, 10**gx, 10**gy)

def _experimental_box(ax, experimental_range, bounds) -> tuple:
    """Draw the experiments' (N_b, N_f) rectangle; returns the log10 axis bounds widened to hold it."""
    x0, x1, y0, y1 = bounds
    from matplotlib.patches import Rectangle

    if isinstance(experimental_range, Mapping):
        try:
            e = [float(experimental_range[k_]) for k_ in ("nb_min", "nb_max", "nf_min", "nf_max")]
        except KeyError as exc:
            raise ValueError(f"experimental_range: missing key {exc}; needs nb_min, nb_max, "
                             "nf_min, nf_max") from None
    else:
        e = [float(v) for v in experimental_range]
    if len(e) != 4 or min(e) <= 0 or e[1] <= e[0] or e[3] <= e[2]:
        raise ValueError(f"experimental_range={experimental_range!r}: needs 0 < nb_min < "
                         "nb_max and 0 < nf_min < nf_max")
    ax.add_patch(Rectangle((e[0], e[2]), e[1] - e[0], e[3] - e[2], fill=False, ec="red",
                           lw=1.5, zorder=4, label="experiments"))
    x0, x1 = min(x0, math.log10(e[0]) - 0.2), max(x1, math.log10(e[1]) + 0.2)
    y0, y1 = min(y0, math.log10(e[2]) - 0.2), max(y1, math.log10(e[3]) + 0.2)
    return x0, x1, y0, y1


def _place_thumbnails(fig, ax, df, thumbnails) -> None:
    """Inset snapshots of chosen runs (see :func:`plot_nf_vs_nb`'s ``thumbnails``)."""
    for th in thumbnails:
        if not isinstance(th, Mapping) or "pos" not in th:
            raise ValueError(f"thumbnails: entry {th!r} must be a mapping with 'pos'")
        if "row" in th:
            row = df.loc[th["row"]]
            run_dir, xy = row["run_dir"], (float(row["N_b"]), float(row["N_f"]))
        else:
            run_dir, xy = th["run_dir"], tuple(th["xy"])
        _thumbnail(fig, ax, run_dir, xy, tuple(th["pos"]), float(th.get("size", 0.18)), th.get("at", "last"))



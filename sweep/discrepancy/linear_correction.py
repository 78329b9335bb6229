"""The discretization correction as a linear function of the fitted parameters (``[profile] correction =
"linear"``): fitted once from the fine realizations at a few anchors and evaluated at every profile point and
re-centring, so that every point is compared under the same correction function (common random numbers); with
``[profile] correction_follows = "all"`` it is linear in the calibrated parameters too and each fit evaluates it
at its own trial parameters (noise.NoiseModel.following).  Built by profile._Profile.linear_correction.  Units:
the correction in kPa / mm per curve row; coordinates are the parameters' internal (fit) coordinates.
"""
from __future__ import annotations

import numpy as np

__all__ = ["StrengthCorrection", "PiecewiseCorrection"]


class StrengthCorrection:
    """The discretization correction (fine − coarse, per curve row, kPa / mm) as a linear function of the
    fitted parameters' internal coordinates x (log10 or linear): c(x) = a + Bᵀ (x − x̄), least squares per
    row through the corrections estimated at the anchors ``xs`` (``corrs``: one row vector each; exact through
    d + 1 anchors in general position).  ``xs``: (n,) for one parameter (the profiled strength:
    ``[profile] correction_follows = "strength"``) or (n, d) for d (``"all"``: the strength and the calibrated
    parameters, the strength in column ``strength``); ``params``: the CalibParam of each column, which lets
    the model be evaluated at a values dict (:meth:`__call__`, the noise model's correction that follows the parameters, :meth:`NoiseModel.following`).

    The fine-minus-coarse difference of damage- and crack-dependent observables changes with the effect's
    strength (results/discrepancy/long_bias/README.md), and with the calibrated parameters (k̄ through the
    pressure's scale, results/discrepancy/ten_minute_twin/diagnosis/): one correction vector taken at one
    point and applied elsewhere gives the fit the coarse model's sensitivity to the parameters instead of the
    fine one's.  A linear model holds the fine model's first-order sensitivity to each parameter it models;
    with the strength alone, the other parameters' influence is taken along the profile's own path (each
    strength anchor's others refitted at its strength)."""

    def __init__(self, xs, corrs, values=None, real=None, params=None, strength: int = 0):
        self.real = real            # the same model through the corrections of real runs, when ``corrs`` are not
        X = np.asarray(xs, float)
        self.X = X[:, None] if X.ndim == 1 else X
        self.xs = X                 # the anchors as given: (n,) for one parameter
        C = np.vstack([np.asarray(c, float) for c in corrs])
        n, d = self.X.shape
        if n < max(2, d + 1) or C.shape[0] != n:
            raise ValueError(f"StrengthCorrection: {n} anchors for {C.shape[0]} corrections and {d} parameters "
                             f"(needs as many corrections as anchors, >= {max(2, d + 1)})")
        self.params = tuple(params) if params is not None else None
        self.strength = int(strength)          # the profiled strength's column (its anchors: ``values``)
        if self.params is not None and len(self.params) != d:
            raise ValueError(f"StrengthCorrection: {len(self.params)} parameters for anchors of {d} coordinates")
        self.values = list(values) if values is not None else [float(x) for x in self.X[:, self.strength]]
        self.realizations = self.slope_realizations = None   # fine realizations at the first / the other anchors
        self._model(C)

    def _model(self, C: np.ndarray) -> None:
        """The least-squares line through the corrections ``C`` (one row per anchor) and its residual RMS."""
        self.xbar = self.X.mean(axis=0)
        U = self.X - self.xbar
        self.a = C.mean(axis=0)
        self.B = np.linalg.lstsq(U, C - self.a, rcond=None)[0]          # (d, rows)
        self.resid_rms = float(np.sqrt(np.mean((C - self.a - U @ self.B) ** 2)))

    def beyond(self, x: float) -> bool:
        """Whether the profile must add an anchor at ``x`` before evaluating there: never for a line, which is
        defined everywhere (the piecewise correction answers otherwise)."""
        return False

    def at(self, x) -> np.ndarray:
        """c(x) on every curve row; ``x`` the model's coordinates (a number for one parameter)."""
        return self.a + (np.atleast_1d(np.asarray(x, float)) - self.xbar) @ self.B

    def coordinates(self, values: dict) -> np.ndarray:
        """The model's coordinates of ``values`` ({name: value}, each parameter's unit)."""
        if self.params is None:
            raise ValueError("StrengthCorrection: built without its parameters, it cannot be evaluated at values")
        missing = [p.name for p in self.params if p.name not in values]
        if missing:
            raise ValueError(f"StrengthCorrection: values {sorted(values)} lack the modelled parameters {missing}")
        return np.array([p.to_x(values[p.name]) for p in self.params])

    def __call__(self, values: dict) -> np.ndarray:
        """c at ``values`` ({name: value}, each parameter's unit; names beyond the model's are ignored)."""
        return self.at(self.coordinates(values))

    def for_real_runs(self) -> "StrengthCorrection":
        """The model for real runs of the coarse model: the one through the anchors' fine − real coarse runs
        (``real``; on the emulator this model is taken against the emulator's mean,
        :meth:`_Profile.model_correction`)."""
        return self.real if self.real is not None else self

    def real_at(self, x) -> np.ndarray:
        """c(x) for a real run of the coarse model (:meth:`for_real_runs`)."""
        return self.for_real_runs().at(x)

    def covers(self, values: dict) -> bool:
        """Whether every modelled parameter of ``values`` lies within its anchors' range (no extrapolation)."""
        x = self.coordinates(values)
        return bool(np.all((self.X.min(axis=0) <= x) & (x <= self.X.max(axis=0))))

    def summary(self, layout=None) -> dict:
        """The strength anchors (parameter units), the slope's RMS change of the correction over the anchors'
        span and the residual RMS of the model at the anchors (kPa / mm: per observable with ``layout``); with
        more than one parameter the anchors and the change over them per parameter."""
        out = {"model": "linear", "anchors": self.values, "line_residual_rms": self.resid_rms,
               "realizations": self.realizations, "slope_realizations": self.slope_realizations}
        if self.params is not None and len(self.params) > 1:
            out["follows"] = [p.name for p in self.params]
            out["parameter_anchors"] = {p.name: sorted({float(p.from_x(v)) for v in self.X[:, i]})
                                        for i, p in enumerate(self.params)}
        if layout is not None:
            from .noise import rms_per_observable
            span = np.ptp(self.X, axis=0)
            ch = [rms_per_observable(layout, self.B[i] * span[i]) for i in range(len(span))]
            out["change_over_anchors_rms"] = ch[self.strength]
            if len(ch) > 1:
                out["change_over_anchors_rms_by_parameter"] = {p.name: c for p, c in zip(self.params, ch)}
        return out


class PiecewiseCorrection(StrengthCorrection):
    """The discretization correction (kPa / mm per curve row) as a piecewise-linear function of the profiled
    strength's coordinate x (``[profile] correction = "piecewise"``): interpolated linearly between the anchors
    (sorted by x) and continued along the end segments beyond them, so that it equals the estimated correction
    at every anchor.  The profile adds an anchor wherever it evaluates beyond the anchors' range (:meth:`add`,
    ``_Profile.extend_correction``): the correction is never extrapolated past where it was estimated, which a
    line through a few anchors about the fit does when the correction switches on and saturates within the
    profile's reach (results/discrepancy/coverage/beta_point/), while between anchors every point is compared
    under the same function (common random numbers, a profile without the point-wise correction's steps).
    One parameter only (the strength)."""

    added = 0                                  # anchors the profile added beyond the first ones

    def _model(self, C: np.ndarray) -> None:
        """The anchors sorted by the strength, with their corrections ``C`` (the function: :meth:`at`)."""
        if self.X.shape[1] != 1:
            raise ValueError(f"PiecewiseCorrection: anchors in {self.X.shape[1]} parameters (it follows the "
                             "strength alone)")
        self._sort(self.X[:, 0], C, list(self.values))

    def _sort(self, x: np.ndarray, C: np.ndarray, values: list) -> None:
        order = np.argsort(x, kind="stable")
        self.px, self.C = np.asarray(x, float)[order], C[order]
        if np.any(np.diff(self.px) <= 0.0):
            raise ValueError(f"PiecewiseCorrection: two anchors at one strength ({self.px.tolist()})")
        self.values = [values[i] for i in order]
        self.X = self.xs = self.px[:, None]

    def at(self, x) -> np.ndarray:
        """c(x), ``x`` the strength's coordinate (a number or a one-element array)."""
        x = float(np.asarray(x, float).reshape(-1)[0])
        i = int(np.clip(np.searchsorted(self.px, x) - 1, 0, self.px.size - 2))
        t = (x - self.px[i]) / (self.px[i + 1] - self.px[i])
        return self.C[i] + t * (self.C[i + 1] - self.C[i])

    #: how far outside the anchors' range (a fraction of it) a point lies before it is "beyond" them: the first
    #: profile point is the Wald bound, which is also the outer anchor, recomputed to within rounding
    BEYOND_TOL = 1e-6

    def beyond(self, x: float) -> bool:
        """Whether ``x`` (the strength's coordinate) lies outside the anchors' range by more than rounding
        (:attr:`BEYOND_TOL` of the range)."""
        tol = self.BEYOND_TOL * (self.px[-1] - self.px[0])
        return bool(x < self.px[0] - tol or x > self.px[-1] + tol)

    def add(self, x: float, corr, value: float, real=None) -> None:
        """One more anchor at coordinate ``x`` (strength ``value``, its unit) with its correction ``corr`` (and
        ``real``, the same for real runs of the coarse model, into :attr:`real`)."""
        self._sort(np.append(self.px, float(x)), np.vstack([self.C, np.asarray(corr, float)]), self.values + [value])
        self.added += 1
        if self.real is not None and real is not None:
            self.real.add(x, real, value)

    def summary(self, layout=None) -> dict:
        """The anchors (strength units, sorted), how many the profile added, and the correction's RMS change
        between the outer anchors (kPa / mm: per observable with ``layout``)."""
        out = {"model": "piecewise", "anchors": self.values, "added_anchors": self.added,
               "realizations": self.realizations, "slope_realizations": self.slope_realizations}
        if layout is not None:
            from .noise import rms_per_observable
            out["change_over_anchors_rms"] = rms_per_observable(layout, self.C[-1] - self.C[0])
        return out

"""A cheap analytic forward model with the catalogue's effects, for testing the workflow's statistics.

Not physics: closed-form curves whose effects have the *kind* of signatures the solver's have
(units kPa, mm, s).  With P0 = 0.05 w_i η_o / k̄ and τ = 0.3·331/E:

    p(t)      = P0 (1 − e^{−t/τ}) / (1 + 2 c)                  c: outer_compliance (confounded with k̄ in p)
                + β (w_i/50) 0.5 e^{−t/0.2}                    β: damage viscosity (rate dependent)
                + 25 v e^{−t/0.2}                              v: volumetric_coupling (rate independent)
                − 0.3 s P0 σ((t − t_i)/0.05)                   s: crack_permeability (after initiation)
                + h_err                                        discretization error ∝ mesh size h
    front(t)  = 5 + 15 t (w_i/50) (1 + 20 c) − 0.5 κf          κf: korteweg_factor
    crack(t)  = 20 (t − t_i)₊ (1 + 0.5 s),   t_i = 0.2 (1 + 0.01 β)
    regime    = "fracturing" if crack(t_end) > 1 mm else "porous_invasion"

``anomaly`` (not a Parameters field, read from the constructor) adds 30 sin(2π t/0.5) kPa to p:
an effect outside the catalogue.  h (mm) comes from the constructor and adds 0.02 h (1 − e^{−t/τ}) kPa;
``beta_mesh`` b makes the damage-viscosity term mesh dependent, β → β (1 + b h), as an effect whose
discretization error grows with its strength (damage on a mesh that barely resolves l_d).
"""
from __future__ import annotations

import math

import numpy as np

from .forward import ForwardModel

__all__ = ["ToyForward", "MeshToy"]


class ToyForward(ForwardModel):
    """Closed-form stand-in for the solver (see the module docstring); counts evaluations in ``n_runs``."""

    regime_labels = ("fracturing", "porous_invasion")   # the labels predict_one gives

    def __init__(self, base: dict | None = None, h: float = 8.0, anomaly: float = 0.0, beta_mesh: float = 0.0):
        self.base = dict(base or {})
        self.h = float(h)
        self.anomaly = float(anomaly)
        self.beta_mesh = float(beta_mesh)
        self.n_runs = 0

    def predict_one(self, overrides: dict, times: dict) -> dict:
        from solver import Parameters

        self.n_runs += 1
        p = Parameters.from_dict({**self.base, **overrides})
        beta = p.damage_viscosity * (1.0 + self.beta_mesh * self.h)
        c, v, s, kf = p.outer_compliance, p.volumetric_coupling, p.crack_permeability, p.korteweg_factor
        P0 = 0.05 * p.w_i * p.eta_o / p.kbar
        tau = 0.3 * 331.0 / p.E
        ti = 0.2 * (1 + 0.01 * p.damage_viscosity)
        rate = p.w_i / 50.0

        def pres(t):
            return (P0 * (1 - np.exp(-t / tau)) / (1 + 2 * c) + beta * rate * 0.5 * np.exp(-t / 0.2)
                    + 25 * v * np.exp(-t / 0.2) - 0.3 * s * P0 / (1 + np.exp(-(t - ti) / 0.05))
                    + 0.02 * self.h * (1 - np.exp(-t / tau)) + self.anomaly * 30 * np.sin(2 * np.pi * t / 0.5))

        def crack(t):
            return 20 * np.clip(t - ti, 0, None) * (1 + 0.5 * s)

        out = {}
        for obs, t in times.items():
            t = np.asarray(t, float)
            if obs == "p_inj":
                out[obs] = pres(t)
            elif obs == "front_radius_mean":
                out[obs] = 5 + 15 * t * rate * (1 + 20 * c) - 0.5 * kf
            elif obs == "crack_length":
                out[obs] = crack(t)
            elif obs == "regime":
                out[obs] = "fracturing" if crack(t.max()) > 1.0 else "porous_invasion"
            else:
                raise ValueError(f"ToyForward: observable {obs!r} is not modelled (p_inj, front_radius_mean, "
                                 "crack_length, regime)")
        return out


class MeshToy(ForwardModel):
    """A closed-form stand-in with the structure the interval's coverage depends on (units kPa, mm, s).

    With rate = w_i/50, P0 = 0.05 w_i η_o/k̄ · (1 + 0.25 (C − 1.2)), τ = 0.3 (331/E_h)(0.5 + 800/K_s):

        p(t)     = P0 (1 − e^{−t/τ}) (1 + a_b h) + 0.5 β_h rate √(C/1.2) e^{−t/0.2} + 25 v e^{−t/0.2} + δp(t)
        front(t) = 5 + 15 t rate (η_o/0.29)^(−0.2) (k̄/0.0015)^0.3 (1 + 0.1 v) (1 − a_f h) + δf(t)

    E_h = E (1 + a_E h), β_h = β (1 + a_β h): a discretization error growing with the mesh size h (mm)
    that depends on the parameters, so a correction estimated at one point is wrong elsewhere (``bias``
    scales the four coefficients a_b = 0.005, a_f = 0.01, a_E = 0.01, a_β = 0.05; 0: no discretization
    error).  β: damage viscosity (kPa·s), v: volumetric coupling (-), both continuous strengths correlated
    with E, k̄, K_s through the early pressure.  δp, δf: the deviation of mesh realization ``realization``,
    a random curve per condition (``spread`` scales it; 0: none), of one of two shapes (``shape``):

    "smooth"   δp = spread (P0/483) (3 a (1 − e^{−t/0.1}) + 2 b t/0.3),  δf = spread (0.4 c t/0.3 + 0.15 d sin(πt/0.3)),
               a, b, c, d standard normal: two smooth components, correlated over the whole curve;
    "wander"   δp = spread (P0/483) 3 g(t) u_p(t),  δf = spread 0.4 g(t) u_f(t),  g = 1 − e^{−t/0.05}, u_p, u_f
               unit Ornstein–Uhlenbeck processes with correlation time 0.1 s (stationary, on a 2.5 ms grid
               from t = 0, interpolated): the exponential correlation in time the workflow's covariance assumes.

    The draws come from (realization, condition), so a realization is the same mesh whatever the fitted
    parameters.  ``jitter`` (kPa; default 0) adds the jitter of a mesh that barely resolves the front: a
    curve-wide offset jitter·(P0/483)·g(t)·z in p_inj and 0.1·jitter·g(t)·z' in the front radius, z, z' standard
    normal drawn per (realization, condition, parameter values): independent between parameter values however
    close, as the solver's outputs jump when an S = 0.5 contour crosses a node.  Counts evaluations in ``n_runs``.

    ``cracks`` (the whole injection, ``crack_length`` observable; default off, the curves above): the crack initiates at
    t_i = 0.4 (331/E_h)^0.5 (1 + β_h'/60) s with β_h' = β (1 + a_c h), a_c = 0.1 ``bias`` (damage on a mesh that
    barely resolves l_d delays initiation, and more so for a stronger damage viscosity: a discretization
    error that depends on the strength), grows as crack = 12 (t − t_i)₊ rate (η_o/0.29)^0.3 mm, and the
    pressure falls after it by 0.25 P0 σ((t − t_i)/0.04); the realization deviation of the crack is
    spread·0.6·u_c(t)·min(1, (t − t_i)₊/0.1) mm (u_c a unit Ornstein–Uhlenbeck process, τ = 0.2 s).
    """

    regime_labels = ("porous_invasion",)

    SHAPES = ("smooth", "wander")

    def __init__(self, h: float = 4.0, realization: int = 0, spread: float = 1.0, bias: float = 1.0,
                 shape: str = "smooth", jitter: float = 0.0, cracks: bool = False):
        if not (h > 0 and spread >= 0 and bias >= 0 and int(realization) >= 0 and shape in self.SHAPES
                and jitter >= 0):
            raise ValueError(f"MeshToy: h={h!r} (> 0), spread={spread!r} (>= 0), bias={bias!r} (>= 0), "
                             f"realization={realization!r} (integer >= 0), shape={shape!r} (one of {self.SHAPES}), "
                             f"jitter={jitter!r} (>= 0)")
        self.h, self.realization, self.spread, self.bias = float(h), int(realization), float(spread), float(bias)
        self.shape, self.jitter, self.cracks = shape, float(jitter), bool(cracks)
        self.n_runs = 0

    def _key(self, p) -> list:
        """The condition of ``p`` as integers (the realization deviation's seed with the realization)."""
        return [self.realization, int(round(p.w_i * 1e3)), int(round(p.cement * 1e4)), int(round(p.eta_o * 1e6))]

    def _jitter(self, p, P0: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p_inj, front) jitter of this realization at the parameter values of ``p`` (class docstring)."""
        if self.jitter == 0.0:
            return np.zeros_like(t), np.zeros_like(t)
        vals = (p.damage_viscosity, p.volumetric_coupling, p.E, p.kbar * 1e6, p.K_s)
        rng = np.random.default_rng(self._key(p) + [int(round(v * 1e6)) % (2**62) for v in vals])
        z = rng.standard_normal(2)
        g = self.jitter * (1 - np.exp(-t / 0.05))
        return (P0 / 483.0) * g * z[0], 0.1 * g * z[1]

    def _crack(self, p, rate: float, hb: float, t: np.ndarray, E_h: float) -> tuple[np.ndarray, float]:
        """The crack length (mm) and initiation time t_i (s) on this mesh, with its realization deviation."""
        ti = 0.4 * math.sqrt(331.0 / E_h) * (1 + p.damage_viscosity * (1 + 0.1 * hb) / 60.0)
        grown = np.clip(t - ti, 0, None)
        c = 12.0 * grown * rate * (p.eta_o / 0.29) ** 0.3
        if self.spread:
            rng = np.random.default_rng(self._key(p) + [3])
            c = c + self.spread * 0.6 * _ou(rng, t, 0.2) * np.minimum(1.0, grown / 0.1)
        return np.maximum(c, 0.0), ti

    def _deviation(self, p, P0: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(δp, δf) of this realization for the condition of ``p`` at times ``t``."""
        rng = np.random.default_rng(self._key(p))
        if self.shape == "wander":
            g = self.spread * (1 - np.exp(-t / 0.05))
            return 3.0 * (P0 / 483.0) * g * _ou(rng, t, 0.1), 0.4 * g * _ou(rng, t, 0.1)
        a, b, c, d = rng.standard_normal(4)
        dp = self.spread * (P0 / 483.0) * (3.0 * a * (1 - np.exp(-t / 0.1)) + 2.0 * b * t / 0.3)
        df = self.spread * (0.4 * c * t / 0.3 + 0.15 * d * np.sin(np.pi * t / 0.3))
        return dp, df

    def predict_one(self, overrides: dict, times: dict) -> dict:
        from solver import Parameters

        self.n_runs += 1
        p = Parameters.from_dict(overrides)
        hb = self.h * self.bias
        rate = p.w_i / 50.0
        P0 = 0.05 * p.w_i * p.eta_o / p.kbar * (1 + 0.25 * (p.cement - 1.2))
        tau = 0.3 * (331.0 / (p.E * (1 + 0.01 * hb))) * (0.5 + 800.0 / p.K_s)
        beta = p.damage_viscosity * (1 + 0.05 * hb)
        v = p.volumetric_coupling
        E_h = p.E * (1 + 0.01 * hb)
        out = {}
        for obs, t in times.items():
            t = np.asarray(t, float)
            dp, df = self._deviation(p, P0, t)
            jp, jf = self._jitter(p, P0, t)
            if obs == "p_inj":
                out[obs] = (P0 * (1 - np.exp(-t / tau)) * (1 + 0.005 * hb)
                            + (0.5 * beta * rate * math.sqrt(p.cement / 1.2) + 25 * v) * np.exp(-t / 0.2) + dp + jp)
                if self.cracks:                       # the whole injection: the fall after initiation
                    ti = self._crack(p, rate, hb, t, E_h)[1]
                    out[obs] = out[obs] - 0.25 * P0 / (1 + np.exp(-(t - ti) / 0.04))
            elif obs == "front_radius_mean":
                out[obs] = (5 + 15 * t * rate * (p.eta_o / 0.29) ** -0.2 * (p.kbar / 0.0015) ** 0.3
                            * (1 + 0.1 * v) * (1 - 0.01 * hb) + df + jf)
            elif obs == "crack_length" and self.cracks:
                out[obs] = self._crack(p, rate, hb, t, E_h)[0]
            elif obs == "regime":
                out[obs] = "porous_invasion"
            else:
                raise ValueError(f"MeshToy: observable {obs!r} is not modelled (p_inj, front_radius_mean, regime; "
                                 "crack_length with cracks=True)")
        return out


def _ou(rng, t: np.ndarray, tau: float, dt: float = 0.0025) -> np.ndarray:
    """A unit stationary Ornstein–Uhlenbeck path (correlation exp(−|Δt|/τ), τ and t in s) drawn on the grid
    0, dt, 2 dt, … up to max(t) and interpolated at ``t``."""
    n = int(np.ceil(max(float(np.max(t)), dt) / dt)) + 2
    rho = math.exp(-dt / tau)
    xi = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = xi[0]
    for i in range(1, n):                     # n ~ 120 points per path: a short recursion
        x[i] = rho * x[i - 1] + math.sqrt(1 - rho * rho) * xi[i]
    return np.interp(t, dt * np.arange(n), x)

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

import numpy as np

from .forward import ForwardModel

__all__ = ["ToyForward"]


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

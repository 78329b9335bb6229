"""What a run records of each accepted step: the time-series row (volume balances, front and damage measures)
and the snapshot fields.

Volumes in mm² per unit cell height (the model is 2D), pressures kPa, lengths mm, times s; the columns and their
units are declared once in ``solver.output.TIMESERIES_COLUMNS``.  The balances come from the unconstrained residual
at the converged state: its Dirichlet rows are the reactions (the injected, outflow and water volumes).
"""
from __future__ import annotations

import numpy as np

from . import fem, linsolve, metrics
from .model import MU, P, S, element_fields, line_stored_rate, outlet_water_outflow, residual_and_jacobian

__all__ = ["accumulate_balances", "stored_volume", "water_fraction", "step_row", "take_snapshot"]


def accumulate_balances(sim, U, data, dt: float, cum: dict, ev: np.ndarray, phi_q: np.ndarray) -> None:
    """Add the step's injected, outflow, source and water volumes (mm²) to ``cum``.

    From the unconstrained residual at the converged state U: its Dirichlet rows are the reactions.  ``ev``,
    ``phi_q``: U's volumetric strain and porosity (:func:`solver.model.porosity_state`).
    """
    disc, p = sim.disc, sim.params
    R, _ = residual_and_jacobian(disc, p, U, data, need_jacobian=False)
    nf = disc.n_fields
    Rp, Rs = R[P::nf], R[S::nf]
    cum["inj"] += dt * p.w_i * disc.inner_length
    cum["out"] += -dt * Rp[disc.outer_nodes].sum()
    if disc.inner_weights is not None:  # the injection line's storage (solver.model.line_stored_rate)
        cum["line"] += dt * float(line_stored_rate(disc, p, U, data).v.sum())
    cum["src"] += dt * _source(sim, data, ev, phi_q)
    cum["w_src"] += dt * _source(sim, data, ev, phi_q * fem.at_quadrature(U[:, S], disc.triangles, fem.STRANG3))
    if disc.inner_injection:  # the inlet's load on the S rows: the pumped water less the line's storage
        cum["w_in"] += -dt * float(disc.inject[S::nf][disc.inner_nodes].sum())
        if disc.inner_weights is not None:
            cum["w_in"] -= dt * float(line_stored_rate(disc, p, U, data).v.sum())
    else:  # S = 1 imposed on r_i: the water inflow is its reaction (advection and the Cahn–Hilliard flux)
        cum["w_in"] += dt * Rs[disc.inner_nodes].sum()
    if disc.outlet is None:  # S = 0 imposed on r_o: the water outflow is its reaction (0 with no S condition)
        cum["w_out"] += -dt * Rs[disc.outer_nodes].sum()
    else:  # the outlet's boundary term (solver.model.outlet_water_outflow), part of the S rows
        cum["w_out"] += dt * outlet_water_outflow(disc, p, U, R).sum()


def stored_volume(sim, phi_q: np.ndarray) -> float:
    """∫ φ dx (mm² per unit cell height) from φ at the Strang points (equal weights); φ is the storage fraction
    (pores and the elastic cell's gap, :func:`solver.model.storage_fraction`)."""
    return float(np.sum(sim.disc.geom.areas * phi_q.mean(axis=1)))


def water_fraction(sim, U: np.ndarray, phi_q: np.ndarray) -> np.ndarray:
    """φ S at the Strang points (M, 3), the invading fluid's volume fraction as the S rows' storage term sees it."""
    return phi_q * fem.at_quadrature(U[:, S], sim.disc.triangles, fem.STRANG3)


def _source(sim, data, ev: np.ndarray, phi_q: np.ndarray) -> float:
    """c_v ∫ φ ε̇_v dx: the second-order volume source of the total mass balance (mm²/s), from the step's
    frozen data and the new state's ε_v and φ; with φ S in place of φ (:func:`water_fraction`), that of the
    invading balance."""
    dev = (ev - data.ev_n) / data.dt
    return float(sim.params.volumetric_coupling * np.sum(sim.disc.geom.areas * phi_q.mean(axis=1) * dev))


def step_row(sim, dt, info, cum, V0, V, W) -> dict:
    """The time series' row of the committed state: V its stored volume, W its stored invading volume (mm²,
    :func:`stored_volume`)."""
    disc, p, U, d = sim.disc, sim.params, sim.U, sim.d
    ef = element_fields(disc, p, U, d, fluxes=False)
    Sn = U[:, S]
    fm, fx, fb = metrics.front_measures(disc.points, Sn, sim.edges, disc.inner_nodes)
    err = abs(cum["inj"] - (V - V0 + cum["src"] + cum["out"] + cum["line"])) / max(cum["inj"], 1e-300)
    area = disc.geom.areas
    d_el = d[disc.triangles].mean(axis=1)
    inv = float(np.sum(area * ef["phi"] * Sn[disc.triangles].mean(axis=1)))
    return {
        "t": sim.t, "dt": dt,
        "p_inj": float(np.mean(U[disc.inner_nodes, P])),
        "injected_volume": cum["inj"],
        "invading_volume": inv,
        "water_inflow_volume": cum["w_in"],
        "water_outflow_volume": cum["w_out"],
        "outflow_volume": cum["out"],
        "line_stored_volume": cum["line"],
        "stored_volume": V,
        "source_volume": cum["src"],
        "mass_error": err,
        "water_stored_volume": W,
        "water_source_volume": cum["w_src"],
        "water_mass_error": abs(cum["w_in"] - cum["w_out"] - (W - cum["W0"] + cum["w_src"])) / max(cum["inj"], 1e-300),
        "mean_damage": float(np.sum(area * d_el) / area.sum()),
        "max_damage": float(d.max()),
        "max_hoop_stress": float(ef["hoop_stress"].max()),
        "front_radius_mean": fm,
        "front_radius_max": fx,
        "front_radius_branches": fb,
        "open_tip_radius": metrics.open_tip_radius(disc.points, disc.triangles, ef["phi"], disc.inner_nodes),
        "outer_layer_area": metrics.outer_layer_area(disc.points, disc.triangles, area, Sn, sim.edges, disc.inner_nodes, disc.outer_nodes),
        "newton_its": info["newton_its"],
        "stagger_its": info["stagger_its"],
        "damage_kkt": info["damage_kkt"],
        "step_change": info["step_change"],
        "factorizations": linsolve.STATS["factorizations"] - sim.fact0,
    }


def take_snapshot(sim, snaps, writer):
    """Append the committed state's fields (nodal S, μ, p, d, u; element φ, ε_v, hoop stress, k, |w_1|) at
    ``sim.t`` to ``snaps`` and write them with ``writer`` (when given)."""
    disc = sim.disc
    ef = element_fields(disc, sim.params, sim.U, sim.d)
    fields = {
        "S": sim.U[:, S].copy(), "mu": sim.U[:, MU].copy(), "p": sim.U[:, P].copy(), "d": sim.d.copy(),
        "u": sim.U[:, :2].copy(),
        "phi": ef["phi"], "eps_v": ef["eps_v"], "hoop_stress": ef["hoop_stress"], "k": ef["k"], "w1_mag": ef["w1_mag"],
    }
    snaps.append((sim.t, fields))
    if writer:
        writer.write_snapshot(len(snaps) - 1, sim.t, fields)

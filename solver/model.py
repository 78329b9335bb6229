"""The model assembled: step data, the residual and exact Jacobian of the coupled poromechanics block, element fields.

The weak form is written once, point-wise, in :mod:`solver.forms`; :mod:`solver.discretization` holds the mesh-dependent
operators and boundary conditions.  Here the forms are evaluated over the elements (compiled kernels of
:mod:`solver.codegen`, else :class:`solver.ad.Dual` arrays), the boundary terms are added, and the element fields of the
outputs are computed with the same constitutive chain.  Damage d (nodal, -) is frozen here (staggered scheme,
Sec. 3.1) and solved in :mod:`solver.damage`.  Units mm, s, kPa.

This module is also the face of the model for its callers: the field indices, :func:`build_discretization`,
:func:`step_data` and :func:`residual_and_jacobian` are imported from here.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from . import ad, codegen, fem, kernels, paths, physics
from .ad import Dual
from .discretization import Discretization, build_discretization
from .forms import (FIELD_NAMES, GX, GY, MU, NOT_ELEMENT_DATA, P, S, UX, UY, Constitutive, StepData, constitutive,
                    darcy_fluxes, pointwise_forms, projection_forms)

__all__ = ["UX", "UY", "P", "S", "MU", "GX", "GY", "FIELD_NAMES", "Discretization", "StepData", "build_discretization",
           "step_data", "porosity_state", "storage_fraction", "residual_and_jacobian", "compiled_forms",
           "element_residuals", "line_stored_rate", "outlet_water_outflow", "korteweg_force", "project_gradient",
           "element_fields"]


def step_data(disc: Discretization, params, U_n: np.ndarray, d: np.ndarray, dt: float) -> StepData:
    """Freeze the previous state ``U_n`` (N, nf) and the damage iterate ``d`` (N,)."""
    tri = disc.triangles
    q = fem.STRANG3
    grads, ev_n, phi_n = porosity_state(disc, params, U_n)
    S_n = fem.at_quadrature(U_n[:, S], tri, q)
    up_x, up_y = upwind_shift(disc, grads[:, P]) if disc.upwind_length is not None else (None, None)
    stab = {} if disc.stab_tau is None else {"tau": disc.stab_tau, "px_n": grads[:, P, 0], "py_n": grads[:, P, 1]}
    if params.cell_compliance > 0:
        stab["gap_n"] = physics.gap_storage(fem.at_quadrature(U_n[:, P], tri, q), params.cell_compliance,
                                            params.cell_height)
    if params.line_compliance > 0:
        stab["p_nodal_n"] = U_n[:, P].copy()
    return StepData(dt=dt, d_q=fem.at_quadrature(d, tri, q), phi_n=phi_n, S_n=S_n, ev_n=ev_n, up_x=up_x, up_y=up_y,
                    supg_h=disc.supg_length, **stab)


def porosity_state(disc: Discretization, params, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of a state U (N, nf): the gradients of (u_x, u_y, p) per element (M, 3, 2), ε_v per element (-) and φ at
    the Strang points (M, 3), the porosity the storage term sees (Eq. summary_equations_3); read by
    :func:`step_data` and by the volume balances of the time series."""
    grads = fem.field_gradients(disc.geom.grads, U[disc.triangles][:, :, :P + 1])
    ev = grads[:, UX, 0] + grads[:, UY, 1]
    p_q = fem.at_quadrature(U[:, P], disc.triangles, fem.STRANG3)
    phi = physics.porosity(disc.phi0[:, None], ev[:, None], p_q, params.K_s, params.porosity_floor,
                           params.porosity_ceiling)
    return grads, ev, phi


def storage_fraction(disc: Discretization, params, U: np.ndarray, phi_q: np.ndarray) -> np.ndarray:
    """The fluid volume fraction the mass balances store, at the Strang points (M, 3): the porosity ``phi_q`` of
    :func:`porosity_state`, plus the elastic cell's gap δ/h (:func:`solver.physics.gap_storage`) when on."""
    if params.cell_compliance == 0:
        return phi_q
    p_q = fem.at_quadrature(U[:, P], disc.triangles, fem.STRANG3)
    return phi_q + physics.gap_storage(p_q, params.cell_compliance, params.cell_height)


def upwind_shift(disc: Discretization, grad_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upstream shift (mm) per element: half the element size along ∇p/|∇p| of the previous step.

    The flow runs down the pressure gradient, so +∇p points upstream.  The direction is lagged one step
    (taken from the converged previous state), so the Newton Jacobian of the step is exact and the
    shift vanishes where the previous pressure is uniform (the first step is Galerkin).
    """
    norm = np.sqrt(np.sum(grad_p * grad_p, axis=1) + 1e-24)
    return disc.upwind_length * grad_p[:, 0] / norm, disc.upwind_length * grad_p[:, 1] / norm


def outlet_water_outflow(disc: Discretization, params, U: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Water leaving each outer node (mm²/s), :func:`solver.physics.outlet_water_flux` of the node's S and total
    outflow Q_a = −R_p,a, the reaction of its p = 0 row in the unconstrained residual ``R`` (ndof,)."""
    nf, nodes = disc.n_fields, disc.outlet.nodes
    return physics.outlet_water_flux(U[nodes, S], -R[nf * nodes + P], params.viscosity_ratio,
                                     params.critical_saturation)


def _add_outlet(disc: Discretization, params, U: np.ndarray, R: np.ndarray, J) -> None:
    """Add the outlet's water outflow f(S_a) Q_a⁺ to the S rows of the outer nodes (the boundary term
    ∫_Γo r w_1·n of the invading balance, lumped on the nodes); J (or None) gets its exact derivative
    f(S_a) [Q_a > 0] ∂Q_a/∂U + f'(S_a) Q_a⁺ ∂S_a/∂U, with ∂Q_a/∂U = −(the p row of a)."""
    nf, out = disc.n_fields, disc.outlet
    Q = -R[nf * out.nodes + P]
    S_a = ad.Dual.variables([U[out.nodes, S]])[0]
    f = physics.fractional_flow(S_a, params.viscosity_ratio, params.critical_saturation)
    R[nf * out.nodes + S] += f.v * np.maximum(Q, 0.0)
    if J is None:
        return
    J.data[out.dst] -= (f.v * (Q > 0.0))[out.owner] * J.data[out.src]
    J.data[out.diag] += f.d[:, 0] * np.maximum(Q, 0.0)


def _variables(U_elem: np.ndarray, geom: fem.Geometry, quad: fem.Quadrature, dual: bool = True) -> list:
    """Point-wise inputs as Duals (for the Jacobian) or plain arrays (residual only: no derivative cost)."""
    inp = fem.qp_inputs(U_elem, geom, quad)
    M, nq = inp.shape[:2]
    flat = inp.reshape(M, nq, -1)
    n = flat.shape[-1]
    # gradients of P1 fields are constant on an element: one column (M, 1), broadcast against the point
    # values, so every quantity made of gradients only (strains, spectral split, Korteweg stress) is
    # computed once per element instead of once per point
    cols = [flat[:, :, k] if k % 3 == 0 else flat[:, :1, k] for k in range(n)]
    return Dual.variables(cols) if dual else cols


def compiled_forms(params, n_fields: int, data: StepData) -> tuple:
    """The compiled kernel of :func:`pointwise_forms` (and :func:`projection_forms`) and its constants.

    The forms are traced on symbols (:mod:`solver.codegen`): per-element arrays (phi0 and the (M,) fields
    of ``data``) and per-point arrays ((M, nq) fields) become inputs, parameters and ``data.dt`` become
    constants; traced once per (params, n_fields, dt), compiled once per structure.
    """
    layout = tuple((f.name, np.ndim(getattr(data, f.name))) for f in fields(StepData)
                   if f.name not in NOT_ELEMENT_DATA and getattr(data, f.name) is not None)

    def build(tr):
        step = StepData(dt=data.dt, **{name: tr.data(name, per_point=nd == 2) for name, nd in layout})
        groups = [(pointwise_forms(tr.inputs(0, n_fields), params, tr.data("phi0", False), step, n_fields), fem.STRANG3)]
        if n_fields == 7:
            groups.append((projection_forms(tr.inputs(1, n_fields)), fem.VERTEX))
        return groups

    return codegen.forms_kernel((params, n_fields, float(data.dt), layout), build)


def element_residuals(disc: Discretization, params, U: np.ndarray, data: StepData, sl: slice, need_jacobian=True,
                      out: tuple | None = None):
    """Element residuals Fe (m, 3, nf) and field-major Jacobians Ke (m, nf, nf, 3, 3) of the elements ``sl``.

    ``out = (Fe, Ke)``: zeroed arrays of those shapes to accumulate into (``Ke`` None without the Jacobian).
    With the numba kernels (:func:`solver.kernels.backend`) the point-wise forms are the compiled trace of
    :func:`compiled_forms`, which writes the non-zero entries (the same values as the Dual path to round-off).
    """
    nf = disc.n_fields
    m = sl.stop - sl.start
    if out is None:
        out = (np.zeros((m, 3, nf)), np.zeros((m, nf, nf, 3, 3)) if need_jacobian else None)
    Fe, Ke = out
    if kernels.backend() == "numba":
        # the same forms, traced once and compiled (solver.codegen): point-wise physics, derivatives and
        # contraction in one pass over the elements, without the GIL
        kern, consts = compiled_forms(params, nf, data)
        step = {f.name: getattr(data, f.name)[sl] for f in fields(StepData)
                if f.name not in NOT_ELEMENT_DATA and getattr(data, f.name) is not None}
        kern(consts, U, disc.triangles[sl], disc.geom.grads[sl], disc.geom.areas[sl], {"phi0": disc.phi0[sl], **step},
             Fe, Ke if need_jacobian else None)
        return Fe, Ke
    U_elem = U[disc.triangles[sl]]
    geom = fem.Geometry(disc.geom.areas[sl], disc.geom.grads[sl])
    X = _variables(U_elem, geom, fem.STRANG3, need_jacobian)
    F = pointwise_forms(X, params, disc.phi0[sl], data.take(sl), nf)
    neq = len(F)
    fem.assemble_forms(F, geom, fem.STRANG3, need_jacobian, nf,
                       out=(Fe[:, :, :neq], Ke[:, :neq] if need_jacobian else None))
    if nf == 7:
        # the two gradient-projection equations fill the last rows of the same arrays
        Xv = _variables(U_elem, geom, fem.VERTEX, need_jacobian)
        fem.assemble_forms(projection_forms(Xv), geom, fem.VERTEX, need_jacobian, nf,
                           out=(Fe[:, :, neq:], Ke[:, neq:] if need_jacobian else None))
    return Fe, Ke


def _element_matrices(disc: Discretization) -> np.ndarray:
    """The element-matrix buffer (M, nf, nf, 3, 3) of ``disc``, made once and reused (its chunks are zeroed by
    :func:`residual_and_jacobian` before each use): at h = 1 mm it holds 37 MB, above the allocator's
    largest heap block (32 MB), so a new array at every assembly would be a fresh memory mapping whose pages
    are faulted in one by one.  Used only inside :func:`residual_and_jacobian`
    (the Jacobian it returns has its own data)."""
    shape = (len(disc.triangles), disc.n_fields, disc.n_fields, 3, 3)
    Ke = disc.workspace.get("element_matrices")
    if Ke is None or Ke.shape != shape:
        Ke = disc.workspace["element_matrices"] = np.empty(shape)
    return Ke


def residual_and_jacobian(disc: Discretization, params, U: np.ndarray, data: StepData, need_jacobian=True):
    """Unconstrained residual (ndof,) and Jacobian (CSR) at nodal state U (N, nf).

    Elements are processed in chunks of a few thousand (``disc.chunks``): the dual-number
    intermediates of a chunk stay in cache, which is faster than whole-mesh arrays, and
    the chunks can run on several threads (:func:`solver.fem.map_chunks`).  Each chunk
    accumulates into its own rows of Fe and Ke, so the result does not depend on the thread count.
    """
    nf = disc.n_fields
    M = len(disc.triangles)
    Fe = np.zeros((M, 3, nf))
    Ke = _element_matrices(disc) if need_jacobian else None

    def work(sl):
        if need_jacobian:
            Ke[sl] = 0.0  # each chunk zeroes its own rows of the reused buffer, on its thread, just before use
        element_residuals(disc, params, U, data, sl, need_jacobian,
                          out=(Fe[sl], Ke[sl] if need_jacobian else None))

    n = paths.assembly_threads()
    fem.map_chunks(work, (disc.chunks or (slice(0, M),)) if n <= 1 else fem.thread_chunks(M, n))
    R = disc.asm.vector(Fe.reshape(M, -1)) + disc.boundary_op @ U.ravel() + disc.inject
    J = None
    if need_jacobian:
        J = disc.asm.matrix_field_major(Ke)
        J.data[disc.boundary_slots] += disc.boundary_vals
    if disc.outlet is not None:
        _add_outlet(disc, params, U, R, J)
    if disc.inner_weights is not None:
        _add_line_storage(disc, params, U, data, R, J)
    return R, J


def line_stored_rate(disc: Discretization, params, U: np.ndarray, data: StepData):
    """The line's storage rate on each inner node (mm²/s, a Dual in the node's p): ∫_Γi N_a ds times
    :func:`solver.physics.line_storage_rate` at the node (lumped on the inlet's nodes; the cavity's pressure is
    uniform, so p = p_inj there)."""
    nodes = disc.inner_nodes
    p_a = ad.Dual.variables([U[nodes, P]])[0]
    rate = physics.line_storage_rate(p_a, data.p_nodal_n[nodes], data.dt, params.line_compliance, disc.inner_length)
    return rate * disc.inner_weights


def _add_line_storage(disc: Discretization, params, U: np.ndarray, data: StepData, R: np.ndarray, J) -> None:
    """Add the line's storage to the inlet's p rows (the pack receives w_i minus it), with its exact derivative;
    with an ``injection`` inlet to its S rows too (the line keeps pumped water, so the pack receives less)."""
    rows = disc.n_fields * disc.inner_nodes + P
    rate = line_stored_rate(disc, params, U, data)
    R[rows] += rate.v
    if J is not None:
        J.data[disc.asm.diag_slot[rows]] += rate.d[:, 0]
    if disc.inner_injection:
        R[disc.n_fields * disc.inner_nodes + S] += rate.v
        if J is not None:
            J.data[disc.inner_sp_slots] += rate.d[:, 0]


# ---------------------------------------------------------------- element fields
def korteweg_force(disc: Discretization, U: np.ndarray, kappa: float) -> np.ndarray:
    """κ ∇·(G⊗G) per element (kPa/mm) from the nodal projected gradient G = U[:, GX:GY+1].

    The same expression the residual uses, (∇·G) G + (∇G) G, here at the centroid.
    """
    tri = disc.triangles
    gradG = fem.field_gradients(disc.geom.grads, U[tri][:, :, GX:GY + 1])  # (M, 2 comps, 2 dirs)
    G = U[tri][:, :, GX:GY + 1].mean(axis=1)
    divG = gradG[:, 0, 0] + gradG[:, 1, 1]
    return kappa * (divG[:, None] * G + np.einsum("mij,mj->mi", gradG, G))


def project_gradient(disc: Discretization, S_nodal: np.ndarray) -> np.ndarray:
    """Lumped L2 projection Π∇S (N, 2) of a nodal field: the solution of the G equations for given S."""
    tri = disc.triangles
    g = fem.element_gradient(S_nodal, tri, disc.geom)
    w = np.repeat(disc.geom.areas / 3.0, 3)
    out = np.empty((disc.n_nodes, 2))
    for c in range(2):
        out[:, c] = np.bincount(tri.ravel(), weights=np.repeat(g[:, c], 3) * w, minlength=disc.n_nodes) / disc.lumped_mass
    return out


def element_fields(disc: Discretization, params, U: np.ndarray, d: np.ndarray, fluxes: bool = True) -> dict:
    """Post-processed element fields at the centroid: φ, ε_v, hoop stress (σ'_θθ, kPa), k (mm²), ψ_A (kPa),
    Cahn–Hilliard mobility M (mm²/(kPa·s)) and, with ``fluxes``, |w_1| (mm/s), all from the same
    :func:`constitutive` as the residual.  ``fluxes=False`` skips the Korteweg force and the Darcy fluxes (the
    per-step measures of the time series read φ and the hoop stress only)."""
    Ue = U[disc.triangles]  # (M, 3, nf), gathered once
    gradU = fem.field_gradients(disc.geom.grads, Ue)
    cen = (Ue[:, 0] + Ue[:, 1] + Ue[:, 2]) / 3.0
    exx, eyy = gradU[:, UX, 0], gradU[:, UY, 1]
    exy = 0.5 * (gradU[:, UX, 1] + gradU[:, UY, 0])
    de = d[disc.triangles]
    c = constitutive(params, disc.phi0, exx, eyy, exy, cen[:, P], cen[:, S], gradU[:, S, 0], gradU[:, S, 1],
                     physics.degradation((de[:, 0] + de[:, 1] + de[:, 2]) / 3.0, params.m))
    out = {"phi": c.phi, "eps_v": exx + eyy, "hoop_stress": _hoop_stress(disc, params, c, cen[:, P]), "k": c.k,
           "psi_a": c.psi_a, "ch_mobility": c.M}
    if fluxes:
        force = None
        if disc.n_fields == 7:
            f = korteweg_force(disc, U, params.kappa * params.korteweg_factor)
            force = (f[:, 0], f[:, 1])
        darcy_fluxes(c, gradU[:, P, 0], gradU[:, P, 1], force)
        out["w1_mag"] = np.hypot(c.w1x, c.w1y)
    return out


def _hoop_stress(disc: Discretization, params, c: Constitutive, p_cen: np.ndarray) -> np.ndarray:
    """Effective hoop stress σ'_θθ = (σ + b p I)_θθ (kPa) at the element centroids, θ the centroid's angle."""
    x = disc.points[disc.triangles]
    xc, yc = (x[:, 0, 0] + x[:, 1, 0] + x[:, 2, 0]) / 3.0, (x[:, 0, 1] + x[:, 1, 1] + x[:, 2, 1]) / 3.0
    r = np.hypot(xc, yc)
    cs = np.divide(xc, r, out=np.ones_like(r), where=r > 0)  # θ = 0 at the origin, as arctan2
    sn = np.divide(yc, r, out=np.zeros_like(r), where=r > 0)
    sxx, syy = c.sxx + params.biot * p_cen, c.syy + params.biot * p_cen
    return sxx * sn * sn + syy * cs * cs - 2 * c.sxy * sn * cs

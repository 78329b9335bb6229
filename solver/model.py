"""The poromechanics block of the model: weak form, residual and exact Jacobian.

Unknowns on P1 nodes (node-major): u_x, u_y (mm), p (kPa), S (-), μ (kPa),
and, when the Korteweg terms are on, the L2-projected saturation gradient
G = Π∇S (1/mm).  Damage d (nodal, -) is frozen here (staggered scheme,
Sec. 3.1) and solved in :mod:`solver.damage`.

Weak form, test functions v (vector), q, r, ϱ, ϑ (Eq. summary_equations and
summary_equations_secondary, backward Euler with step Δt, second-order terms
scaled by the ``volumetric_coupling`` strength c_v):

  momentum      ∫ σ : ∇v  + ∫_Γi p n·v  [+ ∫_Γo u·v / c_o]           = 0
  total mass    ∫ q [(φ − φ_n)/Δt + c_v φ ε̇_v] − ∫ ∇q·w − ∫_Γi q w_i  = 0
  invading      ∫ r [(φS − φ_n S_n)/Δt + c_v φ S ε̇_v] − ∫ ∇r·(w_1 − M∇μ) = 0
  chem. pot.    ∫ ϱ [μ − (12γ/l_S) f'(S)] − (3γ l_S/2) ∫ ∇ϱ·∇S       = 0
  projection    ∫_h ϑ (G − ∇S) = 0   (vertex quadrature: a diagonal mass)

with σ = g(d) ∂ψ_A/∂ε + ∂ψ_I/∂ε − κ ∇S⊗∇S − b p I (Miehe split, plane strain),
φ = φ0 + (1 − φ0) ε_v + (1 − φ0) p/K_s, w_α = −λ_α (∇p + φ⁻¹ κ ∇·(G⊗G)),
λ_α = k(φ) k_rα / η_α, M = k/η̄.  n is the outward normal of the domain: on
the inner circle the total traction is σn = −p n (the injection pressure
loads the skeleton), and the invading fluid enters with Darcy velocity w_i.

The Korteweg force ∇·(κ∇S⊗∇S) contains second derivatives of S, which are
zero inside P1 elements; evaluated element-wise it would silently vanish.
We therefore carry G = Π∇S, the lumped L2 projection of ∇S, as two extra
nodal unknowns (a local equation per node, so the stencil does not widen),
and evaluate ∇·(G⊗G) = (∇·G) G + (∇G) G from its P1 interpolant.  In the
effective stress, which enters the weak form without derivatives, ∇S itself
is used.  κ = 3γl_S/2 follows from the free energy (Eq. fluid_free_energy);
the paper's dimensionless section writes 3γl_S/4, which is inconsistent with it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
import scipy.sparse as sp

from . import ad, codegen, fem, kernels, physics
from .ad import Dual
from .options import TRANSPORTS

UX, UY, P, S, MU, GX, GY = range(7)
FIELD_NAMES = ("ux", "uy", "p", "S", "mu", "Gx", "Gy")


@dataclass(frozen=True)
class Discretization:
    """Everything that depends on the mesh and parameters but not on the state."""

    points: np.ndarray
    triangles: np.ndarray
    geom: fem.Geometry
    asm: fem.BlockAssembler
    n_fields: int
    inner_nodes: np.ndarray
    outer_nodes: np.ndarray
    inner_edges: np.ndarray
    outer_edges: np.ndarray
    phi0: np.ndarray  # (M,)
    boundary_slots: np.ndarray  # CSR slots of the constant boundary couplings, each once
    boundary_vals: np.ndarray  # their values, summed per slot
    boundary_op: sp.csr_matrix  # the same couplings as a matrix (for the residual)
    inject: np.ndarray  # constant residual part (ndof,)
    dirichlet: fem.DirichletRows
    dirichlet_values: np.ndarray
    lumped_mass: np.ndarray  # (N,) mm²
    inner_length: float  # mm
    upwind_length: np.ndarray | None = None  # (M,) mm, h_e/2 with transport = "upwind"; None: Galerkin
    supg_length: np.ndarray | None = None  # (M,) mm, h_e = √(2 A_e) with transport = "supg"; None: no SUPG term
    stab_tau: np.ndarray | None = None  # (M,) mm²/kPa, pressure stabilization τ_e; None: plain Galerkin
    chunks: tuple = ()  # element slices assembled one at a time (see residual_and_jacobian)
    outlet: "Outlet | None" = None  # the outflow condition's rows (outer_saturation_bc = "outflow"); None: off
    inner_weights: np.ndarray | None = None  # ∫_Γi N_a ds (mm) of the inner nodes, with line_compliance; None: off
    # arrays reused by every assembly (by name; see _element_matrices)
    workspace: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def projection_dofs(self) -> np.ndarray | None:
        """Unknowns of the projected gradient G (None without the Korteweg terms).  Their equations are
        local (vertex quadrature), so their Jacobian block is the diagonal lumped mass: a solver may
        eliminate them (solver.linsolve, ``condense``)."""
        if self.n_fields != 7:
            return None
        nodes = np.arange(self.n_nodes) * self.n_fields
        return np.sort(np.concatenate([nodes + GX, nodes + GY]))


def _boundary_couplings(pts, tri, inner_e, outer_e, params, nf: int):
    """The constant boundary couplings (rows, cols, values) and the inner edges' lengths L (mm): the injection
    pressure's load on the skeleton ∫_Γi p n·v, and the outer spring ∫_Γo u·v / c_o when c_o > 0 (mm/kPa)."""
    L, nrm = fem.outward_normals(pts, inner_e, tri)
    loc = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0  # ∫ N_a N_b ds / L
    rows, cols, vals = [], [], []
    for a in range(2):
        for b in range(2):
            w = L * loc[a, b]
            for c in range(2):  # velocity component of the test function
                rows.append(nf * inner_e[:, a] + c)
                cols.append(nf * inner_e[:, b] + P)
                vals.append(w * nrm[:, c])
    if params.outer_compliance > 0:
        Lo, _ = fem.edge_geometry(pts, outer_e)
        for a in range(2):
            for b in range(2):
                for c in range(2):
                    rows.append(nf * outer_e[:, a] + c)
                    cols.append(nf * outer_e[:, b] + c)
                    vals.append(Lo * loc[a, b] / params.outer_compliance)
    rows, cols, vals = (np.concatenate(x) for x in (rows, cols, vals))
    return rows, cols, vals, L


@dataclass(frozen=True)
class Outlet:
    """CSR slots of the outlet condition (``outer_saturation_bc = "outflow"``): for each outer node a, the slots
    of its p row (``src``) and of its S row (``dst``, the same columns in the same order: the block pattern),
    ``owner`` the position of the slot's node in ``nodes``, and ``diag`` the slots (S_a, S_a)."""

    nodes: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    owner: np.ndarray
    diag: np.ndarray


def _outlet(asm: fem.BlockAssembler, outer_n: np.ndarray, nf: int) -> Outlet:
    """The :class:`Outlet` slots of the outer nodes."""
    ptr = asm.indptr.astype(np.int64)
    starts_p, starts_s = ptr[nf * outer_n + P], ptr[nf * outer_n + S]
    counts = ptr[nf * outer_n + P + 1] - starts_p
    owner = np.repeat(np.arange(len(outer_n)), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return Outlet(nodes=outer_n, src=np.repeat(starts_p, counts) + offset, dst=np.repeat(starts_s, counts) + offset,
                  owner=owner, diag=asm.diag_slot[nf * outer_n + S])


def outlet_water_outflow(disc: Discretization, params, U: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Water leaving each outer node (mm²/s), :func:`solver.physics.outlet_water_flux` of the node's S and total
    outflow Q_a = −R_p,a, the reaction of its p = 0 row in the unconstrained residual ``R`` (ndof,)."""
    nf, nodes = disc.n_fields, disc.outlet.nodes
    return physics.outlet_water_flux(U[nodes, S], -R[nf * nodes + P], params.viscosity_ratio)


def _add_outlet(disc: Discretization, params, U: np.ndarray, R: np.ndarray, J) -> None:
    """Add the outlet's water outflow f(S_a) Q_a⁺ to the S rows of the outer nodes (the boundary term
    ∫_Γo r w_1·n of the invading balance, lumped on the nodes); J (or None) gets its exact derivative
    f(S_a) [Q_a > 0] ∂Q_a/∂U + f'(S_a) Q_a⁺ ∂S_a/∂U, with ∂Q_a/∂U = −(the p row of a)."""
    nf, out = disc.n_fields, disc.outlet
    Q = -R[nf * out.nodes + P]
    S_a = ad.Dual.variables([U[out.nodes, S]])[0]
    f = physics.fractional_flow(S_a, params.viscosity_ratio)
    R[nf * out.nodes + S] += f.v * np.maximum(Q, 0.0)
    if J is None:
        return
    J.data[out.dst] -= (f.v * (Q > 0.0))[out.owner] * J.data[out.src]
    J.data[out.diag] += f.d[:, 0] * np.maximum(Q, 0.0)


def _dirichlet_conditions(inner_n, outer_n, params, nf: int):
    """The Dirichlet unknowns (sorted) and their values (Sec. 3.4): S = 1 and μ = μ_i on r_i; p = 0 on r_o, and
    S = 0, μ = μ_o and u = 0 there as the options choose."""
    dofs, values = [], []

    def fix(nodes, field, value):
        dofs.append(nf * nodes + field)
        values.append(np.full(len(nodes), float(value)))

    fix(inner_n, S, 1.0)
    fix(inner_n, MU, params.mu_i)
    fix(outer_n, P, 0.0)
    if params.outer_saturation_bc == "dirichlet":
        fix(outer_n, S, 0.0)
    if params.mu_outer_bc == "dirichlet":
        fix(outer_n, MU, params.mu_o)
    if params.outer_compliance == 0:
        fix(outer_n, UX, 0.0)
        fix(outer_n, UY, 0.0)
    dofs = np.concatenate(dofs)
    values = np.concatenate(values)
    order = np.argsort(dofs)
    return dofs[order], values[order]


def build_discretization(mesh, params, phi0: np.ndarray, transport: str = "galerkin",
                         pressure_stabilization: float | None = None) -> Discretization:
    """Assemble the mesh-dependent operators for ``params`` (units mm, s, kPa).

    ``transport``: "galerkin" (mobilities at the point's saturation), "upwind" (mobilities at the
    saturation shifted upstream by half the element size, see :func:`upwind_saturation`) or "supg" (the
    Galerkin form plus :func:`supg_flux`).
    ``pressure_stabilization``: factor s of :func:`pressure_stabilization_tau` (None or 0: none).
    """
    if transport not in TRANSPORTS:
        raise ValueError(f"transport={transport!r}: allowed one of {TRANSPORTS}")
    pts, tri = np.asarray(mesh.points, float), np.asarray(mesh.triangles)
    n = len(pts)
    nf = 7 if params.korteweg_factor > 0 else 5
    geom = fem.geometry(pts, tri)
    asm = fem.BlockAssembler(tri, n, nf)
    inner_e = np.asarray(mesh.boundary_edges["inner"])
    outer_e = np.asarray(mesh.boundary_edges["outer"])
    inner_n = np.unique(inner_e)
    outer_n = np.unique(outer_e)

    rows, cols, vals, L = _boundary_couplings(pts, tri, inner_e, outer_e, params, nf)
    op = sp.csr_matrix((vals, (rows, cols)), shape=(asm.ndof, asm.ndof))
    slots = asm.slots(rows, cols)

    inject = np.zeros(asm.ndof)
    inject[P::nf] = -fem.edge_load(pts, inner_e, n, params.w_i)
    dofs, values = _dirichlet_conditions(inner_n, outer_n, params, nf)
    lumped = np.bincount(tri.ravel(), weights=np.repeat(geom.areas / 3, 3), minlength=n)
    slots, inverse = np.unique(slots, return_inverse=True)  # one value per slot: J.data[slots] += vals
    vals = np.bincount(inverse.ravel(), weights=vals, minlength=len(slots))
    return Discretization(
        points=pts, triangles=tri, geom=geom, asm=asm, n_fields=nf,
        inner_nodes=inner_n, outer_nodes=outer_n, inner_edges=inner_e, outer_edges=outer_e,
        phi0=np.asarray(phi0, float), boundary_slots=slots, boundary_vals=vals, boundary_op=op,
        inject=inject, dirichlet=asm.dirichlet_rows(dofs), dirichlet_values=values,
        lumped_mass=lumped, inner_length=float(L.sum()), chunks=fem.element_chunks(len(tri)),
        upwind_length=0.5 * np.sqrt(2.0 * geom.areas) if transport == "upwind" else None,
        supg_length=np.sqrt(2.0 * geom.areas) if transport == "supg" else None,
        stab_tau=pressure_stabilization_tau(pts, tri, params, phi0, pressure_stabilization),
        outlet=_outlet(asm, outer_n, nf) if params.outer_saturation_bc == "outflow" else None,
        inner_weights=fem.edge_load(pts, inner_e, n, 1.0)[inner_n] if params.line_compliance > 0 else None,
    )


def pressure_stabilization_tau(pts, tri, params, phi0, factor: float | None):
    """τ_e = s b (1 − φ0) h_e² / (4 (λ + 2μ)) per element, mm²/kPa (None when s is None or 0).

    The equal-order P1 / P1 pair of (u, p) is not inf-sup stable in the undrained limit
    k Δt / η ≪ h² / (λ + 2μ); there the pressure oscillates from node to node (Murad and Loula 1994).
    The perturbation τ_e ∫ ∇q·∇(p − p_n)/Δt of the mass balance (Aguilar et al. 2008) with
    τ = α_m α_f h² / (4 (λ + 2μ)) (Rodrigo et al. 2016, the coupling coefficients of the momentum balance,
    b, and of the mass balance, 1 − φ0 in φ = φ0 + (1 − φ0)(ε_v + p/K_s)) removes them; it vanishes as
    O(h²) ∂p/∂t.  h_e is the element's longest edge (mm); λ + 2μ the undamaged P-wave modulus (kPa).
    """
    if not factor:
        return None
    e = pts[tri[:, [1, 2, 0]]] - pts[tri]
    h2 = np.max(np.sum(e * e, axis=2), axis=1)
    p_modulus = params.lame_lambda + 2.0 * params.lame_mu
    return factor * params.biot * (1.0 - np.asarray(phi0, float)) * h2 / (4.0 * p_modulus)


@dataclass(frozen=True)
class StepData:
    """Data of the previous time step seen by the poromechanics residual."""

    dt: float  # s
    d_q: np.ndarray  # damage at quadrature points (M, nq), frozen
    phi_n: np.ndarray  # porosity at quadrature points (M, nq)
    S_n: np.ndarray  # saturation at quadrature points (M, nq)
    ev_n: np.ndarray  # volumetric strain per element (M,)
    up_x: np.ndarray | None = None  # upwind shift per element (M,), mm (None: Galerkin transport)
    up_y: np.ndarray | None = None
    tau: np.ndarray | None = None  # pressure stabilization τ_e per element (M,), mm²/kPa (None: none)
    px_n: np.ndarray | None = None  # previous pressure gradient per element (M,), kPa/mm (with tau)
    py_n: np.ndarray | None = None
    supg_h: np.ndarray | None = None  # element size h_e per element (M,), mm, with transport = "supg"
    gap_n: np.ndarray | None = None  # previous gap storage δ/h at quadrature points (M, nq), with cell_compliance
    p_nodal_n: np.ndarray | None = None  # previous nodal pressure (N,), kPa, with line_compliance (not element data)

    def take(self, sl: slice) -> "StepData":
        """The same data restricted to the elements of ``sl`` (views, no copies)."""
        cut = lambda a: None if a is None else a[sl]
        return StepData(dt=self.dt, d_q=self.d_q[sl], phi_n=self.phi_n[sl], S_n=self.S_n[sl], ev_n=self.ev_n[sl],
                        gap_n=cut(self.gap_n), p_nodal_n=self.p_nodal_n,
                        up_x=cut(self.up_x), up_y=cut(self.up_y), tau=cut(self.tau), px_n=cut(self.px_n),
                        py_n=cut(self.py_n), supg_h=cut(self.supg_h))


# the fields of StepData that are not per-element arrays (the compiled forms and the element chunks skip them)
_NOT_ELEMENT_DATA = ("dt", "p_nodal_n")


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


@dataclass
class Constitutive:
    """The constitutive chain at a set of points (one definition for the residual, Jacobian and outputs).

    Units: φ (-), stresses kPa (σ' effective, total = σ' − b p I), k mm², mobilities mm²/(kPa·s),
    Darcy fluxes mm/s, ψ_A kPa.
    """

    phi: object
    sxx: object  # total stress σ = σ' − b p I, kPa
    syy: object
    sxy: object
    psi_a: object
    k: object
    lam1: object
    lam2: object
    w1x: object
    w1y: object
    wx: object
    wy: object
    M: object
    yx: object = None  # the Darcy drive ∇p + φ⁻¹ κ ∇·(∇S⊗∇S), kPa/mm (filled by darcy_fluxes)
    yy: object = None


def upwind_saturation(Sat, Sx, Sy, up_x, up_y):
    """S shifted upstream by the vector (up_x, up_y) (mm, :func:`upwind_shift`): S + up·∇S.

    Evaluating the phase mobilities at this saturation upwinds the convective transport of S (first-order
    streamline upwinding of the fractional flow, artificial diffusion of about |v_S| h_e/2 along the flow);
    it tends to S as h -> 0.
    """
    return Sat + up_x * Sx + up_y * Sy


def supg_flux(c: Constitutive, params, Sat, Sx, Sy, accumulation, h_e, dt: float):
    """The SUPG term of the invading-fluid balance as a flux (mm/s) tested with ∇r: τ v R (Brooks and Hughes 1982).

    The balance ∂(φS)/∂t + c_v φ S ε̇_v + ∇·w_1 − ∇·(M∇μ) = 0 transports S with the velocity
    v = (∂λ_1/∂S)(−Y)/φ (mm/s, Y = c.yx, c.yy the Darcy drive), since ∇·w_1 = φ v·∇S + ... within an element.
    R = accumulation + φ v·∇S (1/s) is its strong residual on a P1 element: ``accumulation`` is the time and
    volumetric-coupling part; the Cahn–Hilliard flux's divergence (second derivatives of μ, zero on P1) and the
    ∇k, ∇φ parts of ∇·w_1 are left out.  Tested with τ (v·∇r), τ = [(2/Δt)² + (2|v|/h_e)²]^(−1/2) (s; the
    transient form of Tezduyar and Osawa 2000), it adds diffusion τ v⊗v along the flow only where R ≠ 0.  R
    vanishes for the exact solution up to the parts left out, so the term is consistent to O(h_e) and tends to
    zero as h_e -> 0.  Being a flux in divergence form, it keeps the discrete volume balance.  ``h_e`` (mm) per
    element, shaped to broadcast against the points.
    """
    slope = physics.invading_permeability_slope(Sat, params.viscosity_ratio)
    dlam = c.k * slope / params.eta_w
    vx, vy = -dlam * c.yx / c.phi, -dlam * c.yy / c.phi
    root = ad.sqrt if isinstance(vx, Dual) else np.sqrt
    rate = 2.0 * root(vx * vx + vy * vy + 1e-24) / h_e  # 2|v|/h_e, 1/s (smooth at v = 0)
    tau = 1.0 / root((2.0 / dt) ** 2 + rate * rate)
    res = accumulation + c.phi * (vx * Sx + vy * Sy)
    return tau * vx * res, tau * vy * res


def constitutive(params, phi0, exx, eyy, exy, p, Sat, Sx, Sy, gd, S_flow=None) -> Constitutive:
    """Porosity, stress, permeability, mobilities, Darcy fluxes and Cahn–Hilliard mobility (Sec. 2.9).

    Strains exx, eyy, exy (-), pressure p (kPa), saturation S and its gradient (1/mm), degradation g(d) (-);
    ``S_flow``: the saturation the phase mobilities see (default S; upwind transport:
    :func:`upwind_saturation`).  Numpy arrays, Duals or traced symbols alike.  The Darcy fluxes follow
    from :func:`darcy_fluxes`.

    * φ = φ0 + (1 − φ0) ε_v + (1 − φ0) p/K_s (Eq. summary_equations_3), with the optional porosity floor and
      ceiling;
    * k from :func:`solver.physics.permeability` (Eq. permeability), with the optional permeability floor;
    * σ = g(d) σ_A + σ_I − κ ∇S⊗∇S − b p I with Miehe's split (Eq. summary_equations_4, _secondary_3);
    * w_α = −λ_α (∇p + φ⁻¹ κ ∇·(∇S⊗∇S)), λ_α = k k_rα/η_α (Eq. fluid_equation);
    * M from :func:`solver.physics.ch_mobility` (Sec. 2.8, option ``ch_mobility``).
    """
    kap = params.kappa * params.korteweg_factor
    phi = physics.porosity(phi0, exx + eyy, p, params.K_s, params.porosity_floor, params.porosity_ceiling)
    (ax, ay, axy), (ex, ey, exy_s), psi_a = physics.spectral_split(exx, eyy, exy, params.lame_lambda, params.lame_mu)
    deg = gd - 1.0  # σ' = σ_elastic + (g − 1) σ_A
    sxx = ex + ax * deg - params.biot * p
    syy = ey + ay * deg - params.biot * p
    sxy = exy_s + axy * deg
    if kap > 0:
        sxx = sxx - kap * Sx * Sx
        syy = syy - kap * Sy * Sy
        sxy = sxy - kap * Sx * Sy
    k = physics.permeability(phi, phi0, params.kbar, params.k_max, params.crack_permeability,
                             params.permeability_floor)
    if params.cell_compliance > 0:  # the opened gap above the pack carries both fluids in parallel
        k = k + physics.gap_permeability(p, params.cell_compliance, params.cell_height)
    kr1, kr2 = physics.relative_permeabilities(Sat if S_flow is None else S_flow, params.viscosity_ratio)
    lam1 = k * kr1 / params.eta_w
    lam2 = k * kr2 / params.eta_o
    return Constitutive(phi=phi, sxx=sxx, syy=syy, sxy=sxy, psi_a=psi_a, k=k, lam1=lam1, lam2=lam2,
                        w1x=None, w1y=None, wx=None, wy=None,
                        M=physics.ch_mobility(k, Sat, params.eta_o, params.eta_w, params.ch_mobility))


def darcy_fluxes(c: Constitutive, px, py, force=None) -> Constitutive:
    """Fill the Darcy fluxes w_1, w = w_1 + w_2 (mm/s) of ``c`` from ∇p (kPa/mm) and the Korteweg force."""
    Yx, Yy = px, py
    if force is not None:
        Yx = Yx + force[0] / c.phi
        Yy = Yy + force[1] / c.phi
    c.yx, c.yy = Yx, Yy
    c.w1x, c.w1y = -c.lam1 * Yx, -c.lam1 * Yy
    lam = c.lam1 + c.lam2
    c.wx, c.wy = -lam * Yx, -lam * Yy
    return c


def pointwise_forms(X: list, params, phi0: np.ndarray, data: StepData, n_fields: int) -> list:
    """f0/f1 of the five equations at the Strang points: ``F[i][k]`` (M, nq), None = structural zero.

    ``X[3 f + k]`` is field f's value (k = 0) or gradient component (k = 1, 2).
    """
    g = lambda f, k: X[3 * f + k]
    kap = params.kappa * params.korteweg_factor
    cv = params.volumetric_coupling
    dt = data.dt

    exx, eyy = g(UX, 1), g(UY, 2)
    exy = 0.5 * (g(UX, 2) + g(UY, 1))
    ev = exx + eyy
    p, Sat, mu = g(P, 0), g(S, 0), g(MU, 0)
    Sx, Sy = g(S, 1), g(S, 2)
    S_flow = None
    if data.up_x is not None:
        S_flow = upwind_saturation(Sat, Sx, Sy, data.up_x[:, None], data.up_y[:, None])
    c = constitutive(params, phi0[:, None], exx, eyy, exy, p, Sat, Sx, Sy,
                     physics.degradation(data.d_q, params.m), S_flow)
    force = None
    if n_fields == 7:
        # κ ∇·(G⊗G) = κ ((∇·G) G + (∇G) G) from the projected gradient G = Π∇S
        Gx, Gy = g(GX, 0), g(GY, 0)
        divG = g(GX, 1) + g(GY, 2)
        force = (kap * (divG * Gx + g(GX, 1) * Gx + g(GX, 2) * Gy),
                 kap * (divG * Gy + g(GY, 1) * Gx + g(GY, 2) * Gy))
    darcy_fluxes(c, g(P, 1), g(P, 2), force)
    phi = c.phi

    dev = (ev - data.ev_n[:, None]) / dt
    c_mu = 12.0 * params.gamma / params.l_S
    c_grad = c_mu * params.l_S**2 / 8.0
    fx, fy = -c.wx, -c.wy
    f1x, f1y = -c.w1x + c.M * g(MU, 1), -c.w1y + c.M * g(MU, 2)
    if data.tau is not None:  # pressure stabilization τ ∇(p − p_n)/Δt (see pressure_stabilization_tau)
        sx = data.tau[:, None] * (g(P, 1) - data.px_n[:, None]) / dt
        sy = data.tau[:, None] * (g(P, 2) - data.py_n[:, None]) / dt
        frac = c.lam1 / (c.lam1 + c.lam2 + 1e-300)
        fx, fy = fx + sx, fy + sy
        f1x, f1y = f1x + frac * sx, f1y + frac * sy
    store, store_n = phi, data.phi_n  # the storage: the pores, and the gap of an elastic cell
    if data.gap_n is not None:
        store = phi + physics.gap_storage(p, params.cell_compliance, params.cell_height)
        store_n = data.phi_n + data.gap_n
    invading = (store * Sat - store_n * data.S_n) / dt + cv * phi * Sat * dev
    if data.supg_h is not None:
        sx, sy = supg_flux(c, params, Sat, Sx, Sy, invading, data.supg_h[:, None], dt)
        f1x, f1y = f1x + sx, f1y + sy
    return [
        [None, c.sxx, c.sxy],
        [None, c.sxy, c.syy],
        [(store - store_n) / dt + cv * phi * dev, fx, fy],
        [invading, f1x, f1y],
        [mu - c_mu * physics.double_well_prime(Sat), -c_grad * Sx, -c_grad * Sy],
    ]


def projection_forms(X: list) -> list:
    """f0 of the gradient projection G − ∇S at the vertex points (two equations)."""
    g = lambda f, k: X[3 * f + k]
    return [[g(GX, 0) - g(S, 1), None, None], [g(GY, 0) - g(S, 2), None, None]]


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
                   if f.name not in _NOT_ELEMENT_DATA and getattr(data, f.name) is not None)

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
                if f.name not in _NOT_ELEMENT_DATA and getattr(data, f.name) is not None}
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

    n = fem.assembly_threads()
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
    """Add the line's storage to the inlet's p rows (the pack receives w_i minus it), with its exact derivative."""
    rows = disc.n_fields * disc.inner_nodes + P
    rate = line_stored_rate(disc, params, U, data)
    R[rows] += rate.v
    if J is not None:
        J.data[disc.asm.diag_slot[rows]] += rate.d[:, 0]


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

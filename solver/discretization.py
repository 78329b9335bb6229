"""The discretized problem: the mesh-dependent operators, boundary conditions and Dirichlet rows (units mm, s, kPa).

:func:`build_discretization` gathers what depends on the mesh and the parameters but not on the state: the element
geometry and the block pattern (:mod:`solver.fem`), the constant boundary couplings of the inner and outer circles,
the injection load, the Dirichlet unknowns of Sec. 3.4, the outlet's slots (``outer_saturation_bc = "outflow"``), the
transport's element lengths and the pressure stabilization.  :mod:`solver.model` assembles the residual on it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from . import fem
from .forms import GX, GY, MU, P, S, UX, UY
from .options import TRANSPORTS

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
    inner_injection: bool = False  # the inlet feeds the invading balance w_i (inner_saturation_bc = "injection")
    inner_sp_slots: np.ndarray | None = None  # CSR slots (S row, p column) of the inner nodes: injection with the line
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


def _dirichlet_conditions(inner_n, outer_n, params, nf: int):
    """The Dirichlet unknowns (sorted) and their values (Sec. 3.4): S = 1 and μ = μ_i on r_i (unless the inlet is
    an ``injection`` one, where S and μ are free); p = 0 on r_o, and S = 0, μ = μ_o and u = 0 there as the options
    choose."""
    dofs, values = [], []

    def fix(nodes, field, value):
        dofs.append(nf * nodes + field)
        values.append(np.full(len(nodes), float(value)))

    if params.inner_saturation_bc == "dirichlet":
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
    if params.inner_saturation_bc == "injection":  # ∫_Γi q w_1·n ds with w_1·n = −w_i: all the pumped fluid is water
        inject[S::nf] = inject[P::nf]
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
        inner_injection=params.inner_saturation_bc == "injection",
        inner_sp_slots=(asm.slots(nf * inner_n + S, nf * inner_n + P)
                        if params.inner_saturation_bc == "injection" and params.line_compliance > 0 else None),
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

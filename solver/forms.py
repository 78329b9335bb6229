"""The weak form, written once and point-wise: the constitutive chain and the coefficients of the five equations.

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

The functions take numpy arrays, :class:`solver.ad.Dual` arrays or traced symbols (:mod:`solver.tracer`) alike: the
reference path, the exact Jacobian and the compiled kernels (:mod:`solver.codegen`) evaluate the same forms.
:mod:`solver.model` assembles them over the mesh.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import ad, physics
from .ad import Dual

UX, UY, P, S, MU, GX, GY = range(7)
FIELD_NAMES = ("ux", "uy", "p", "S", "mu", "Gx", "Gy")


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
NOT_ELEMENT_DATA = ("dt", "p_nodal_n")


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
    slope = physics.invading_permeability_slope(Sat, params.viscosity_ratio, params.critical_saturation)
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
    * w_α = −λ_α (∇p + φ⁻¹ κ ∇·(∇S⊗∇S)), λ_α = k k_rα/η_α (Eq. fluid_equation; k_rα with the critical
      saturation ``critical_saturation``);
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
    kr1, kr2 = physics.relative_permeabilities(Sat if S_flow is None else S_flow, params.viscosity_ratio,
                                               params.critical_saturation)
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

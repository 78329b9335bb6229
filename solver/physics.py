"""Constitutive laws of the Darcy–Cahn–Hilliard–damage model, one function per term.

Each function is point-wise and works on numpy arrays and on
:class:`solver.ad.Dual` numbers alike (so the Newton Jacobian is exact).
Units: mm, s, kPa.  Equation names refer to Guevel et al. (JMPS).
"""
from __future__ import annotations

import numpy as np

from . import ad
from .ad import Dual


# ---------------------------------------------------------------- porosity
def porosity(phi0, eps_v, p, K_s: float, floor: float | None = None, ceiling: float | None = None):
    """φ = φ0 + (1 − φ0) ε_v + (1 − φ0) p / K_s  (Eq. summary_equations_3), bounded below by
    :func:`porosity_floor` when ``floor`` is given (the ``porosity_floor`` parameter) and above by
    :func:`porosity_ceiling` when ``ceiling`` is given (the ``porosity_ceiling`` parameter); None: the paper's
    law, unbounded both ways.

    ``phi0`` per element (dimensionless), ``eps_v`` volumetric strain, ``p`` kPa, ``K_s`` kPa.
    """
    phi = phi0 + (1.0 - phi0) * eps_v + (1.0 - phi0) * p / K_s
    if floor is not None:
        phi = porosity_floor(phi, floor)
    return phi if ceiling is None else porosity_ceiling(phi, ceiling)


def porosity_floor(phi, floor: float):
    """Smooth lower bound φ_f > 0 of the porosity: φ for φ >= φ_f, φ_f² / (2 φ_f − φ) below.

    The linear law of Eq. summary_equations_3 has no lower bound: under compaction it reaches φ <= 0, where
    the pores are closed (k = 0) and the invading-fluid balance ∂(φS)/∂t has no capacity.  Below φ_f this
    branch keeps φ positive and decreasing to 0 as the linear value goes to −∞: the grains come into contact
    and the pore space stiffens.  Value and slope match at φ_f (C¹), so Newton keeps its convergence.
    """
    return smooth_floor(phi, floor)


def porosity_ceiling(phi, onset: float):
    """Smooth upper bound 1 of the porosity from the onset φ_c < 1: φ for φ <= φ_c, and above it
    1 − (1 − φ_c)² / (2 (1 − φ_c) − (1 − φ)), which rises to 1 as the linear value goes to +∞.

    The linear law of Eq. summary_equations_3 has no upper bound: in the dilated cracks it exceeds 1
    (results/porosity_ceiling_h2/README.md), so the crack stores more fluid than the open gap holds (φ S, φ ε̇_v)
    and the Korteweg force divides by that φ.  A volume fraction is at most 1: this is :func:`smooth_floor` mirrored
    about 1 (applied to 1 − φ with the floor 1 − φ_c), value and slope continuous at φ_c.  Above the
    Kozeny–Carman cap porosity φ* the permeability is k_max whatever φ, so the bound changes the storage and the
    Korteweg term, not the flow.  Not the paper's model (which states no bound): an option.  Exactly φ at and
    below the onset (written out rather than through smooth_floor, whose 1 − (1 − φ) would round φ).
    """
    delta = 1.0 - onset
    above = ad.value(phi) > onset
    if isinstance(phi, Dual):
        safe = ad.where(above, phi, onset)
        return ad.where(above, 1.0 - delta * delta / (2.0 * delta - (1.0 - safe)), phi)
    safe = np.where(above, phi, onset)  # the unused branch, at the onset, stays finite where 2δ − (1 − φ) = 0
    return np.where(above, 1.0 - delta * delta / (2.0 * delta - (1.0 - safe)), phi)


def smooth_floor(x, floor: float):
    """x for x >= floor > 0, floor² / (2 floor − x) below: C¹ at the floor, positive, and decreasing to 0 as
    x goes to −∞ (at x = 0 it is floor / 2).  The one form of the porosity and permeability floors."""
    v = ad.value(x)
    below = v < floor
    if isinstance(x, Dual):
        safe = ad.where(below, x, floor)
        return ad.where(below, floor * floor / (2.0 * floor - safe), x)
    safe = np.where(below, x, floor)  # the unused branch stays finite where x >= 2 floor
    return np.where(below, floor * floor / (2.0 * floor - safe), x)


def kozeny_carman(phi, kbar: float, k_max: float):
    """k(φ) = φ³/(1 − φ)² k̄ capped at k_max = h²/12 (Eq. permeability), mm².

    The cap is reached at the porosity φ* where the Kozeny–Carman law equals
    k_max; for φ >= φ* (including φ >= 1, where the law diverges) k = k_max,
    the Poiseuille permeability of the open Hele-Shaw gap.
    """
    phi_star = cap_porosity(kbar, k_max)
    v = ad.value(phi)
    below = v < phi_star
    closed = v <= 0.0  # linear poroelasticity can drive φ below 0 under strong compression: pores closed, k = 0
    mid = below & ~closed
    safe = ad.where(mid, phi, 0.5 * phi_star) if isinstance(phi, Dual) else np.where(mid, phi, 0.5 * phi_star)
    kc = safe**3 / (1.0 - safe) ** 2 * kbar
    if isinstance(phi, Dual):
        return ad.where(closed, 0.0, ad.where(below, kc, k_max))
    return np.where(closed, 0.0, np.where(below, kc, k_max))


def cap_porosity(kbar: float, k_max: float) -> float:
    """Porosity φ* in (0, 1) at which φ³/(1 − φ)² k̄ = k_max (monotone, bisection)."""
    lo, hi = 0.0, 1.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if mid**3 / (1 - mid) ** 2 * kbar < k_max:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def permeability(phi, phi0, kbar: float, k_max: float, crack_permeability: float = 1.0,
                 floor: float | None = None):
    """Absolute permeability (mm²) with the ``crack_permeability`` effect strength s and the optional floor.

    k = k(φ0) + s (k(φ) − k(φ0)): s = 1 is the paper's model, s = 0 freezes the
    permeability at its initial value (no flow enhancement by opening cracks).  With ``floor`` (the
    ``permeability_floor`` parameter, mm²; None: the paper's law) k is bounded below by
    :func:`permeability_floor`.
    """
    k = kozeny_carman(phi, kbar, k_max)
    if crack_permeability != 1.0:
        k0 = kozeny_carman(phi0, kbar, k_max)
        k = k0 + crack_permeability * (k - k0)
    return k if floor is None else permeability_floor(k, floor)


def permeability_floor(k, floor: float):
    """Smooth lower bound k_f > 0 of the permeability (mm²): k for k >= k_f, k_f² / (2 k_f − k) below.

    Under the compaction of the drained, rigid outer wall the porosity law closes the pores of the wall's
    element row (φ -> 0, so Kozeny–Carman k -> 0) and the row seals the layer.  The floor keeps a path for the
    fluid through such a row: at closed pores k = k_f / 2.  Not the paper's model (which states no bound):
    an option to test what the seal does.  C¹ at k_f, like :func:`porosity_floor`.
    """
    return smooth_floor(k, floor)


def cell_gap(p, compliance: float):
    """Opening δ = c_cell p⁺ (mm) of the gap between the cell's plates and the bead pack, under the local pore
    pressure p (kPa), compliance c_cell (mm/kPa): the elastic Hele–Shaw cell (Pihler-Puzović et al., Phys. Rev.
    Lett. 108, 074502, 2012), the plates bowing locally with the pressure (a Winkler foundation); p <= 0 opens
    nothing (derivative 0 there)."""
    pp = ad.positive_part(p) if isinstance(p, Dual) else np.maximum(p, 0.0)
    return compliance * pp


def gap_storage(p, compliance: float, cell_height: float):
    """Fluid volume in the opened gap per unit pack volume, δ/h (-) with δ = :func:`cell_gap`, h the cell height
    (mm): the gap's storage, added to φ in the time derivatives of both mass balances."""
    return cell_gap(p, compliance) / cell_height


def gap_permeability(p, compliance: float, cell_height: float):
    """Transmissivity of the opened gap per unit cell height, δ³/(12 h) (mm²): plane Poiseuille flow in a slit
    of width δ (flux −δ³/(12η) ∇p per unit length) spread over the cell height h; it acts in parallel with the
    pack's k, and both fluids flow through it with the pack's relative permeabilities."""
    d = cell_gap(p, compliance)
    return d * d * d / (12.0 * cell_height)


def line_storage_rate(p, p_n, dt: float, line_compliance: float, inner_length: float):
    """Flux density (mm/s) the injection line and cavity keep from the pack on r_i: (C_line/L_i) (p − p_n)/Δt,
    backward Euler of C_line ∂p_inj/∂t spread over the inlet's length L_i (mm); C_line (mm²/kPa per unit cell
    height) is the line's lumped compliance, p, p_n (kPa) the inlet pressure now and at the last step.  The pack
    receives w_i minus this: the pump's volume goes partly into the line's storage while the pressure rises."""
    return line_compliance / inner_length * (p - p_n) / dt


def _saturation_in_bounds(S):
    """S clipped to [0, 1] (derivative zero outside): the saturation the relative-permeability and degenerate
    mobility laws see (Duals, arrays or traced symbols)."""
    return ad.clip(S, 0.0, 1.0) if isinstance(S, Dual) else np.clip(S, 0.0, 1.0)


def _reduced_saturation(Sc, S_c: float):
    """The water's mobile share (S − S_c)/(1 − S_c) of an in-bounds saturation ``Sc``, clipped to [0, 1] (-);
    ``Sc`` itself when S_c = 0 (the paper)."""
    return Sc if S_c <= 0.0 else _saturation_in_bounds((Sc - S_c) / (1.0 - S_c))


def relative_permeabilities(S, M: float, S_c: float = 0.0):
    """Fourar–Lenormand k_r1(S), k_r2(1 − S) (Eq. relative_permeabilities).

    Phase 1 (S) is the invading water, M = η_o/η_w the viscosity ratio.  S is
    clipped to [0, 1] inside these laws only: the Cahn–Hilliard saturation
    overshoots its bounds by a few percent near the interface, and outside
    [0, 1] the cubic laws turn negative, which would give negative mobility.

    ``S_c`` (parameter ``critical_saturation``, -): the water is immobile below it and k_r1 is the same law of
    the reduced saturation S_e = (S − S_c)/(1 − S_c); k_r2 is unchanged.  The paper's law (S_c = 0) carries
    the water at M k_r1 ≈ 1.5 S + M S³, so at M ~ 1e5 a few percent of water outruns the oil through the whole
    pack; a critical saturation is the pore-scale fact that the invading phase needs a connected path.
    """
    Sc = _saturation_in_bounds(S)
    S1 = _reduced_saturation(Sc, S_c)
    S2 = 1.0 - Sc
    kr1 = S1**3 + (1.5 / M) * S1 * (1.0 - S1) * (1.0 + S1)
    kr2 = 0.5 * S2 * S2 * (3.0 - S2)
    return kr1, kr2


def invading_permeability_slope(S, M: float, S_c: float = 0.0):
    """dk_r1/dS of :func:`relative_permeabilities` (-), [3S_e² + (1.5/M)(1 − 3S_e²)]/(1 − S_c) at the reduced
    saturation S_e clipped to [0, 1]: continuous in S (outside the mobile range it keeps its value at the
    bound).  The speed of the saturation's convective transport is proportional to it."""
    Se = _reduced_saturation(_saturation_in_bounds(S), S_c)
    return (3.0 * Se * Se + (1.5 / M) * (1.0 - 3.0 * Se * Se)) / (1.0 - S_c)


# ---------------------------------------------------------------- Cahn–Hilliard
def fractional_flow(S, M: float, S_c: float = 0.0):
    """Water's share f = λ_1/(λ_1 + λ_2) = M k_r1 / (M k_r1 + k_r2) of the total Darcy flux (-), M = η_o/η_w
    (Eq. relative_permeabilities; the absolute permeability cancels; ``S_c`` the critical saturation).
    f(S <= S_c) = 0, f(S >= 1) = 1."""
    kr1, kr2 = relative_permeabilities(S, M, S_c)
    return M * kr1 / (M * kr1 + kr2)


def outlet_water_flux(S, Q, M: float, S_c: float = 0.0):
    """Water leaving an outlet node (mm²/s per unit cell height): f(S) Q⁺, upwinded from inside the domain.

    ``Q`` (mm²/s) is the node's total outflow, the reaction of its p = 0 condition (Sec. 3.4); where it runs
    out, each phase leaves with its own Darcy flux, so water leaves in the share :func:`fractional_flow` of the
    node's saturation S; where it runs in, the outlet reservoir's oil (S = 0) enters and no water.  Before the
    front reaches the node S = 0 and f = 0: no water leaves.
    """
    return fractional_flow(S, M, S_c) * np.maximum(Q, 0.0)


def harmonic_viscosity(eta_o: float, eta_w: float) -> float:
    """η̄ = 2 η_o η_w / (η_o + η_w), kPa·s: the harmonic mean of Cogswell and Szulczewski (Sec. 2.8)."""
    return 2.0 * eta_o * eta_w / (eta_o + eta_w)


def ch_mobility(k, S, eta_o: float, eta_w: float, law: str = "harmonic"):
    """Cahn–Hilliard mobility M, mm²/(kPa·s), of the flux h = −M∇μ (Eq. solution_dissipation_inequality_4).

    ``law``:

    * "harmonic" (the paper): M = k/η̄ with the harmonic mean η̄ of the two viscosities.  At
      η_w/η_o = 3.4e-6, η̄ ≈ 2η_w and M is about 1.5e5 times the defending fluid's Darcy mobility k/η_o.
    * "oil": M = k/η_o, the mobility of the slower, defending fluid, which limits the counter-current
      exchange h_1 = −h_2 that the Cahn–Hilliard flux describes.
    * "degenerate": M = 4 S(1 − S) k/η̄ (S clipped to [0, 1]): the paper's value at the interface centre,
      zero in both pure phases, so the Cahn–Hilliard flux acts only inside the diffuse interface
      (the usual degenerate mobility of Cahn–Hilliard models of two-phase flow).

    ``k`` permeability (mm²), ``S`` saturation (-), viscosities kPa·s.
    """
    if law == "harmonic":
        return k / harmonic_viscosity(eta_o, eta_w)
    if law == "oil":
        return k / eta_o
    if law == "degenerate":
        Sc = _saturation_in_bounds(S)
        return 4.0 * Sc * (1.0 - Sc) * k / harmonic_viscosity(eta_o, eta_w)
    raise ValueError(f"ch_mobility law {law!r}: allowed 'harmonic', 'oil', 'degenerate'")


def double_well_prime(S):
    """f'(S) for f = S²(1 − S)²: 2S(1 − S)(1 − 2S)."""
    return 2.0 * S * (1.0 - S) * (1.0 - 2.0 * S)


def double_well(S):
    return S * S * (1.0 - S) * (1.0 - S)


# ---------------------------------------------------------------- elasticity
def spectral_split(exx, eyy, exy, lam: float, mu: float):
    """Miehe's spectral split in plane strain (Eq. spectral_decomposition).

    Returns the active stress ∂ψ_A/∂ε as (sxx, syy, sxy), the total elastic
    stress C:ε as (sxx, syy, sxy) (so the inactive part is their difference),
    and ψ_A (kPa).  Principal strains e1,2 = m ± r, m = ε_v/2,
    r = sqrt(((εxx − εyy)/2)² + εxy²); ε3 = 0 contributes nothing.
    <ε>_+ = ½(<e1> + <e2>) I + c D with D = ε − m I and c = (<e1> − <e2>)/(2r),
    whose limit for r -> 0 is the Heaviside H(m): no division by zero at
    equal principal strains.
    """
    is_dual = isinstance(exx, Dual)
    pp = ad.positive_part if is_dual else (lambda x: np.maximum(x, 0.0))
    ev = exx + eyy
    m = 0.5 * ev
    dxx = 0.5 * (exx - eyy)
    r2 = dxx * dxx + exy * exy
    r2v = ad.value(r2)
    tol = 1e-14
    big = r2v > tol * tol
    if is_dual:
        rsafe = ad.sqrt(ad.where(big, r2, 1.0))
    else:
        rsafe = np.sqrt(np.where(big, r2, 1.0))
    e1p = pp(m + rsafe)
    e2p = pp(m - rsafe)
    mv = ad.value(m)
    heav = np.where(mv > 0, 1.0, 0.0)
    if is_dual:
        c = ad.where(big, (e1p - e2p) / (2.0 * rsafe), heav)
        e1p = ad.where(big, e1p, pp(m))
        e2p = ad.where(big, e2p, pp(m))
    else:
        c = np.where(big, (e1p - e2p) / (2.0 * rsafe), heav)
        e1p = np.where(big, e1p, pp(m))
        e2p = np.where(big, e2p, pp(m))
    evp = pp(ev)
    half = 0.5 * (e1p + e2p)
    sa_xx = lam * evp + 2.0 * mu * (half + c * dxx)
    sa_yy = lam * evp + 2.0 * mu * (half - c * dxx)
    sa_xy = 2.0 * mu * c * exy
    s_xx = lam * ev + 2.0 * mu * exx
    s_yy = lam * ev + 2.0 * mu * eyy
    s_xy = 2.0 * mu * exy
    psi_a = 0.5 * lam * evp * evp + mu * (e1p * e1p + e2p * e2p)
    return (sa_xx, sa_yy, sa_xy), (s_xx, s_yy, s_xy), psi_a


# ---------------------------------------------------------------- damage
def degradation(d, m: float):
    """Cohesive degradation g(d) = (1 − d)² / ((1 − d)² + m d (1 + d)) (Eq. fracture_functions)."""
    a = (1.0 - d) ** 2
    return a / (a + m * d * (1.0 + d))


def degradation_prime(d, m: float):
    """g'(d) = −m (1 − d)(1 + 3d) / b², b = (1 − d)² + m d (1 + d); g'(0) = −m."""
    b = (1.0 - d) ** 2 + m * d * (1.0 + d)
    return -m * (1.0 - d) * (1.0 + 3.0 * d) / (b * b)


def degradation_second(d, m: float):
    """g''(d) (derivative of :func:`degradation_prime`)."""
    b = (1.0 - d) ** 2 + m * d * (1.0 + d)
    bp = -2.0 * (1.0 - d) + m * (1.0 + 2.0 * d)
    num = -m * (1.0 - d) * (1.0 + 3.0 * d)
    return -m * (2.0 - 6.0 * d) / (b * b) - 2.0 * num * bp / (b * b * b)


def cohesive_strength_1d(E: float, psi_c: float) -> float:
    """Peak uniaxial stress of the cohesive model in 1D: damage starts at ψ = ψ_c = σ²/(2E).

    With g'(0) = −m the damage driving force first balances the threshold
    3G_c/(8 l_d) = m ψ_c exactly when ψ reaches ψ_c, independently of l_d.
    """
    return float(np.sqrt(2.0 * E * psi_c))

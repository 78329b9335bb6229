"""Model parameters of the Darcy–Cahn–Hilliard fracture model (units mm, s, kPa).

One frozen dataclass, :class:`Parameters`, holds every *model* parameter (how
the mesh and time stepping are chosen lives in :mod:`solver.options`).  The
defaults are the paper's reference experiment (Sec. 3.5, Appendix A, Table
``tab:table_summary``): cement ratio C = 1.2 %, oil viscosity 0.29 kPa·s,
water viscosity 1e-6 kPa·s, permeability coefficient 0.0015 mm².

Units: lengths mm, time s, pressures / moduli / chemical potentials kPa,
viscosities kPa·s, permeabilities mm², toughness kPa·mm, surface tension
kPa·mm (= N/m), energies per volume kPa.

The three fracture parameters follow the paper's laws of the cement ratio C
(in percent) unless given explicitly:

* G_c = (0.26 C + 1)² kPa·mm        (Eq. Gc with K1c = 0.15 C + 0.59 kPa·m^½)
* ψ_c = 0.0015 C² kPa                (Eq. psic, p_c = α C, α = 1 kPa)
* β   = 65.7 √C kPa·s                (calibrated, Sec. 3.6)

The fields ``Gc``, ``psi_c``, ``beta`` stay ``None`` when they follow the laws
(so ``p.replace(cement=2.0)`` moves them); the resolved values are the
properties :attr:`Parameters.fracture_toughness`,
:attr:`Parameters.nucleation_energy` and :attr:`Parameters.damage_viscosity`.

Effect strengths (``volumetric_coupling``, ``korteweg_factor``,
``outer_compliance``, ``crack_permeability``, ``cell_compliance``, ``line_compliance``) switch individual model
ingredients on or off; at their "off" value each reproduces exactly the model
without that ingredient, at the default the paper's model.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace as _dc_replace
from numbers import Integral, Real
from pathlib import Path

from .plausible import did_you_mean, implausible, slip_hint, slip_message
from .tomlio import read_toml, write_flat_toml

import numpy as np

POROSITY_FIELDS = ("random", "pockets", "constant")
MU_OUTER_BCS = ("dirichlet", "zero_flux")
CH_MOBILITIES = ("harmonic", "oil", "degenerate")
OUTER_SATURATION_BCS = ("dirichlet", "defending_outflow", "outflow")
INNER_SATURATION_BCS = ("dirichlet", "injection")
#: the largest seed: it is stored in the campaign tables as a 64-bit integer
SEED_MAX = 2**63 - 1


def _param(default, unit: str, allowed: str, doc: str, choices: tuple = (), plausible: tuple | None = None):
    """A parameter's one declaration: its default, unit (mm, s, kPa system; "-" dimensionless, "" for labels and
    seeds), allowed values as text (a bare "> 0" / ">= 0", optionally after "None or ", is enforced from here;
    the relations between parameters are checked by :func:`_check_relations`), meaning with its paper
    reference, the choices of a text parameter, and for a number its plausible range (lo, hi) in its unit: the
    values a Hele-Shaw experiment of the model's kind can have.  Outside it a run warns, naming the likely unit
    slip (:func:`plausibility_warnings`), and ``--strict`` refuses."""
    return field(default=default, metadata={"unit": unit, "allowed": allowed, "doc": doc, "choices": tuple(choices),
                                            "plausible": plausible})


@dataclass(frozen=True)
class Parameters:
    """All model parameters, units mm, s, kPa; defaults = the paper's reference experiment.

    Each field below is declared once with its default, unit, allowed values and meaning (:func:`_param`);
    ``dchfrac params`` prints them as a table (:func:`parameter_table`), and the attribute list that follows
    is generated from the same declarations.
    """

    eta_o: float = _param(0.29, "kPa·s", "> 0",
        "defending (oil) viscosity η_o = η_2, kPa·s (Sec. 3.5: 300 kcSt = 0.29 kPa·s)",
        plausible=(1e-7, 10.0))
    eta_w: float = _param(1e-6, "kPa·s", "> 0",
        "invading (water) viscosity η_w = η_1, kPa·s (Table A: 1e-6)",
        plausible=(1e-7, 10.0))
    kbar: float = _param(0.0015, "mm²", "> 0",
        "Kozeny–Carman coefficient k̄, mm² (Eq. permeability; Sec. 3.5: 0.0015)",
        plausible=(1e-7, 1.0))
    cement: float = _param(1.2, "%", ">= 0 (> 0 when psi_c follows its law 0.0015 C²)",
        "cement volume ratio C, percent (Table A: [0, 3]; reference 1.2)",
        plausible=(0.0, 10.0))
    w_i: float = _param(50.0, "mm/s", ">= 0",
        "inner-boundary Darcy velocity of the invading fluid w_i, mm/s (Table A: 50)",
        plausible=(1e-3, 1e4))
    E: float = _param(331.0, "kPa", "> 0",
        "Young's modulus of the granular pack, kPa (Table A: 331)",
        plausible=(1.0, 1e5))
    nu: float = _param(0.2, "-", "(-1, 0.5)",
        "Poisson ratio of the granular pack, - (Table A: 0.2)",
        plausible=(0.0, 0.499))
    K_s: float = _param(1600.0, "kPa", "> K = E/(3(1 - 2 nu))",
        "bulk modulus of the solid grains, kPa (Table A: 1600; Biot b = 1 - K/K_s)",
        plausible=(1.0, 1e8))
    gamma: float = _param(0.03, "kPa·mm", ">= 0",
        "surface tension γ between the fluids, kPa·mm (Table A: 0.03; Eq. fluid_free_energy)",
        plausible=(0.0, 1.0))
    l_S: float = _param(4.0, "mm", "> 0",
        "regularization length of the saturation phase field l_S, mm (Table A: 4)",
        plausible=(0.01, 100.0))
    l_d: float = _param(4.0, "mm", "> 0 and <= 3 G_c/(8 psi_c) (m >= 1)",
        "regularization length of the damage phase field l_d, mm (Table A: 4; Eq. crack_density_function)",
        plausible=(0.01, 100.0))
    mu_i: float = _param(0.006, "kPa", ">= 0",
        "Dirichlet chemical potential μ_i on the inner boundary, kPa (Table A: 0.006)",
        plausible=(0.0, 10.0))
    mu_o: float = _param(0.02, "kPa", ">= 0",
        "Dirichlet chemical potential μ_o on the outer boundary, kPa (Table A: 0.02)",
        plausible=(0.0, 10.0))
    Gc: float | None = _param(None, "kPa·mm", "None or > 0",
        "fracture toughness G_c, kPa·mm; None -> (0.26 C + 1)² (Eq. Gc)",
        plausible=(1e-3, 1e3))
    psi_c: float | None = _param(None, "kPa", "None or > 0",
        "nucleation energy ψ_c, kPa; None -> 0.0015 C² (Eq. psic)",
        plausible=(1e-6, 1e3))
    beta: float | None = _param(None, "kPa·s", "None or >= 0",
        "damage viscosity β, kPa·s; None -> 65.7 √C (Sec. 3.6; Eq. fracture_equation)",
        plausible=(0.0, 1e4))
    cell_height: float = _param(1.96, "mm", "> 0",
        "Hele–Shaw cell gap (the paper's h; not the mesh size --h), mm (Table A: 1.96; k_max = gap²/12)",
        plausible=(0.01, 100.0))
    r_inner: float = _param(5.0, "mm", "> 0",
        "inner radius of the annulus r_i, mm (Sec. 3.5: 5)",
        plausible=(0.1, 1e3))
    r_outer: float = _param(53.0, "mm", "> r_inner",
        "outer radius of the annulus r_o, mm (Table A: 53)",
        plausible=(1.0, 1e4))
    bead_diameter: float = _param(2.0, "mm", "> 0",
        "bead diameter δ, mm (Table A: 2; enters Ca*)",
        plausible=(0.01, 100.0))
    phi_mean: float = _param(0.4, "-", "(0, 1)",
        "mean initial porosity φ̄ = 1 - packing fraction, - (Table A: 0.40)",
        plausible=(0.05, 0.95))
    phi_range: float = _param(0.2, "-", ">= 0 and phi_mean ± phi_range inside (0, 1)",
        "half-width of the uniform random initial porosity, - (Sec. 3.3: values in [0.2, 0.6])",
        plausible=(0.0, 0.5))
    seed: int = _param(0, "", "integer in [0, 2**63 - 1]",
        "seed of the random initial porosity (numpy default_rng), int in [0, 2**63 - 1]",
        plausible=(0, SEED_MAX))
    porosity_field: str = _param("random", "", f"one of {POROSITY_FIELDS}",
        f"initial porosity field, one of {POROSITY_FIELDS} (Sec. 3.3)", choices=POROSITY_FIELDS)
    mu_outer_bc: str = _param("dirichlet", "", f"one of {MU_OUTER_BCS}",
        f"outer boundary condition on μ, one of {MU_OUTER_BCS} (Sec. 3.3: Dirichlet μ_o; Dong: zero flux)",
        choices=MU_OUTER_BCS)
    ch_mobility: str = _param("harmonic", "", f"one of {CH_MOBILITIES}",
        f"Cahn–Hilliard mobility law, one of {CH_MOBILITIES}: k/η̄ (paper, Eq. M = k/η̄), k/η_o, or 4S(1 − S) "
        "k/η̄ (degenerate)", choices=CH_MOBILITIES)
    outer_saturation_bc: str = _param("dirichlet", "", f"one of {OUTER_SATURATION_BCS}",
        f"outer condition on the invading phase, one of {OUTER_SATURATION_BCS}: \"dirichlet\" S = 0 (the paper, "
        "Sec. 3.4); \"defending_outflow\" no invading flux (only the defending fluid leaves); \"outflow\" an outlet "
        "reservoir at p = 0 (Sec. 3.4): each phase leaves with its own Darcy flux, water in the share f(S) of the "
        "node's outflow once the front has reached r_o (solver.physics.outlet_water_flux), nothing but oil flows "
        "in; no Cahn–Hilliard flux crosses r_o (pair with mu_outer_bc = \"zero_flux\" for no μ source)",
        choices=OUTER_SATURATION_BCS)
    inner_saturation_bc: str = _param("dirichlet", "", f"one of {INNER_SATURATION_BCS}",
        f"inner condition on the invading phase, one of {INNER_SATURATION_BCS}: \"dirichlet\" S = 1 and μ = μ_i on "
        "r_i (the paper, Sec. 3.4: μ_i > 0 draws water in by the Cahn–Hilliard flux beyond the pumped w_i and lets "
        "the defending fluid out through the inlet); \"injection\" the pumped fluid is all water and the only "
        "inflow: the invading balance receives w_i on r_i (less the line's storage), no Cahn–Hilliard flux "
        "crosses r_i, S and μ are free there (μ_i unused)",
        choices=INNER_SATURATION_BCS)
    volumetric_coupling: float = _param(1.0, "-", ">= 0",
        "factor on the second-order terms φ S ε̇_v and φ ε̇_v of Eq. summary_equations_1,2 (1 paper, 0 off)",
        plausible=(0.0, 10.0))
    korteweg_factor: float = _param(1.0, "-", ">= 0",
        "factor on κ in the Korteweg terms of Eq. summary_equations_secondary (1 paper, 0 off)",
        plausible=(0.0, 10.0))
    outer_compliance: float = _param(0.0, "mm/kPa", ">= 0",
        "compliance of a spring on the outer boundary, mm/kPa (0 = rigid u = 0, the paper)",
        plausible=(0.0, 10.0))
    crack_permeability: float = _param(1.0, "-", ">= 0",
        "blend s: k = k(φ0) + s (min(k(φ), k_max) - k(φ0)) (1 paper, 0 frozen at k(φ0))",
        plausible=(0.0, 10.0))
    porosity_floor: float | None = _param(None, "-",
        "None or in (0, phi_mean - phi_range) (below every initial porosity)",
        "smooth lower bound φ_f of the porosity law, - (None: the paper's unbounded linear law; below φ_f, φ "
        "= φ_f²/(2φ_f − φ_lin), solver.physics.porosity_floor)",
        plausible=(1e-4, 1.0))
    permeability_floor: float | None = _param(None, "mm²",
        "None or in (0, k(phi_mean - phi_range)) mm² (below every initial permeability)",
        "smooth lower bound k_f of the permeability, mm² (None: the paper's Kozeny–Carman law, k = 0 at "
        "closed pores; below k_f, k = k_f²/(2k_f − k_KC), solver.physics.permeability_floor)",
        plausible=(1e-12, 1.0))
    porosity_ceiling: float | None = _param(None, "-",
        "None or in (phi_mean + phi_range, 1) (above every initial porosity)",
        "onset φ_c of a smooth upper bound 1 of the porosity law, - (None: the paper's unbounded linear law, "
        "φ > 1 in dilated cracks; above φ_c, φ = 1 − (1−φ_c)²/(2(1−φ_c) − (1−φ_lin)), "
        "solver.physics.porosity_ceiling)",
        plausible=(0.0, 1.0))
    cell_compliance: float = _param(0.0, "mm/kPa", ">= 0",
        "compliance c_cell of the elastic cell: the plates open a gap δ = c_cell p⁺ above the pack, which stores "
        "δ/h and carries both fluids with transmissivity δ³/12 (0 = rigid plates, the paper; "
        "solver.physics.cell_gap; Pihler-Puzović et al. 2012)",
        plausible=(0.0, 0.01))
    line_compliance: float = _param(0.0, "mm²/kPa", ">= 0",
        "lumped compliance C_line of the injection line and cavity per unit cell height: the pack receives "
        "w_i − (C_line/L_i) ∂p/∂t on r_i (0 = stiff line, the paper; solver.physics.line_storage_rate)",
        plausible=(0.0, 100.0))
    critical_saturation: float = _param(0.0, "-", "in [0, 0.5]",
        "critical saturation S_c of the invading water: below it the water is immobile (k_r1 = 0) and above it "
        "k_r1 is the paper's law of the reduced saturation (S − S_c)/(1 − S_c) (0 = the paper's Fourar–Lenormand "
        "law, Eq. relative_permeabilities; solver.physics.relative_permeabilities)",
        plausible=(0.0, 0.5))

    def __post_init__(self):
        _coerce_and_check(self)

    # ------------------------------------------------------------------ laws
    @property
    def fracture_toughness(self) -> float:
        """G_c, kPa·mm: explicit ``Gc`` or (0.26 C + 1)² (Eq. Gc, K1c = 0.15 C + 0.59)."""
        return float(self.Gc) if self.Gc is not None else (0.26 * self.cement + 1.0) ** 2

    @property
    def nucleation_energy(self) -> float:
        """ψ_c, kPa: explicit ``psi_c`` or 0.0015 C² (Eq. psic: (αC)²/(2E), α = 1 kPa)."""
        return float(self.psi_c) if self.psi_c is not None else 0.0015 * self.cement**2

    @property
    def damage_viscosity(self) -> float:
        """β, kPa·s: explicit ``beta`` or 65.7 √C (Sec. 3.6 calibration)."""
        return float(self.beta) if self.beta is not None else 65.7 * math.sqrt(self.cement)

    # ------------------------------------------------------------- derived
    @property
    def lame_lambda(self) -> float:
        """Plane-strain Lamé λ = E ν / ((1 + ν)(1 − 2ν)), kPa."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def lame_mu(self) -> float:
        """Shear modulus μ = E / (2 (1 + ν)), kPa."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def K(self) -> float:
        """Drained bulk modulus K = E / (3 (1 − 2ν)), kPa (Table A: 184)."""
        return _bulk(self.E, self.nu)

    @property
    def biot(self) -> float:
        """Biot coefficient b = 1 − K/K_s, - (Eq. summary_equations_4)."""
        return 1.0 - self.K / self.K_s

    @property
    def c0(self) -> float:
        """Normalization c0 = 4 ∫0^1 √w(d) dd = 8/3 for w(d) = d (Eq. fracture_functions)."""
        return 8.0 / 3.0

    @property
    def m(self) -> float:
        """Cohesive parameter m = G_c / (c0 l_d ψ_c), - (Eq. fracture_functions); m >= 1 required."""
        return self.fracture_toughness / (self.c0 * self.l_d * self.nucleation_energy)

    @property
    def k_max(self) -> float:
        """Permeability cap k_max = h²/12, mm² (Poiseuille flow in the Hele–Shaw gap)."""
        return self.cell_height**2 / 12.0

    @property
    def viscosity_ratio(self) -> float:
        """M = η_o / η_w = η_2 / η_1, - (Eq. relative_permeabilities)."""
        return self.eta_o / self.eta_w

    @property
    def eta_bar(self) -> float:
        """Harmonic mean η̄ = 2 η_o η_w / (η_o + η_w), kPa·s (Cahn–Hilliard mobility M = k/η̄)."""
        from .physics import harmonic_viscosity

        return harmonic_viscosity(self.eta_o, self.eta_w)

    @property
    def kappa(self) -> float:
        """Korteweg gradient coefficient κ = 3 γ l_S / 2, kPa·mm² (Eq. fluid_free_energy).

        From ψ^f = 12γ/l_S (f(S) + l_S²/16 |∇S|²) one gets κ = 2·12γ/l_S·l_S²/16
        = 3γl_S/2, as Sec. 2 states.  Note: the paper's dimensionless section
        ("Recall that κ = 3γl_S/4") writes 3γl_S/4; we follow the free energy.
        The Korteweg effect strength ``korteweg_factor`` is NOT included here.
        """
        return 1.5 * self.gamma * self.l_S

    def k_of_phi(self, phi):
        """Kozeny–Carman permeability φ³/(1 − φ)² k̄ capped at k_max, mm² (Eq. permeability).

        Vectorized over ``phi`` (any shape, dimensionless).  φ >= 1 gives k_max;
        φ <= 0 gives 0 (the law is only meaningful for φ in (0, 1)).
        Returns a float for scalar input, an ndarray otherwise.
        """
        a = np.asarray(phi, dtype=float)
        below = a < 1.0
        safe = np.where(below, np.clip(a, 0.0, None), 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            law = safe**3 / (1.0 - safe) ** 2 * self.kbar
        k = np.where(below, np.minimum(law, self.k_max), self.k_max)
        return float(k) if k.ndim == 0 else k

    # ------------------------------------------------------- serialization
    def to_dict(self) -> dict:
        """All fields as a plain dict (None kept as None: parameter following its law of C), except the
        fields added after runs were stored (``_OMIT_AT_DEFAULT``), left out at their default."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if not (f.name in _OMIT_AT_DEFAULT and getattr(self, f.name) == _OMIT_AT_DEFAULT[f.name])}

    @classmethod
    def from_dict(cls, d: dict) -> "Parameters":
        """Build from a dict; unknown keys raise ValueError naming them; missing keys take defaults."""
        if not isinstance(d, dict):
            raise ValueError(f"parameters must be given as a dict, got {type(d).__name__}")
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(d) - set(names))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}{did_you_mean(unknown, names)}; allowed names: {names}")
        return cls(**d)

    def replace(self, **changes) -> "Parameters":
        """Validated copy with ``changes`` (unknown names raise ValueError)."""
        names = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}{did_you_mean(unknown, names)}; allowed names: "
                             f"{sorted(names)}")
        return _dc_replace(self, **changes)

    def to_toml(self, path) -> None:
        """Write a flat TOML file (None-valued fields are omitted: they mean 'follow the law')."""
        write_flat_toml(path, self.to_dict(), "dchfrac model parameters (units mm, s, kPa)")

    @classmethod
    def from_toml(cls, path) -> "Parameters":
        """Read a file written by :meth:`to_toml` (absent keys take their defaults)."""
        return cls.from_dict(read_toml(path))

    def to_json(self, path=None) -> str:
        """JSON text of :meth:`to_dict` (None -> null); also written to ``path`` if given."""
        s = json.dumps(self.to_dict(), indent=1)
        if path is not None:
            Path(path).write_text(s + "\n")
        return s

    @classmethod
    def from_json(cls, text_or_path) -> "Parameters":
        """Inverse of :meth:`to_json`: accepts the JSON text or a path to a JSON file."""
        if isinstance(text_or_path, Path) or (
            isinstance(text_or_path, str) and not text_or_path.lstrip().startswith("{")
        ):
            text_or_path = Path(text_or_path).read_text()
        return cls.from_dict(json.loads(text_or_path))


# the declarations read back: units (`dchfrac params`, the campaign column dictionary, the figures' axis
# labels), meanings, allowed values (tests/test_params.py checks each simple bound against the validation)
_FIELD_DOCS = {f.name: f.metadata["doc"] for f in fields(Parameters)}
_UNITS = {f.name: f.metadata["unit"] for f in fields(Parameters)}
_ALLOWED = {f.name: f.metadata["allowed"] for f in fields(Parameters)}
_DEFAULTS = {f.name: f.default for f in fields(Parameters)}
PLAUSIBLE = {f.name: f.metadata["plausible"] for f in fields(Parameters) if f.metadata["plausible"] is not None}
Parameters.__doc__ += "\n    Attributes\n    ----------\n" + "".join(
    f"    {f.name} : {f.metadata['doc']} Default {f.default!r}; allowed {f.metadata['allowed']}.\n"
    for f in fields(Parameters))

# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------
_FLOAT_FIELDS = tuple(f.name for f in fields(Parameters) if f.type == "float")
_OPTIONAL_FLOAT_FIELDS = tuple(f.name for f in fields(Parameters) if f.type == "float | None")
#: the simple bounds declared as "> 0" / ">= 0" (after "None or " for optional fields): name -> (bound, strict)
_SIMPLE_BOUNDS = {f.name: (0.0, f.metadata["allowed"].endswith("> 0")) for f in fields(Parameters)
                  if f.metadata["allowed"].removeprefix("None or ") in ("> 0", ">= 0")}
# fields added after runs were stored: left out of to_dict() at their default (None, or the off value 0 of an
# effect), so the parameter dicts (and the run keys made from them) of older runs do not change
_OMIT_AT_DEFAULT = {"porosity_floor": None, "permeability_floor": None, "porosity_ceiling": None,
                    "cell_compliance": 0.0, "line_compliance": 0.0, "inner_saturation_bc": "dirichlet",
                    "critical_saturation": 0.0}
_CHOICES = tuple((f.name, f.metadata["choices"]) for f in fields(Parameters) if f.metadata["choices"])
CHOICE_FIELDS = tuple(name for name, _ in _CHOICES)


def _bulk(E: float, nu: float) -> float:
    return E / (3.0 * (1.0 - 2.0 * nu))


def _fail(name, value, allowed):
    raise ValueError(f"parameter {name}={value!r} is out of range: allowed {allowed}")


def _as_float(name, v) -> float:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, Real):
        _fail(name, v, "a real number")
    try:
        v = float(v)
    except OverflowError:
        _fail(name, f"{str(v)[:12]}... ({len(str(v))} digits)", "a finite number")
    if not math.isfinite(v):
        _fail(name, v, "a finite number")
    return v


def _coerce_and_check(p: Parameters) -> None:
    """Coerce the types, then check every declared simple bound and the relations between parameters (each
    failure names the parameter, its value and what is allowed)."""
    _coerce_types(p)
    for name, (lo, strict) in _SIMPLE_BOUNDS.items():
        v = getattr(p, name)
        if v is not None and not (v > lo if strict else v >= lo):
            _fail(name, v, f"{'>' if strict else '>='} {lo}")
    _check_relations(p)


def _coerce_types(p: Parameters) -> None:
    """Numbers become plain floats (so the serialization round trip is exact), the seed an int; choices checked."""
    for name in _FLOAT_FIELDS:
        object.__setattr__(p, name, _as_float(name, getattr(p, name)))
    for name in _OPTIONAL_FLOAT_FIELDS:
        v = getattr(p, name)
        if v is not None:
            object.__setattr__(p, name, _as_float(name, v))
    s = p.seed
    if isinstance(s, (bool, np.bool_)) or not isinstance(s, Integral) or not 0 <= s <= SEED_MAX:
        _fail("seed", s, "an integer in [0, 2**63 - 1]")
    object.__setattr__(p, "seed", int(s))
    for name, allowed in _CHOICES:
        if getattr(p, name) not in allowed:
            _fail(name, getattr(p, name), f"one of {allowed}")


def _check_relations(p: Parameters) -> None:
    """The allowed values that are not a simple bound: intervals, and bounds set by other parameters."""
    if not p.l_d > 0.0:
        _fail("l_d", p.l_d, "> 0.0")
    if not p.phi_range >= 0.0:
        _fail("phi_range", p.phi_range, ">= 0.0")
    if not p.cement >= 0.0 or (p.psi_c is None and not p.cement > 0.0):  # psi_c = 0.0015 C^2 would vanish
        _fail("cement", p.cement, "> 0.0" if p.psi_c is None else ">= 0.0")
    if not (-1.0 < p.nu < 0.5):
        _fail("nu", p.nu, "the open interval (-1, 0.5)")
    if not 0.0 <= p.critical_saturation <= 0.5:
        _fail("critical_saturation", p.critical_saturation, "in [0, 0.5]")
    K = _bulk(p.E, p.nu)
    if not p.K_s > K:
        if implausible(p.E, PLAUSIBLE["E"]) and not implausible(p.K_s, PLAUSIBLE["K_s"]):  # E the likely culprit
            raise ValueError(f"parameter E={p.E!r} makes the drained bulk modulus K = {K:.6g} kPa exceed K_s = "
                             f"{p.K_s:g} kPa (allowed: K < K_s); {slip_hint('E', p.E, 'kPa', PLAUSIBLE['E'], _DEFAULTS['E'])}")
        _fail("K_s", p.K_s, f"> drained bulk modulus K = E/(3(1-2nu)) = {K:.6g} kPa (Biot b in (0, 1))")
    if not p.r_outer > p.r_inner:
        _fail("r_outer", p.r_outer, f"> r_inner = {p.r_inner}")
    if not (0.0 < p.phi_mean < 1.0):
        _fail("phi_mean", p.phi_mean, "the open interval (0, 1)")
    if not (p.phi_mean - p.phi_range > 0.0 and p.phi_mean + p.phi_range < 1.0):
        _fail("phi_range", p.phi_range,
              f"< min(phi_mean, 1 - phi_mean) = {min(p.phi_mean, 1 - p.phi_mean):.6g} "
              "(phi_mean ± phi_range inside (0, 1))")
    _check_porosity_bounds(p)
    if not p.nucleation_energy > 0.0:  # 0.0015 C² underflows for a vanishing cement ratio
        _fail("cement" if p.psi_c is None else "psi_c", p.cement if p.psi_c is None else p.psi_c,
              "a value whose nucleation energy psi_c = 0.0015 C² is > 0 kPa (Eq. psic)")
    bound = 3.0 * p.fracture_toughness / (8.0 * p.nucleation_energy)
    if not p.l_d <= bound * (1.0 + 1e-12):
        _fail("l_d", p.l_d, f"<= 3 G_c/(8 psi_c) = {bound:.6g} mm (Eq. fracture_upper_bound, m >= 1)")


def _check_porosity_bounds(p: Parameters) -> None:
    """The optional porosity floor and ceiling and permeability floor lie outside every initial value."""
    if p.porosity_floor is not None and not 0.0 < p.porosity_floor < p.phi_mean - p.phi_range:
        _fail("porosity_floor", p.porosity_floor, f"None or in (0, phi_mean - phi_range = {p.phi_mean - p.phi_range:.6g}) "
                                                  "(below every initial porosity)")
    if p.permeability_floor is not None:
        from .physics import kozeny_carman

        k_min = float(kozeny_carman(np.asarray(p.phi_mean - p.phi_range), p.kbar, p.k_max))
        if not 0.0 < p.permeability_floor < k_min:
            _fail("permeability_floor", p.permeability_floor, f"None or in (0, k(phi_mean - phi_range) = {k_min:.6g}) mm² "
                                                              "(below every initial permeability)")
    if p.porosity_ceiling is not None and not p.phi_mean + p.phi_range < p.porosity_ceiling < 1.0:
        _fail("porosity_ceiling", p.porosity_ceiling, f"None or in (phi_mean + phi_range = {p.phi_mean + p.phi_range:.6g}, 1) "
                                                      "(above every initial porosity)")


def plausibility_warnings(p: Parameters) -> list[str]:
    """One warning per parameter of ``p`` set outside its declared plausible range, naming the likely unit
    slip (``solver.plausible``; G_c, ψ_c, β when given explicitly)."""
    return [slip_message("parameter", name, getattr(p, name), _UNITS[name], rng, _DEFAULTS[name])
            for name, rng in PLAUSIBLE.items() if implausible(getattr(p, name), rng)]


def integer_fields() -> tuple[str, ...]:
    """Names of the integer parameters (declared ``int``, e.g. ``seed``): a table of conditions that stores
    them as floats (1.0) must give them back as integers."""
    return tuple(f.name for f in fields(Parameters) if f.type in ("int", int))


def text_fields() -> tuple[str, ...]:
    """Names of the text parameters (declared ``str``, e.g. ``porosity_field``)."""
    return tuple(f.name for f in fields(Parameters) if f.type in ("str", str))


def field_doc(name: str) -> str:
    """Documentation (meaning, units, paper reference) of the parameter ``name``."""
    if name not in _FIELD_DOCS:
        raise ValueError(f"unknown parameter {name!r}; allowed names: {list(_FIELD_DOCS)}")
    return _FIELD_DOCS[name]


def field_unit(name: str) -> str:
    """Unit of the parameter ``name`` (mm, s, kPa system; "-" dimensionless, "" for labels and seeds)."""
    if name not in _UNITS:
        raise ValueError(f"unknown parameter {name!r}; allowed names: {list(_UNITS)}")
    return _UNITS[name]


def parameter_table() -> list[dict]:
    """One dict per parameter: name, unit, default, allowed (text), plausible ((lo, hi) or None), meaning (units
    mm, s, kPa)."""
    return [{"name": f.name, "unit": _UNITS.get(f.name, "?"), "default": f.default,
             "allowed": _ALLOWED.get(f.name, "?"), "plausible": PLAUSIBLE.get(f.name),
             "meaning": _FIELD_DOCS.get(f.name, "")} for f in fields(Parameters)]

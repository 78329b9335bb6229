"""What a run will cost, estimated from its mesh before any work: nodes, memory and wall time.

Mesh (:func:`mesh_counts`): the annulus mesh (:func:`solver.mesh.annulus_mesh`) is quasi-uniform at the target
size s(r) (:func:`solver.mesh.annulus_size`, graded by h_inner and h_outer), so its node count is that of
equilateral triangles of edge s(r) filling the annulus, 2/√3 ∫ dA / s², plus the boundary nodes, whose rings add
about ``_BOUNDARY_NODES`` of a node per boundary edge.  Measured against the meshes at h = 4, 2, 1, 0.5 mm and
graded ones (``tests/test_budget.py``): within ``COUNT_TOLERANCE``.  Elements: a triangulation of an annulus has
M = 2 N − N_boundary.

Memory (:func:`memory_bytes`): a run's peak resident memory is the interpreter and libraries (``BASE_BYTES``) plus
a part that grows with the unknowns n = 7 N: the Jacobian (≈ 340 nonzeros per node), its factors (nested
dissection in 2D: fill ∝ n log n) and the element arrays.  The coefficient of n log₂ n is fitted per path on the
peak RSS of short runs at h = 4, 2, 1 mm (``MEMORY_PER_NLOGN``, measured on x86_64 Linux, results/bench/memory_peak_rss.jsonl: h = 4, 2, 1 mm
peaked at 311, 439, 968 MB on the fast path, the model gives 325, 447, 991 MB).  Extrapolated to h = 0.5 mm it
gives 3.4 GB, an upper bound (fill grows slower than n log n with nested dissection's separators).

Wall time (:func:`wall_time_s`): a run takes about the same number of Newton iterations per simulated second at
every h (the steps follow the state change, not the mesh: 118-120 accepted steps to 2 s at h = 2 and 1 mm), so its
rate (wall s per simulated s) is ``ITERATIONS_PER_SIM_S`` times the cost of one Newton iteration (assembly,
factorization, solve).  That cost at h = 2, 1, 0.5 mm per linear solver is ``REFERENCE`` (``results/bench/bench.json``,
the quiet reference machine), interpolated log-log in the unknowns and extrapolated with the last slope.  The
machine and path factor is measured here: one Newton iteration at h = 2 mm on the path that will run
(:func:`calibration`, about 2 s, cached per code hash and path in ``$DCHFRAC_CACHE``) divided by the reference's.

Units: mm, s; memory in bytes.
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Estimate", "mesh_counts", "memory_bytes", "available_memory_bytes", "estimate_run", "check_fits",
           "calibration", "wall_time_s"]

_BOUNDARY_NODES = 0.65  # extra nodes per boundary edge of size s (the rings at r_inner and r_outer)
#: relative error of :func:`mesh_counts` against the real meshes, measured (tests/test_budget.py)
COUNT_TOLERANCE = 0.05
N_FIELDS = 7  # unknowns per node: u (2), p, S, μ, G (2)
#: the interpreter and libraries with the first arrays of a run (peak RSS of a coarse run, h = 4 mm: 290-310 MB
#: with numba and MKL loaded; 180 MB with numpy kernels and SuperLU)
BASE_BYTES = 290e6
#: peak-RSS bytes per n log2 n (n = unknowns) above BASE_BYTES, per (linear solver, kernels) path: the slope of
#: the peak RSS of 3-step runs between h = 2 and 1 mm (pypardiso 579, SuperLU 724 B with numba kernels; numpy
#: kernels measured at h = 4 and 2 mm only, 639 B with SuperLU), rounded up (results/bench/memory_peak_rss.jsonl)
MEMORY_PER_NLOGN = {("pypardiso", "numba"): 600.0, ("superlu", "numba"): 750.0,
                    ("pypardiso", "numpy"): 750.0, ("superlu", "numpy"): 800.0}
#: results/bench/bench.json (quiet reference machine): wall seconds of one Newton iteration (assembly on one
#: thread, factorization, solve) by linear solver, at the unknowns of h = 2, 1, 0.5 mm
REFERENCE = {"unknowns": (18494, 72709, 285712),
             "newton_iteration_s": {"pypardiso": (0.06806, 0.33275, 2.12183), "superlu": (0.32299, 2.71395, None)},
             "reference_run_h2_wall_s_per_sim_s": 6.1476, "per_run_overhead_s": 2.19}
#: Newton iterations (in units of one full iteration's cost) per simulated second: the h = 2 reference run's rate
#: over its iteration cost, 6.15 / 0.068 (h = 1: 31.9 / 0.333 = 96)
ITERATIONS_PER_SIM_S = REFERENCE["reference_run_h2_wall_s_per_sim_s"] / REFERENCE["newton_iteration_s"]["pypardiso"][0]


@dataclass(frozen=True)
class Estimate:
    """A run's estimated size and cost: nodes, elements, unknowns, peak memory (bytes), wall time (s, None when not
    calibrated), memory available now (bytes), and the path (linear solver, kernels) it was estimated for."""

    nodes: int
    elements: int
    unknowns: int
    memory_bytes: float
    wall_s: float | None
    available_bytes: float | None
    linear_solver: str
    kernels: str

    def fits(self) -> bool:
        return self.available_bytes is None or self.memory_bytes <= self.available_bytes

    def line(self) -> str:
        """One line: nodes, memory against what is available, wall time."""
        avail = "unknown" if self.available_bytes is None else _gb(self.available_bytes)
        t = "" if self.wall_s is None else f", about {_duration(self.wall_s)} of wall time"
        return (f"{self.nodes:,} nodes ({self.unknowns:,} unknowns), peak memory about {_gb(self.memory_bytes)} "
                f"of {avail} available{t} ({self.linear_solver}, {self.kernels} kernels)")

    def to_dict(self) -> dict:
        return asdict(self)


def _gb(b: float) -> str:
    return f"{b / 1e9:.3g} GB" if b < 1e15 else f"{b / 1e9:.2e} GB"


def _duration(s: float) -> str:
    from .progress import format_duration

    return format_duration(s) if s < 1e7 else f"{s / 3.15e7:.2e} years"


def mesh_counts(h: float, h_inner: float | None = None, grading_length: float | None = None,
                h_outer: float | None = None, r_inner: float = 5.0, r_outer: float = 53.0) -> tuple[int, int]:
    """(nodes, elements) of the annulus mesh of size h (mm), graded by h_inner over grading_length and by h_outer
    (mm; see the module docstring), without building it.  Within ``COUNT_TOLERANCE`` of the real meshes."""
    from .mesh import GRADING_LENGTH, annulus_size

    gl = grading_length or GRADING_LENGTH
    # the size is piecewise linear in r with kinks at r_i + gl and r_o - gl: a fine midpoint rule is exact enough
    edges = np.linspace(r_inner, r_outer, 4001)
    r = 0.5 * (edges[1:] + edges[:-1])
    s = annulus_size(r, h, h_inner, r_inner, gl, h_outer, r_outer)
    interior = 2.0 / math.sqrt(3.0) * float(np.sum(2 * math.pi * r * np.diff(edges) / s**2))
    s_in, s_out = annulus_size(np.array([r_inner, r_outer]), h, h_inner, r_inner, gl, h_outer, r_outer)
    ring = 2 * math.pi * (r_inner / s_in + r_outer / s_out)  # boundary edges (and nodes)
    nodes = interior + _BOUNDARY_NODES * ring
    return int(round(nodes)), int(round(2 * nodes - ring))


def memory_bytes(unknowns: int, linear_solver: str, kernels: str) -> float:
    """Peak resident memory (bytes) of a run with ``unknowns`` unknowns on the path (linear_solver, kernels)."""
    n = max(float(unknowns), 2.0)
    return BASE_BYTES + MEMORY_PER_NLOGN[(linear_solver, kernels)] * n * math.log2(n)


def available_memory_bytes() -> float | None:
    """Memory available to a new process now (bytes): Linux's MemAvailable, else the physical memory; None when
    neither can be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def _reference_iteration_s(unknowns: float, linear_solver: str) -> float:
    """The reference machine's Newton-iteration time (s) at ``unknowns``: log-log interpolation of ``REFERENCE``,
    extrapolated with the slope of the last (or first) measured interval."""
    x = np.log(np.asarray(REFERENCE["unknowns"], float))
    y = [v for v in REFERENCE["newton_iteration_s"][linear_solver]]
    keep = [i for i, v in enumerate(y) if v is not None]
    x, y = x[keep], np.log(np.asarray([y[i] for i in keep], float))
    lx = math.log(max(unknowns, 1.0))
    i = int(np.clip(np.searchsorted(x, lx) - 1, 0, len(x) - 2))
    slope = (y[i + 1] - y[i]) / (x[i + 1] - x[i])
    return float(math.exp(y[i] + slope * (lx - x[i])))


def wall_time_s(unknowns: int, t_end: float, linear_solver: str, factor: float) -> float:
    """Wall time (s) of a run of ``unknowns`` unknowns to ``t_end`` (s) on ``linear_solver``, with the machine and
    path ``factor`` of :func:`calibration` (1 = the reference machine's fast path)."""
    per_iteration = factor * _reference_iteration_s(unknowns, linear_solver)
    return factor * REFERENCE["per_run_overhead_s"] + t_end * ITERATIONS_PER_SIM_S * per_iteration


def _path() -> tuple[str, str]:
    from .paths import active_path

    p = active_path()
    return p["linear_solver"], p["kernels"]


def estimate_run(params, options, calibrate: bool = True) -> Estimate:
    """The :class:`Estimate` of a run of ``params`` (solver.Parameters) with ``options`` (solver.RunOptions) on the
    annulus, on the path that will run; ``calibrate=False`` leaves the wall time out (no measurement)."""
    from .paths import resolve

    nodes, elements = mesh_counts(options.h, options.h_inner, options.inner_grading_length, options.h_outer,
                                  params.r_inner, params.r_outer)
    n = N_FIELDS * nodes
    _, kern = _path()
    ls = resolve(options.linear_solver, n)
    wall = wall_time_s(n, options.t_end, ls, calibration(ls, kern)["factor"]) if calibrate else None
    return Estimate(nodes, elements, n, memory_bytes(n, ls, kern), wall, available_memory_bytes(), ls, kern)


def check_fits(params, options) -> Estimate:
    """The run's memory estimate (no wall time, no measurement: a fraction of a millisecond); raises ValueError
    with one line naming h, the estimate and the memory available when the run cannot fit."""
    est = estimate_run(params, options, calibrate=False)
    if not est.fits():
        raise ValueError(f"h={options.h!r} cannot fit: the run needs about {_gb(est.memory_bytes)} "
                         f"({est.nodes:,} nodes) and {_gb(est.available_bytes)} is available (allowed: a coarser h, "
                         "or --force)")
    return est


def _measure_iteration(h: float = 2.0) -> float:
    """Best wall time (s) of one Newton iteration (assembly, factorization, solve) at mesh size h (mm) on the
    active path, after one warm-up iteration (compilation, symbolic analysis)."""
    from . import linsolve, paths
    from .mesh import annulus_mesh
    from .model import build_discretization, residual_and_jacobian, step_data
    from .params import Parameters
    from .porosity import initial_porosity

    p = Parameters()
    mesh = annulus_mesh(p.r_inner, p.r_outer, h)
    disc = build_discretization(mesh, p, initial_porosity(mesh, p))
    U = np.zeros((disc.n_nodes, disc.n_fields))
    data = step_data(disc, p, U, np.zeros(disc.n_nodes), 1e-3)
    kind = paths.resolve("auto", disc.asm.ndof)
    precision = paths.resolve_precision(None, kind)
    best = math.inf
    for k in range(3):
        t0 = time.perf_counter()
        R, J = residual_and_jacobian(disc, p, U, data)
        disc.dirichlet.apply_matrix(J)
        linsolve.factorize(J, kind, precision, condense=disc.projection_dofs).solve(-R)
        if k:
            best = min(best, time.perf_counter() - t0)
    return best


def calibration(linear_solver: str, kernels: str) -> dict:
    """{"factor": this machine's Newton iteration at h = 2 mm on the path over the reference's, "iteration_s",
    "code_hash"}: measured once per code hash and path (about 2 s) and kept in ``$DCHFRAC_CACHE/budget``."""
    from .jitcache import cache_dir
    from .codehash import code_hash

    path = cache_dir().parent / "budget" / f"calibration_{code_hash()}_{linear_solver}_{kernels}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        pass
    it = _measure_iteration(2.0)
    out = {"factor": it / REFERENCE["newton_iteration_s"][linear_solver][0], "iteration_s": it,
           "code_hash": code_hash(), "linear_solver": linear_solver, "kernels": kernels}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(out))
        os.replace(tmp, path)
    except OSError:
        pass  # an unwritable cache: measured again next time (solver.jitcache warns about the folder)
    return out

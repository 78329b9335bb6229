"""Field-split preconditioning with algebraic multigrid against the PARDISO factorization, side by side on the same
Jacobians (issue #49, the "not tried" lever of results/bench/README.md).

Reads the Jacobians and right-hand sides ``fieldsplit_dump.py`` saved (J_h*_t*.npz: the reference run's Newton
Jacobian at a fresh factorization, −R of that iterate and of the next chord iteration) and, in one process with
repeats interleaved variant by variant, measures for each variant the set-up, the iterations to the Newton forcing
‖J x − b‖ ≤ 1e-3 ‖b‖ (``linsolve.SINGLE_FORCING``, the test the default single-precision path applies), the time
per solve, the update's error in the Newton test's measure (largest field-scaled difference from the
double-precision solution, relative to the update's size), and the memory:

  pardiso      today's path: ``linsolve.factorize(J, "pypardiso", "single")`` and its substitutions;
  blt_amg      GMRES right-preconditioned by the block-lower-triangular field split u | (p, S, μ, G):
               y_u = AMG(A_uu) b_u (one V-cycle), y_f = A_ff⁻¹ (b_f − A_fu y_u), A_ff by PARDISO (single);
  blt_amg_cond the same with the projected gradient G condensed out of A_ff (its block is the diagonal lumped
               mass), PARDISO on the (p, S, μ) Schur complement K;
  schur_amg    GMRES with the block LDU preconditioner on the approximate Schur complement
               Ŝ = A_ff − A_fu D_uu⁻¹ A_uf (D_uu the nodal 2x2 block diagonal of A_uu), PARDISO on Ŝ;
               y_u = AMG b_u, y_f = Ŝ⁻¹ (b_f − A_fu y_u), x_u = AMG (b_u − A_uf y_f);
  blt_exact_uu the diagnostic of blt_amg with A_uu solved exactly (PARDISO) instead of the V-cycle: the iterations
               the split itself costs, whatever the multigrid;
  amg_whole    GMRES preconditioned by smoothed aggregation on the whole J (7x7 nodal blocks; h = 2 only, one
               repeat).

AMG: pyamg smoothed aggregation on A_uu as 2x2 nodal blocks with the three rigid-body modes of plane elasticity
as near-null space (Dirichlet columns zeroed with the rows, so the block is symmetric), one V-cycle with symmetric
Gauss-Seidel, the coarsest level by sparse LU (made in the set-up, which pyamg otherwise defers to the first cycle).
Sub-blocks are taken by a gather map made once per pattern (the run's block pattern is fixed), as a solver would.
GMRES: ``solver.krylov.gmres`` (right preconditioning, the true residual), at most 150 iterations.

Per update: (set-up + first solve + (k − 1) later solves) / k, k the reference run's Newton iterations per
factorization, as the chord iteration amortizes a set-up; each variant's ratio is to PARDISO's on the same matrix.
Each variant runs once untimed first (first-call costs), then ``REPS`` times interleaved (one fewer at h = 0.5).

    MKL_NUM_THREADS=1 OMP_NUM_THREADS=1 REPS=2 python results/archive/bench/fieldsplit_amg.py OUT.json J_h2_t0.05.npz ...
"""
import json
import os
import sys
import time

import numpy as np
import scipy.sparse as sp

from solver import krylov, linsolve
from solver.forms import GX, GY, P, S, MU, UX, UY

NF = 7
FORCING = linsolve.SINGLE_FORCING
FLOORS = np.array([1e-2, 1e-2, 1.0, 1.0, 1e-2, 0.1, 0.1])  # solver.stagger._FLOORS
MAXITER = 150
# Newton iterations per factorization of the reference run to 2 s (profile_sizes.json, round9b): what a
# preconditioner set-up is amortized over in the chord iteration
ITS_PER_FACTORIZATION = {2.0: 1426 / 143, 1.0: 1435 / 153, 0.5: 1419 / 168}


def load(path):
    z = np.load(path)
    J = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(z["shape"]))
    return J, z["rhs0"], z["rhs1"], z["U"], float(z["t"]), float(z["dt"]), float(z["h"])


# ------------------------------------------------------------------ PARDISO handles of the study's own blocks
class Pardiso:
    """PARDISO factors of one matrix on a private handle, with linsolve's settings (iparm) and precision."""

    def __init__(self, A, single=True):
        import pypardiso

        linsolve._pardiso_solver("single")  # MKL located, CBWR set
        self.s = pypardiso.PyPardisoSolver()
        for i, v in {1: 1, 2: 2, 8: 0, 10: 13, 11: 0, 13: 0, 24: 1, 28: int(single)}.items():
            self.s.set_iparm(i, v)
        self.A = sp.csr_matrix(A)
        self.A.sort_indices()
        self.dtype = np.float32 if single else np.float64
        self.data = self.A.data.astype(self.dtype)
        self.one = ((self.A.indptr + 1).astype(np.int32), (self.A.indices + 1).astype(np.int32))
        rhs = np.zeros((self.A.shape[0], 1), self.dtype)
        t0 = time.perf_counter()
        linsolve._call(self.s, self.data, self.one, 11, rhs)
        t1 = time.perf_counter()
        linsolve._call(self.s, self.data, self.one, 22, rhs)
        t2 = time.perf_counter()
        self.symbolic_s, self.numeric_s = t1 - t0, t2 - t1
        ip = self.s.iparm  # iparm(15) peak of the analysis, (16) permanent, (17) factorization and solution, KB
        self.memory_mb = max(int(ip[14]), int(ip[15]) + int(ip[16])) / 1024.0

    def refactor(self, A):
        """Numeric factorization only (the same pattern): what a run does after the first analysis."""
        self.data = np.asarray(A.data, self.dtype)
        t0 = time.perf_counter()
        linsolve._call(self.s, self.data, self.one, 22, np.zeros((A.shape[0], 1), self.dtype))
        self.numeric_s = time.perf_counter() - t0

    def solve(self, b):
        self.s.set_iparm(8, 0)
        return linsolve._call(self.s, self.data, self.one, 33, np.asfortranarray(b, self.dtype)).astype(float)

    def free(self):
        self.s.free_memory(everything=True)


# ------------------------------------------------------------------ the field split
class Split:
    """Index sets and gather maps of the block pattern (made once per pattern)."""

    def __init__(self, J):
        n = J.shape[0] // NF
        node = np.arange(n) * NF
        self.u = np.sort(np.concatenate([node + UX, node + UY]))
        self.f = np.sort(np.concatenate([node + f for f in (P, S, MU, GX, GY)]))
        self.f_g = np.flatnonzero(np.isin(self.f % NF, (GX, GY)))  # G within the fluid block
        self.points_n = n
        ids = sp.csr_matrix((np.arange(1, J.nnz + 1, dtype=float), J.indices, J.indptr), shape=J.shape)
        self.maps = {}
        for name, (r, c) in {"uu": (self.u, self.u), "uf": (self.u, self.f), "fu": (self.f, self.u),
                             "ff": (self.f, self.f)}.items():
            B = ids[r][:, c].tocsr()
            B.sort_indices()
            self.maps[name] = (B.data.astype(np.int64) - 1, B.indices, B.indptr, B.shape)

    def block(self, J, name):
        m, ind, ptr, shape = self.maps[name]
        return sp.csr_matrix((J.data[m], ind, ptr), shape=shape)


def rigid_body_modes(points, dir_u_local):
    """The three rigid-body modes of plane elasticity on the u unknowns (u_x, u_y interleaved by node), zero at
    Dirichlet unknowns."""
    x, y = points[:, 0], points[:, 1]
    B = np.zeros((2 * len(x), 3))
    B[0::2, 0] = 1.0
    B[1::2, 1] = 1.0
    B[0::2, 2], B[1::2, 2] = -y, x
    B[dir_u_local] = 0.0
    return B


def amg_uu(A_uu, B, dirichlet):
    """Smoothed aggregation on A_uu with its Dirichlet columns zeroed (symmetric), 2x2 nodal blocks."""
    import pyamg

    A = A_uu.copy()
    keep = np.ones(A.shape[0])
    keep[dirichlet] = 0.0
    A = (A @ sp.diags(keep)).tocsr()
    A = A + sp.diags(1.0 - keep)  # identity rows and columns at Dirichlet unknowns
    A = A.tobsr(blocksize=(2, 2))
    ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="symmetric", strength=("symmetric", {"theta": 0.0}),
                                           presmoother=("gauss_seidel", {"sweep": "symmetric"}),
                                           postsmoother=("gauss_seidel", {"sweep": "symmetric"}), max_coarse=400,
                                           coarse_solver="splu")
    ml.solve(np.ones(A.shape[0]), x0=np.zeros(A.shape[0]), maxiter=1, tol=1e-300)  # the coarse LU (made lazily)
    return ml


def amg_memory_mb(ml):
    nb = 0
    for lvl in ml.levels:
        for name in ("A", "P", "R"):
            M = getattr(lvl, name, None)
            if M is not None:
                nb += M.data.nbytes + M.indices.nbytes + M.indptr.nbytes
    return nb / 2**20


def nodal_block_inverse(A_uu):
    """D_uu⁻¹: the inverse of the 2x2 nodal diagonal blocks of A_uu, as a block-diagonal sparse matrix."""
    d = A_uu.diagonal()
    off_u = np.asarray(A_uu[np.arange(0, A_uu.shape[0], 2), np.arange(1, A_uu.shape[0], 2)]).ravel()
    off_l = np.asarray(A_uu[np.arange(1, A_uu.shape[0], 2), np.arange(0, A_uu.shape[0], 2)]).ravel()
    a, dd = d[0::2], d[1::2]
    det = a * dd - off_u * off_l
    blocks = np.stack([np.stack([dd, -off_u], -1), np.stack([-off_l, a], -1)], -2) / det[:, None, None]
    return sp.bsr_matrix((blocks, np.arange(len(a)), np.arange(len(a) + 1)), shape=A_uu.shape).tocsr()


class ExactUU:
    """The diagnostic in place of the V-cycle: A_uu solved by PARDISO (double; the u block's pattern is fixed)."""

    def __init__(self, A_uu, cache):
        if "uu" in cache:
            self.lu = cache["uu"]
            self.lu.refactor(A_uu)
        else:
            self.lu = cache["uu"] = Pardiso(A_uu, single=False)
        self.levels = []

    def solve(self, b, **kw):
        return self.lu.solve(b)

    def operator_complexity(self):
        return None


class FieldSplit:
    """The block preconditioners; ``kind`` "blt", "blt_cond" or "schur"."""

    def __init__(self, J, split: Split, B, dir_u, kind, cache):
        self.kind, self.split = kind, split
        t0 = time.perf_counter()
        A_uu, A_uf, A_fu, A_ff = (split.block(J, k) for k in ("uu", "uf", "fu", "ff"))
        self.A_uf, self.A_fu = A_uf, A_fu
        t1 = time.perf_counter()
        self.ml = ExactUU(A_uu, cache) if kind == "blt_exact" else amg_uu(A_uu, B, dir_u)
        t2 = time.perf_counter()
        self.cond = None
        if kind in ("blt", "blt_exact"):
            M = A_ff
        elif kind == "blt_cond":
            self.cond = linsolve._Condensation(A_ff, split.f_g)
            M = self.cond.K
        else:  # schur
            M = (A_ff - A_fu @ nodal_block_inverse(A_uu) @ A_uf).tocsr()
        t3 = time.perf_counter()
        # the run's pattern is fixed: the fluid block keeps its analysis (the condensed and Schur matrices' patterns
        # move with the interfaces; their analysis is charged, as a run would have to)
        if kind in ("blt", "blt_exact") and kind in cache:
            self.lu = cache[kind]
            self.lu.A = M
            self.lu.refactor(M)
            symbolic = 0.0
        else:
            if kind in cache:
                cache.pop(kind).free()
            self.lu = Pardiso(M, single=True)
            cache[kind] = self.lu
            symbolic = self.lu.symbolic_s
        self.setup = {"extract_s": t1 - t0, "amg_setup_s": t2 - t1, "fluid_matrix_s": t3 - t2,
                      "fluid_symbolic_s": symbolic, "fluid_numeric_s": self.lu.numeric_s}
        self.setup["total_s"] = sum(self.setup.values())
        self.memory = {"amg_mb": amg_memory_mb(self.ml) if kind != "blt_exact" else None, "fluid_factor_mb": self.lu.memory_mb,
                       "fluid_unknowns": M.shape[0], "fluid_nnz": M.nnz,
                       "amg_levels": len(self.ml.levels), "amg_operator_complexity": self.ml.operator_complexity()}

    def _fluid(self, r):
        if self.cond is None:
            return self.lu.solve(r)
        return self.cond.expand(r, self.lu.solve(self.cond.reduce(r)))

    def __call__(self, v):
        sp_ = self.split
        b_u, b_f = v[sp_.u], v[sp_.f]
        y_u = self.ml.solve(b_u, x0=np.zeros_like(b_u), maxiter=1, cycle="V", tol=1e-300)
        y_f = self._fluid(b_f - self.A_fu @ y_u)
        if self.kind == "schur":
            y_u = self.ml.solve(b_u - self.A_uf @ y_f, x0=np.zeros_like(b_u), maxiter=1, cycle="V", tol=1e-300)
        x = np.empty_like(v)
        x[sp_.u], x[sp_.f] = y_u, y_f
        return x


def component_costs(J, split, B, dir_u, b, cache, reps=5):
    """Median seconds of what one GMRES iteration with the block-lower-triangular preconditioner does: the
    product J v, the V-cycle on A_uu, the fluid block's substitution, and a substitution with the full factors."""
    pc = FieldSplit(J, split, B, dir_u, "blt", cache)
    lu = linsolve.factorize(J, "pypardiso", "single")
    lu.solve(b)
    b_u, b_f = b[split.u], b[split.f]
    jobs = {"matvec_J": lambda: J @ b,
            "amg_vcycle_uu": lambda: pc.ml.solve(b_u, x0=np.zeros_like(b_u), maxiter=1, cycle="V", tol=1e-300),
            "fluid_substitution": lambda: pc.lu.solve(b_f),
            "off_diagonal_matvec": lambda: pc.A_fu @ b_u,
            "full_substitution": lambda: lu.solve(b)}
    out = {k: [] for k in jobs}
    for _ in range(reps):
        for k, fn in jobs.items():
            t0 = time.perf_counter()
            fn()
            out[k].append(time.perf_counter() - t0)
    return {k: float(np.median(v)) for k, v in out.items()}


def update_error(dx, ref, U):
    """The Newton test's measure of dx − ref relative to ref: largest |·| / field scale over the fields."""
    scale = np.maximum(np.abs(U).max(axis=0), FLOORS)
    e = (np.abs((dx - ref).reshape(-1, NF)).max(axis=0) / scale).max()
    return float(e / (np.abs(ref.reshape(-1, NF)).max(axis=0) / scale).max())


def rel_res(J, x, b):
    return float(np.linalg.norm(J @ x - b) / np.linalg.norm(b))


def run_pardiso(J, bs, refs, U):
    t0 = time.perf_counter()
    lu = linsolve.factorize(J, "pypardiso", "single")
    setup = time.perf_counter() - t0
    out = {"setup": {"total_s": setup}, "solves": []}
    for b, ref in zip(bs, refs):
        t0 = time.perf_counter()
        x = lu.solve(b)
        out["solves"].append({"solve_s": time.perf_counter() - t0, "iterations": 1, "rel_residual": rel_res(J, x, b),
                              "update_error": update_error(x, ref, U)})
    ip = linsolve._pardiso_solver("single")["solver"].iparm
    out["memory"] = {"factor_mb": max(int(ip[14]), int(ip[15]) + int(ip[16])) / 1024.0}
    return out


def run_krylov(J, bs, refs, U, make_precond):
    t0 = time.perf_counter()
    pc = make_precond()
    setup = time.perf_counter() - t0
    out = {"setup": dict(getattr(pc, "setup", {}), total_s=setup), "memory": getattr(pc, "memory", {}), "solves": []}
    for b, ref in zip(bs, refs):
        t0 = time.perf_counter()
        x, its = krylov.gmres(lambda v: J @ v, pc, b, FORCING, MAXITER)
        dt = time.perf_counter() - t0
        ok = x is not None
        out["solves"].append({"solve_s": dt, "iterations": its, "converged": ok,
                              "rel_residual": rel_res(J, x, b) if ok else None,
                              "update_error": update_error(x, ref, U) if ok else None})
    return out


class WholeAMG:
    def __init__(self, J):
        import pyamg

        t0 = time.perf_counter()
        self.ml = pyamg.smoothed_aggregation_solver(J.tobsr(blocksize=(NF, NF)), symmetry="nonsymmetric",
                                                    strength=("evolution", {}), max_coarse=400,
                                                    presmoother=("gauss_seidel_nr", {"sweep": "symmetric"}),
                                                    postsmoother=("gauss_seidel_nr", {"sweep": "symmetric"}))
        self.setup = {"amg_setup_s": time.perf_counter() - t0}
        self.memory = {"amg_mb": amg_memory_mb(self.ml), "amg_levels": len(self.ml.levels)}

    def __call__(self, v):
        return self.ml.solve(v, x0=np.zeros_like(v), maxiter=1, cycle="V", tol=1e-300)


def study(path, reps, whole):
    J, b0, b1, U, t, dt, h = load(path)
    b0, b1 = np.asarray(b0), np.asarray(b1)
    split = Split(J)
    points = mesh_points(h, U.shape[0])
    dir_u = dirichlet_u(J, split)
    B = rigid_body_modes(points, dir_u)
    ref = linsolve.factorize(J, "pypardiso", "double")
    refs = [ref.solve(b0), ref.solve(b1)]
    A_uu = split.block(J, "uu")
    keep = np.ones(A_uu.shape[0])
    keep[dir_u] = 0.0
    A_in = sp.diags(keep) @ A_uu @ sp.diags(keep)
    sym = float(abs(A_in - A_in.T).max() / abs(A_in).max())
    cache = {}
    variants = {"pardiso": lambda: run_pardiso(J, [b0, b1], refs, U)}
    for kind, name in (("blt", "blt_amg"), ("blt_cond", "blt_amg_cond"), ("schur", "schur_amg"),
                       ("blt_exact", "blt_exact_uu")):
        variants[name] = (lambda kind=kind: run_krylov(J, [b0, b1], refs, U,
                                                       lambda: FieldSplit(J, split, B, dir_u, kind, cache)))
    if whole:
        variants["amg_whole"] = lambda: run_krylov(J, [b0, b1], refs, U, lambda: WholeAMG(J))
    linsolve.factorize(J, "pypardiso", "single").solve(b0)  # the analysis of the run's pattern, made once per run
    FieldSplit(J, split, B, dir_u, "blt", cache)  # likewise for the fluid block's pattern
    parts = component_costs(J, split, B, dir_u, b0, cache)
    for name, fn in variants.items():  # warm-up (first calls of each code path), not recorded
        if name != "amg_whole":
            fn()
    results = {k: [] for k in variants}
    for r in range(reps):
        for name, fn in variants.items():
            if name == "amg_whole" and r > 0:
                continue
            try:
                results[name].append(fn())
            except Exception as exc:  # a variant that fails is recorded, not fatal
                results[name].append({"error": f"{type(exc).__name__}: {exc}"})
            print(name, r, json.dumps(results[name][-1])[:400], file=sys.stderr, flush=True)
    for lu in cache.values():
        lu.free()
    return {"file": os.path.basename(path), "h_mm": h, "t_s": t, "dt_s": dt, "unknowns": J.shape[0], "nnz": J.nnz,
            "u_unknowns": len(split.u), "A_uu_asymmetry": sym, "dirichlet_u": len(dir_u),
            "rhs_norms": [float(np.linalg.norm(b0)), float(np.linalg.norm(b1))],
            "gmres_iteration_parts_s": parts, "variants": results, "summary": summarize(results, h)}


def dirichlet_u(J, split):
    """Positions in the u unknowns of the Dirichlet rows of J (rows whose only non-zero is a unit diagonal)."""
    J.sort_indices()
    rows = np.repeat(np.arange(J.shape[0]), np.diff(J.indptr))
    nzrow = np.bincount(rows[J.data != 0], minlength=J.shape[0])
    dirichlet_rows = np.flatnonzero((nzrow == 1) & np.isclose(J.diagonal(), 1.0))
    return np.flatnonzero(np.isin(split.u, dirichlet_rows))


def mesh_points(h, n_nodes):
    """The nodes (mm) of the reference run's mesh at size h (the mesh ``simulate`` makes with default options)."""
    from solver import Parameters, RunOptions
    from solver.mesh import GRADING_LENGTH, annulus_mesh

    p, o = Parameters(), RunOptions(h=h)
    mesh = annulus_mesh(p.r_inner, p.r_outer, o.h, o.mesh_seed, h_inner=o.h_inner,
                        grading_length=o.inner_grading_length or GRADING_LENGTH, h_outer=o.h_outer)
    pts = np.asarray(mesh.points, float)
    assert len(pts) == n_nodes, (len(pts), n_nodes)
    return pts


def med(xs):
    xs = [x for x in xs if x is not None]
    return float(np.median(xs)) if xs else None


def summarize(results, h):
    """Medians over the repeats; the per-update cost with the set-up amortized over the chord iteration's
    Newton iterations per factorization, and its ratio to PARDISO's."""
    k = ITS_PER_FACTORIZATION.get(h, 9.0)
    out = {}
    for name, reps in results.items():
        ok = [r for r in reps if "error" not in r]
        if not ok:
            out[name] = {"error": reps[0]["error"]}
            continue
        setup = med([r["setup"]["total_s"] for r in ok])
        first = med([r["solves"][0]["solve_s"] for r in ok])
        later = med([r["solves"][1]["solve_s"] for r in ok])
        its = [r["solves"][i]["iterations"] for i in (0, 1) for r in ok[:1]]
        conv = all(s.get("converged", True) for r in ok for s in r["solves"])
        per_update = (setup + first + (k - 1) * later) / k
        out[name] = {"setup_s": setup, "solve_first_s": first, "solve_later_s": later, "iterations": its,
                     "converged": conv, "per_update_s": per_update,
                     "update_error": [ok[0]["solves"][i]["update_error"] for i in (0, 1)],
                     "rel_residual": [ok[0]["solves"][i]["rel_residual"] for i in (0, 1)],
                     "setup_parts": {key: med([r["setup"].get(key) for r in ok]) for key in ok[0]["setup"]},
                     "memory": ok[0]["memory"]}
    base = out.get("pardiso", {}).get("per_update_s")
    for name, v in out.items():
        if base and "per_update_s" in v:
            v["per_update_ratio_to_pardiso"] = v["per_update_s"] / base
            v["setup_ratio_to_pardiso"] = v["setup_s"] / out["pardiso"]["setup_s"]
    return out


def main():
    out_path, files = sys.argv[1], sys.argv[2:]
    reps = int(os.environ.get("REPS", "3"))
    from sweep.studies.bench import _refactorization_h1

    import pyamg
    import threadpoolctl

    record = {"threads": {"MKL_NUM_THREADS": os.environ.get("MKL_NUM_THREADS"),
                          "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
                          "threadpools": threadpoolctl.threadpool_info()},
              "pyamg": pyamg.__version__, "forcing": FORCING, "maxiter": MAXITER, "reps": reps,
              "its_per_factorization": ITS_PER_FACTORIZATION, "load_average_start": os.getloadavg(),
              "h1_refactorization_start": _refactorization_h1(), "studies": []}
    for f in files:
        h = float(np.load(f)["h"])
        record["studies"].append(study(f, reps if h > 0.5 else max(1, reps - 1), whole=h >= 2.0))
        print(json.dumps({"file": f, "summary": record["studies"][-1]["summary"]}, indent=1), flush=True)
        tmp = out_path + ".tmp"
        record["h1_refactorization_end"] = None
        with open(tmp, "w") as fh:
            json.dump(record, fh, indent=1)
        os.replace(tmp, out_path)
    record["h1_refactorization_end"] = _refactorization_h1()
    record["load_average_end"] = os.getloadavg()
    with open(out_path + ".tmp", "w") as fh:
        json.dump(record, fh, indent=1)
    os.replace(out_path + ".tmp", out_path)


if __name__ == "__main__":
    main()

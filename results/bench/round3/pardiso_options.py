"""PARDISO options on one Jacobian of the reference case: factorization and substitution times and fill.

    MKL_NUM_THREADS=1 python results/bench/round3/pardiso_options.py H CONFIGS    # e.g. 2 base,vbsr80,twolevel

H: mesh size, mm; CONFIGS: comma-separated names of CONFIGS below.  Each configuration gets its own PARDISO
handle with the solver's settings (solver/linsolve.py) plus its extra iparm entries (1-based), one analysis, then
three rounds of (numeric factorization, substitution); prints the best of three, the relative
residual and the factors' entries (iparm(18)).  Units: s.
"""
import ctypes
import os
import sys
import time

os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")
import numpy as np, scipy.sparse as sp
from solver import Parameters, linsolve
from solver.mesh import annulus_mesh
from solver.model import build_discretization, residual_and_jacobian, step_data
from solver.porosity import random_porosity
h=float(sys.argv[1])
p = Parameters(); mesh = annulus_mesh(p.r_inner, p.r_outer, h)
disc = build_discretization(mesh, p, random_porosity(mesh, seed=0))
N, nf = disc.n_nodes, disc.n_fields
rng = np.random.default_rng(0); r = np.hypot(*disc.points.T)
U = np.zeros((N, nf)); U[:, 0:2] = 1e-3 * rng.standard_normal((N, 2))
U[:, 2] = 200 * (p.r_outer - r) / (p.r_outer - p.r_inner); U[:, 3] = np.clip(1.5 - (r - p.r_inner) / 10, 0, 1)
data = step_data(disc, p, 0.99 * U, np.zeros(N), 1e-2)
R, J = residual_and_jacobian(disc, p, U, data); disc.dirichlet.apply_matrix(J)
A = sp.csr_matrix(J, dtype=float); A.sort_indices()
print("n", A.shape[0], "nnz", A.nnz, "fields", nf, flush=True)
linsolve._locate_mkl_rt()
import pypardiso
def make(extra):
    s = pypardiso.PyPardisoSolver()
    for i, v in {1: 1, 2: 2, 8: 0, 10: 13, 11: 0, 13: 0, 18: -1, 19: -1, **extra}.items(): s.set_iparm(i, v)
    return s
ia=(A.indptr+1).astype(np.int32); ja=(A.indices+1).astype(np.int32)
def call(s, ph, b):
    x=np.zeros_like(b); err=ctypes.c_int32(0); i32,f64=ctypes.POINTER(ctypes.c_int32),ctypes.POINTER(ctypes.c_double)
    s._mkl_pardiso(s.pt.ctypes.data_as(ctypes.POINTER(s._pt_type[0])), ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(s.mtype)), ctypes.byref(ctypes.c_int32(ph)), ctypes.byref(ctypes.c_int32(A.shape[0])), A.data.ctypes.data_as(f64), ia.ctypes.data_as(i32), ja.ctypes.data_as(i32), s.perm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(1)), s.iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(f64), x.ctypes.data_as(f64), ctypes.byref(err))
    assert err.value==0, err.value
    return x
CONFIGS = {"base": {}, "vbsr80": {37: -80}, "vbsr95": {37: -95}, "twolevel": {24: 1}, "twolevel10": {24: 10}}
configs = {k: CONFIGS[k] for k in sys.argv[2].split(",")}
b=np.asfortranarray(R.reshape(-1,1).astype(float))
sol={}; times={k:{"fac":[], "sol":[]} for k in configs}
S={}
for k,e in configs.items():
    try:
        s=make(e); call(s,11,b); S[k]=s
        print(k, "analysis ok; factor nnz (iparm18)", s.iparm[17], "MFLOPS(iparm19)", s.iparm[18], flush=True)
    except Exception as ex:
        print(k, "failed", ex)
for rep in range(3):
    for k,s in S.items():
        t=time.perf_counter(); call(s,22,b); times[k]["fac"].append(time.perf_counter()-t)
        s.set_iparm(8,0); t=time.perf_counter(); x=call(s,33,b); times[k]["sol"].append(time.perf_counter()-t)
        sol[k]=np.linalg.norm(A@x.ravel()-b.ravel())/np.linalg.norm(b)
for k in S: print(k, "fac min %.3f"%min(times[k]["fac"]), "sol min %.4f"%min(times[k]["sol"]), "relres %.2e"%sol[k], "nnzLU", S[k].iparm[17])

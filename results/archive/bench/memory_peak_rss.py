import json, resource, sys, time
from solver import Parameters, RunOptions, simulate
from solver.mesh import annulus_mesh
h = float(sys.argv[1])
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
r = simulate(Parameters(), RunOptions(h=h, t_end=3e-3, dt0=1e-3, snapshot_times=[], write_xdmf=False))
m = annulus_mesh(5.0, 53.0, h)
print(json.dumps({"h": h, "status": r.status, "path": r.path, "nodes": m.n_nodes, "elements": m.n_elements,
                  "base_kb": base, "peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "wall": time.perf_counter() - t0, "steps": len(r.timeseries)}))

import cProfile, pstats, sys, time, tomllib, shutil
t0 = time.process_time()
import cProfile
from solver import Parameters, RunOptions, simulate
t_imp = time.process_time() - t0
src = sys.argv[1]; out = sys.argv[2]
p = tomllib.loads(open(src + '/params.toml').read()); o = tomllib.loads(open(src + '/options.toml').read())
shutil.rmtree(out, ignore_errors=True)
pr = cProfile.Profile(time.process_time)
pr.enable()
simulate(Parameters.from_dict(p), RunOptions.from_dict(o), out_dir=out)
pr.disable()
print("import cpu", t_imp, "total cpu", time.process_time() - t0)
st = pstats.Stats(pr); st.sort_stats('cumulative').print_stats(45)

"""One-off diagnostic (issue #47 item 7): continue a failed run of experiment_ca_star_eta_line from one of its
checkpoints with changed run options, to see whether the failure at t = 2.2-2.3 s is the discretization's or
the model's.  The checkpoint's identity check is bypassed on purpose (its options differ from the probe's):
this is a probe, not a result of the campaign.

    python probe.py CONFIG.toml CHECKPOINT.npz OUT_DIR [name=value ...]

CONFIG: the run's [parameters]/[options] (dchfrac run --config); CHECKPOINT: a copy of its checkpoint.npz; the
name=value pairs override run options or model parameters (Python literals).  Writes OUT_DIR as a run folder and prints the summary.
Units mm, s, kPa.
"""
import ast
import json
import shutil
import sys
from pathlib import Path

from importlib import import_module

import numpy as np

from solver import Parameters, RunOptions
from sweep.cli import _load_config


def main(argv):
    config, ck_path, out = argv[:3]
    pdict, odict = _load_config(config)
    for kv in argv[3:]:
        k, v = kv.split("=", 1)
        (odict if k in RunOptions.__dataclass_fields__ else pdict)[k] = ast.literal_eval(v)
    odict.setdefault("frames", 20)  # as the dchfrac run that wrote the checkpoint
    params, options = Parameters.from_dict(pdict), RunOptions.from_dict(odict)
    out = Path(out)
    src = Path(ck_path).parent / "run"
    ck = json.loads(str(np.load(ck_path)["state"]))
    out.mkdir(parents=True, exist_ok=True)
    (out / "snapshots").mkdir(exist_ok=True)
    for i in range(int(ck["n_snapshots"])):
        shutil.copy(src / "snapshots" / f"snap_{i:05d}.npz", out / "snapshots")
    shutil.copy(ck_path, out / "checkpoint.npz")
    checkpoint = import_module("solver.checkpoint")
    checkpoint.mismatch = lambda stored, current: None  # the probe's options differ on purpose
    res = import_module("solver.simulate").simulate(params, options, out_dir=out)
    print(json.dumps({"status": res.status, "reason": res.reason, "t": float(res.timeseries["t"].iloc[-1]), "options": argv[3:]}))


if __name__ == "__main__":
    main(sys.argv[1:])

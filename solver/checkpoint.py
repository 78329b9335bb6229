"""Checkpoints of a run: the whole state of the time loop in ``<run folder>/checkpoint.npz``.

A run with a run folder writes a checkpoint at the end of an accepted step once ``RunOptions.checkpoint_interval``
seconds of wall time have passed since the last one (atomically: ``solver.output.atomic_path``).  A run killed
part-way (machine lost, job cancelled, Ctrl-C) keeps it; ``solver.simulate`` called again on the same folder
continues the time loop from it, and a run that ends ("ok" or "failed") removes it.

Contents: the arrays ``U`` (nodes x fields), ``d`` (nodes), ``previous_U``, ``previous_d`` (the state before the
last accepted step, for the step predictor; absent on the first step) and ``state``, a JSON text: the time t (s),
the next dt (s), the cumulative balances (mm²), the time-series rows, the pending snapshot times (s), the
rejected steps, the outer-layer warning flag, the number of snapshots written, the factorizations and the wall
time (s) so far, the times of earlier resumptions (s), and the identity of the run that wrote it (:func:`identity`:
solver code hash, parameters, options without the result-neutral ones, mesh fingerprint).  A checkpoint whose
identity is not the run's is never used.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .codehash import code_hash
from .options import keyed

__all__ = ["NAME", "identity", "inputs_identity", "mesh_fingerprint", "save", "load", "mismatch", "remove",
           "resumable"]

NAME = "checkpoint.npz"


def mesh_fingerprint(sim) -> dict:
    """Numbers of nodes and triangles of the run's discretization and a hash of its points (mm), triangles and
    initial porosity: a checkpoint of another mesh or initial field does not match."""
    disc = sim.disc
    h = hashlib.sha256()
    for a in (disc.points, disc.triangles, disc.phi0):
        h.update(np.ascontiguousarray(a).tobytes())
    return {"n_nodes": int(disc.n_nodes), "n_triangles": int(len(disc.triangles)), "hash": h.hexdigest()[:16]}


def inputs_identity(params, options) -> dict:
    """The part of a run's identity known before its set-up: solver code hash, parameters and options (their
    dict form, without the options that do not change the result)."""
    return {"code_hash": code_hash(), "params": _plain(params.to_dict()), "options": _plain(keyed(options.to_dict()))}


def identity(params, options, sim) -> dict:
    """The identity a checkpoint of this run carries: :func:`inputs_identity` and the mesh fingerprint."""
    return {**inputs_identity(params, options), "mesh": mesh_fingerprint(sim)}


def mismatch(stored: dict, current: dict) -> str | None:
    """Why the identity ``stored`` (of a checkpoint) is not ``current`` (the entries ``current`` has), or None."""
    for name, value in current.items():
        if stored.get(name) != value:
            return f"its {name.replace('_', ' ')} differs from this run's"
    return None


def save(run_dir, sim, state: dict) -> None:
    """Write the checkpoint of ``sim`` (its U, d, t and predictor state) with the loop's ``state`` (a JSON-able
    dict: the module docstring) atomically to ``run_dir/checkpoint.npz``."""
    import io

    from .output import atomic_write_bytes

    arrays = {"U": sim.U, "d": sim.d}
    prev_dt = None
    if sim.previous is not None:
        arrays["previous_U"], arrays["previous_d"], prev_dt = sim.previous
    text = json.dumps({**state, "t": sim.t, "previous_dt": prev_dt}, default=_json_default)
    buf = io.BytesIO()
    np.savez(buf, state=np.array(text), **arrays)
    atomic_write_bytes(Path(run_dir) / NAME, buf.getvalue())


def load(run_dir) -> tuple[dict | None, str | None]:
    """(checkpoint, None) of ``run_dir``, or (None, why) when it has none or it cannot be read; the checkpoint is
    the state dict with the arrays under "U", "d" and "previous" ((U, d, dt) or None)."""
    path = Path(run_dir) / NAME
    if not path.is_file():
        return None, None
    try:
        with np.load(path, allow_pickle=False) as z:
            ck = json.loads(str(z["state"]))
            ck["U"], ck["d"] = z["U"], z["d"]
            ck["previous"] = (z["previous_U"], z["previous_d"], ck["previous_dt"]) \
                if ck["previous_dt"] is not None else None
        if ck["U"].ndim != 2 or ck["d"].shape != (ck["U"].shape[0],):
            raise ValueError(f"arrays of shapes {ck['U'].shape}, {ck['d'].shape}")
    except Exception as exc:  # noqa: BLE001 - any reading error: the checkpoint is not used
        return None, f"{NAME} cannot be read ({type(exc).__name__}: {exc})"
    return ck, None


def resumable(run_dir) -> bool:
    """Whether ``run_dir`` holds a readable checkpoint written by the current solver code."""
    ck, _ = load(run_dir)
    return ck is not None and ck.get("identity", {}).get("code_hash") == code_hash()


def remove(run_dir) -> None:
    """Remove the checkpoint of ``run_dir`` (none: nothing to do)."""
    (Path(run_dir) / NAME).unlink(missing_ok=True)


def _plain(d: dict) -> dict:
    """``d`` as its JSON round trip (tuples as lists, numpy scalars as numbers): comparable with a loaded one."""
    return json.loads(json.dumps(d, default=_json_default))


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"{type(o).__name__} is not JSON-serializable")

"""Which computational path a run takes: the sparse direct solver and the element kernels.

Both are chosen automatically from what is installed: MKL PARDISO (``pypardiso``) and compiled numba kernels
(the fast path, the core dependencies where MKL's wheels install), else SuperLU and numpy kernels (the fallback,
scipy and numpy only).  Two environment variables force a choice, for every run of the process:

* ``DCHFRAC_LINEAR_SOLVER`` = ``auto`` | ``superlu`` | ``pypardiso`` (:func:`env_choice`): what the
  run option ``linear_solver = "auto"`` picks;
* ``DCHFRAC_KERNELS`` = ``auto`` | ``numba`` | ``numpy`` (:func:`solver.kernels.backend`).

``DCHFRAC_ASSEMBLY_THREADS`` (:func:`assembly_threads`) sets the threads of the element assembly
(:func:`solver.fem.map_chunks`).

An invalid value raises ValueError naming the variable (:func:`check_environment`), before any work.
The choice imports neither scipy nor numba nor pypardiso (it looks for them with ``find_spec``), so that bad input
and the memory budget (:mod:`solver.budget`) are answered before the heavy libraries load.
"""
from __future__ import annotations

import os

__all__ = ["active_path", "check_environment", "describe", "available_backends", "env_choice", "resolve",
           "resolve_precision", "assembly_threads", "PRECISIONS", "PARDISO_MIN_SIZE", "ENV_VAR"]

#: precisions of the factors (run option ``linear_precision``; :mod:`solver.linsolve`)
PRECISIONS = ("double", "single")


def available_backends() -> list[str]:
    """Installed backends (found without importing them: importing pypardiso loads MKL)."""
    from importlib.util import find_spec

    return ["superlu"] + (["pypardiso"] if find_spec("pypardiso") is not None else [])


#: below this many unknowns "auto" keeps SuperLU even when pypardiso is installed (there the
#: difference is a few milliseconds; measured: h = 8 mm, 1,300 unknowns, both about 5 ms)
PARDISO_MIN_SIZE = 2_000


#: the environment variable that forces the backend "auto" picks (the fallback path: ``superlu``)
ENV_VAR = "DCHFRAC_LINEAR_SOLVER"
ENV_CHOICES = ("auto", "superlu", "pypardiso")


def env_choice() -> str:
    """``DCHFRAC_LINEAR_SOLVER`` (default ``auto``): what ``linear_solver = "auto"`` picks; ValueError naming
    the variable when its value is not one of ``ENV_CHOICES`` or names a backend that is not installed."""
    v = os.environ.get(ENV_VAR, "auto").strip().lower() or "auto"
    if v not in ENV_CHOICES:
        raise ValueError(f"{ENV_VAR}={v!r} is not allowed: one of {ENV_CHOICES}")
    if v == "pypardiso" and "pypardiso" not in available_backends():
        raise ValueError(f"{ENV_VAR}='pypardiso' but pypardiso is not installed (MKL wheels: x86_64 Linux and "
                         "Windows)")
    return v


def resolve(kind: str, n: int | None = None) -> str:
    """The backend that factorizes a matrix of ``n`` unknowns under the run option ``linear_solver = kind``:
    ``"auto"`` is pypardiso when installed (and ``n`` >= ``PARDISO_MIN_SIZE``), else SuperLU, unless
    ``DCHFRAC_LINEAR_SOLVER`` forces one."""
    if kind == "auto":
        forced = env_choice()
        if forced != "auto":
            return forced
        if n is not None and n < PARDISO_MIN_SIZE:
            return "superlu"
        return "pypardiso" if "pypardiso" in available_backends() else "superlu"
    if kind not in ("superlu", "pypardiso"):
        raise ValueError(f"linear_solver={kind!r} is not one of ('auto', 'superlu', 'pypardiso')")
    if kind == "pypardiso" and "pypardiso" not in available_backends():
        raise ValueError("linear_solver='pypardiso' but pypardiso is not installed (MKL wheels: x86_64 Linux and Windows)")
    return kind


def resolve_precision(precision: str | None, kind: str) -> str:
    """The factors' precision for the resolved backend ``kind``: ``precision`` when given, else (None) "single"
    with PARDISO and "double" with SuperLU (whose single-precision factorization is slower than its double
    one on the coupled Jacobian; results/archive/bench_rounds.md, sixth round)."""
    if precision is None:
        return "single" if kind == "pypardiso" else "double"
    if precision not in PRECISIONS:
        raise ValueError(f"linear_precision={precision!r} is not one of {PRECISIONS} or None")
    return precision


def assembly_threads() -> int:
    """Threads for element assembly: ``DCHFRAC_ASSEMBLY_THREADS`` if set, else 1.

    numpy releases the GIL inside its array loops, so chunks assembled on two threads overlap
    their arithmetic.  Campaigns run one solver per core and keep this at 1.
    """
    v = os.environ.get("DCHFRAC_ASSEMBLY_THREADS", "1")
    try:
        n = int(v)
    except ValueError:
        raise ValueError(f"DCHFRAC_ASSEMBLY_THREADS must be a positive integer, got {v!r}") from None
    if n < 1:
        raise ValueError(f"DCHFRAC_ASSEMBLY_THREADS must be a positive integer, got {n}")
    return n


#: unknowns of a run-sized Jacobian: "auto" keeps SuperLU only below PARDISO_MIN_SIZE
_RUN_SIZE = 10**6


def check_environment() -> None:
    """Raise ValueError (one line naming the variable, its value and what is allowed) if ``DCHFRAC_KERNELS`` or
    ``DCHFRAC_LINEAR_SOLVER`` is invalid."""
    active_path()


def active_path() -> dict:
    """``{"linear_solver": "pypardiso" | "superlu", "kernels": "numba" | "numpy", "fast": bool}``: the path that a
    run-sized problem takes now (linear_solver = "auto", environment read at the call)."""
    from . import kernels

    ls, kern = resolve("auto", _RUN_SIZE), kernels.backend()
    return {"linear_solver": ls, "kernels": kern, "fast": ls == "pypardiso" and kern == "numba"}


def describe(path: dict | None = None) -> str:
    """One line naming the active path, e.g. ``linear solver pypardiso (MKL PARDISO), kernels numba (compiled):
    fast path``; the fallback says what is missing or which variable forced it."""
    from . import kernels

    path = path or active_path()
    names = {"pypardiso": "pypardiso (MKL PARDISO)", "superlu": "superlu (scipy SuperLU)",
             "numba": "numba (compiled)", "numpy": "numpy (reference)"}
    text = f"linear solver {names[path['linear_solver']]}, kernels {names[path['kernels']]}"
    if path["fast"]:
        return text + ": fast path"
    why = []
    if path["linear_solver"] == "superlu":
        forced = os.environ.get(ENV_VAR, "").strip().lower() == "superlu"
        why.append(f"{ENV_VAR}=superlu" if forced else "pypardiso not installed")
    if path["kernels"] == "numpy":
        forced = os.environ.get("DCHFRAC_KERNELS", "").strip().lower() == "numpy"
        why.append("DCHFRAC_KERNELS=numpy" if forced or kernels.numba_available() else "numba not installed")
    return text + f": fallback ({', '.join(why)})"

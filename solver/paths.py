"""Which computational path a run takes: the sparse direct solver and the element kernels.

Both are chosen automatically from what is installed: MKL PARDISO (``pypardiso``) and compiled numba kernels
(the fast path, the core dependencies where MKL's wheels install), else SuperLU and numpy kernels (the fallback,
scipy and numpy only).  Two environment variables force a choice, for every run of the process:

* ``DCHFRAC_LINEAR_SOLVER`` = ``auto`` | ``superlu`` | ``pypardiso`` (:func:`solver.linsolve.env_choice`): what the
  run option ``linear_solver = "auto"`` picks;
* ``DCHFRAC_KERNELS`` = ``auto`` | ``numba`` | ``numpy`` (:func:`solver.kernels.backend`).

An invalid value raises ValueError naming the variable (:func:`check_environment`), before any work.
"""
from __future__ import annotations

__all__ = ["active_path", "check_environment", "describe"]

#: unknowns of a run-sized Jacobian: "auto" keeps SuperLU only below linsolve.PARDISO_MIN_SIZE
_RUN_SIZE = 10**6


def check_environment() -> None:
    """Raise ValueError (one line naming the variable, its value and what is allowed) if ``DCHFRAC_KERNELS`` or
    ``DCHFRAC_LINEAR_SOLVER`` is invalid."""
    active_path()


def active_path() -> dict:
    """``{"linear_solver": "pypardiso" | "superlu", "kernels": "numba" | "numpy", "fast": bool}``: the path that a
    run-sized problem takes now (linear_solver = "auto", environment read at the call)."""
    from . import kernels, linsolve

    ls, kern = linsolve.resolve("auto", _RUN_SIZE), kernels.backend()
    return {"linear_solver": ls, "kernels": kern, "fast": ls == "pypardiso" and kern == "numba"}


def describe(path: dict | None = None) -> str:
    """One line naming the active path, e.g. ``linear solver pypardiso (MKL PARDISO), kernels numba (compiled):
    fast path``; the fallback says what is missing or which variable forced it."""
    import os

    from . import kernels, linsolve

    path = path or active_path()
    names = {"pypardiso": "pypardiso (MKL PARDISO)", "superlu": "superlu (scipy SuperLU)",
             "numba": "numba (compiled)", "numpy": "numpy (reference)"}
    text = f"linear solver {names[path['linear_solver']]}, kernels {names[path['kernels']]}"
    if path["fast"]:
        return text + ": fast path"
    why = []
    if path["linear_solver"] == "superlu":
        forced = os.environ.get(linsolve.ENV_VAR, "").strip().lower() == "superlu"
        why.append(f"{linsolve.ENV_VAR}=superlu" if forced else "pypardiso not installed")
    if path["kernels"] == "numpy":
        forced = os.environ.get("DCHFRAC_KERNELS", "").strip().lower() == "numpy"
        why.append("DCHFRAC_KERNELS=numpy" if forced or kernels.numba_available() else "numba not installed")
    return text + f": fallback ({', '.join(why)})"

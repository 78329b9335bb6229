"""Feedback on the compilation of the numba kernels, and warming their on-disk cache.

The compiled kernels (:mod:`solver.kernels`, and the generated point-wise physics of :mod:`solver.codegen`)
are compiled by numba on their first call and kept on disk (``cache=True``): the first run on a machine, or the
first after a change of the physics, compiles them (about 50 s of CPU for the default model structure: one core
of a 2-core x86_64 machine, results/bench/README.md), every later run loads them in a fraction of a second.  This module says so
when it happens (:func:`announce`, :func:`finished`, logger ``dchfrac.solver``), warns once when the cache
directory is not writable (:func:`warn_unwritable`), and :func:`warmup` compiles them ahead (``dchfrac warmup``).
"""
from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path

__all__ = ["is_cached", "announce", "finished", "warn_unwritable", "warmup", "compile_estimate_s"]

LOG = logging.getLogger("dchfrac.solver")

#: compile time assumed before one was measured on this machine, s (CPU of the default structure, see above)
DEFAULT_COMPILE_S = 50.0
_ESTIMATE_FILE = "compile_seconds.txt"
_PENDING: dict = {}  # key -> (wall clock at the announcement, dispatchers)
_WARNED: set = set()
_ANNOUNCED = [0]  # compilations announced in this process
_LOCK = threading.Lock()


def is_cached(dispatchers) -> bool:
    """Whether every numba dispatcher of ``dispatchers`` has an on-disk cache index newer than its source (then
    its first call loads machine code instead of compiling); False when that cannot be told."""
    for d in dispatchers:
        if getattr(d, "signatures", None):
            continue  # compiled or loaded in this process already
        try:
            index = Path(d._cache._cache_file._index_path)
            source = Path(d.py_func.__code__.co_filename)
            if not index.exists() or index.stat().st_mtime < source.stat().st_mtime:
                return False
        except (AttributeError, OSError):
            return False
    return True


def compile_estimate_s() -> float:
    """The last compile time measured on this machine (s, kept in the kernel cache directory), else
    ``DEFAULT_COMPILE_S``."""

    try:
        return float((cache_dir() / _ESTIMATE_FILE).read_text())
    except (OSError, ValueError):
        return DEFAULT_COMPILE_S


def announce(key, dispatchers, also=()) -> bool:
    """Log "compiling kernels (first run, ~N s) ..." when ``dispatchers`` (or ``also``) are not in the on-disk
    cache; their first calls then compile them, and :func:`finished` reports when ``dispatchers`` are done.
    Returns whether they compile."""
    dispatchers = tuple(dispatchers)
    if is_cached(dispatchers + tuple(also)):
        return False
    with _LOCK:
        if key in _PENDING:
            return True
        _PENDING[key] = (time.perf_counter(), dispatchers)
        _ANNOUNCED[0] += 1
    from .progress import format_duration

    LOG.info("compiling kernels (first run, ~%s) ... later runs load them from the cache",
             format_duration(compile_estimate_s()))
    return True


def finished(key) -> None:
    """After a call of the kernels of ``key``: once every announced dispatcher has compiled, log the time it took
    and keep it as the next estimate."""
    if key not in _PENDING:
        return
    with _LOCK:
        t0, dispatchers = _PENDING.get(key, (None, ()))
        if t0 is None or not all(getattr(d, "signatures", None) for d in dispatchers):
            return
        del _PENDING[key]
    seconds = time.perf_counter() - t0
    LOG.info("kernels compiled in %.0f s (cached for later runs)", seconds)

    try:
        tmp = cache_dir() / f".{_ESTIMATE_FILE}.{os.getpid()}.tmp"
        tmp.write_text(f"{seconds:.1f}\n")
        os.replace(tmp, cache_dir() / _ESTIMATE_FILE)
    except OSError:
        pass


def warn_unwritable(root: Path, used: Path, exc: Exception) -> None:
    """One warning per process that the kernel cache ``root`` cannot be written and ``used`` serves instead."""
    if str(root) in _WARNED:
        return
    _WARNED.add(str(root))
    var = "DCHFRAC_CACHE" if os.environ.get("DCHFRAC_CACHE") else "the default cache"
    LOG.warning("kernel cache %s (%s) is not writable (%s): compiled kernels are kept in %s instead; set "
                "DCHFRAC_CACHE to a writable folder to keep them across runs", root, var,
                getattr(exc, "strerror", None) or exc, used)


def cache_dir() -> Path:
    """Directory of the generated kernel modules: ``$DCHFRAC_CACHE/kernels`` or ``~/.cache/dchfrac/kernels``."""
    root = os.environ.get("DCHFRAC_CACHE") or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "dchfrac"
    return Path(root) / "kernels"

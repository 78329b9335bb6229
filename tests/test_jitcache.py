"""Compile feedback of the numba kernels (solver/jitcache.py): announced when not in the on-disk cache, timed when
done, and an unwritable cache folder warned about once, not silently recompiled."""
from __future__ import annotations

import logging

from solver import codegen, jitcache


class _FakeDispatcher:
    """A numba dispatcher as jitcache sees it: no on-disk cache (no ``_cache``), compiled once ``signatures`` is
    filled."""

    def __init__(self):
        self.signatures = []


def test_uncached_kernels_are_announced_then_timed_and_the_time_kept_as_the_next_estimate(tmp_path, monkeypatch,
                                                                                          caplog):
    monkeypatch.setenv("DCHFRAC_CACHE", str(tmp_path))
    (tmp_path / "kernels").mkdir()
    d = (_FakeDispatcher(), _FakeDispatcher())
    assert not jitcache.is_cached(d)
    with caplog.at_level(logging.INFO, logger="dchfrac.solver"):
        assert jitcache.announce("k1", d)
        assert jitcache.announce("k1", d)  # the same key: announced once
        jitcache.finished("k1")  # not compiled yet: no report
        for x in d:
            x.signatures.append("sig")
        jitcache.finished("k1")
        jitcache.finished("k1")
    msgs = [r.getMessage() for r in caplog.records]
    assert sum("compiling kernels (first run, ~" in m for m in msgs) == 1
    assert sum(m.startswith("kernels compiled in") for m in msgs) == 1
    assert jitcache.compile_estimate_s() >= 0.0 and (tmp_path / "kernels" / "compile_seconds.txt").is_file()
    assert jitcache.is_cached(d)  # compiled in this process: nothing more to announce
    assert not jitcache.announce("k2", d)


def test_unwritable_cache_folder_warns_once_and_keeps_the_kernels_in_a_temporary_folder(tmp_path, monkeypatch,
                                                                                       caplog):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    monkeypatch.setenv("DCHFRAC_CACHE", str(blocker / "cache"))  # below a file: cannot be created, even by root
    with caplog.at_level(logging.WARNING, logger="dchfrac.solver"):
        m1 = codegen._load_module("X = 1\n")
        m2 = codegen._load_module("X = 2\n")
    assert (m1.X, m2.X) == (1, 2)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "DCHFRAC_CACHE" in warnings[0] and "not writable" in warnings[0]
    assert str(blocker / "cache") in warnings[0]

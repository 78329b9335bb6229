"""Cheap wall-time accounting of one run by phase and by part of the run.

A :class:`Profile` keeps ``time.perf_counter`` accumulators (seconds) keyed by
(part, phase).  Phases nest: entering a phase pauses the enclosing one, so the
times are exclusive and add up to the wall time between :meth:`Profile.start`
and :meth:`Profile.stop`; whatever no named phase claims is ``python`` (the
time loop's own work, Newton's bookkeeping, interpreter overhead).  The cost is
two ``perf_counter`` calls per phase entry (about a microsecond), negligible
against a millisecond assembly, so every run keeps its profile.

The solver modules charge their work to the active profile through
:func:`phase`; :func:`activate` makes a profile active for the duration of one
run (one run per process or thread of control: the assembly threads only run
inside the ``assembly`` phase).
"""
from __future__ import annotations

import time
from contextlib import contextmanager

#: phases a run's wall time is split into (seconds, exclusive); ``python`` is the remainder
PHASES = ("setup", "assembly", "symbolic_factorization", "numeric_factorization", "solve", "damage", "stagger",
          "metrics", "output", "python")
#: the part of the run a step belongs to, by its start time: the start-up (t < STARTUP_S, s) or the rest
STARTUP_S = 0.05
PARTS = ("startup", "rest")


class Profile:
    """Exclusive wall seconds and entry counts per (part, phase); see the module docstring."""

    def __init__(self):
        self.part = "startup"
        self.seconds = {(p, ph): 0.0 for p in PARTS for ph in PHASES}
        self.calls = {(p, ph): 0 for p in PARTS for ph in PHASES}
        self.counters = {p: {} for p in PARTS}  # steps, rejections, Newton iterations ... per part
        self._stack = ["python"]
        self._mark = None
        self._t0 = None
        self.wall = 0.0

    def start(self) -> None:
        self._t0 = self._mark = time.perf_counter()

    def stop(self) -> None:
        now = time.perf_counter()
        self._charge(now)
        self.wall = now - self._t0

    def _charge(self, now: float) -> None:
        if self._mark is not None:
            self.seconds[(self.part, self._stack[-1])] += now - self._mark
        self._mark = now

    def enter(self, name: str) -> None:
        self._charge(time.perf_counter())
        self._stack.append(name)
        self.calls[(self.part, name)] += 1

    def leave(self) -> None:
        self._charge(time.perf_counter())
        self._stack.pop()

    def set_part(self, t: float) -> None:
        """Charge what follows to the part of simulated time ``t`` (s)."""
        part = "startup" if t < STARTUP_S else "rest"
        if part != self.part:
            self._charge(time.perf_counter())
            self.part = part

    def count(self, name: str, n: int = 1) -> None:
        c = self.counters[self.part]
        c[name] = c.get(name, 0) + n

    def to_dict(self) -> dict:
        """JSON-ready breakdown: seconds and calls by phase, per part and in total, and the counters."""
        def block(parts):
            sec = {ph: sum(self.seconds[(p, ph)] for p in parts) for ph in PHASES}
            calls = {ph: sum(self.calls[(p, ph)] for p in parts) for ph in PHASES}
            counters = {}
            for p in parts:
                for k, v in self.counters[p].items():
                    counters[k] = counters.get(k, 0) + v
            total = sum(sec.values())
            return {"wall_s": total, "seconds": sec, "fraction": {ph: s / total if total else 0.0 for ph, s in sec.items()},
                    "calls": calls, "counters": counters}

        return {"units": "wall seconds (exclusive per phase)", "startup_s": STARTUP_S, "wall_s": self.wall,
                "total": block(PARTS), "by_part": {p: block((p,)) for p in PARTS}}


class _Null:
    """The inactive profile: every call does nothing."""

    part = None

    def enter(self, name):
        pass

    def leave(self):
        pass

    def set_part(self, t):
        pass

    def count(self, name, n=1):
        pass


_NULL = _Null()
_ACTIVE = [_NULL]


def active():
    """The profile work is charged to (a do-nothing object outside :func:`activate`)."""
    return _ACTIVE[-1]


@contextmanager
def activate(profile: Profile):
    """Make ``profile`` the active one inside the block, started and stopped with it."""
    _ACTIVE.append(profile)
    profile.start()
    try:
        yield profile
    finally:
        profile.stop()
        _ACTIVE.pop()


class phase:
    """``with phase("assembly"): ...`` charges the block to the active profile (exclusive of nested phases)."""

    __slots__ = ("name", "prof")

    def __init__(self, name: str):
        self.name = name

    def __enter__(self):
        self.prof = _ACTIVE[-1]
        self.prof.enter(self.name)
        return self

    def __exit__(self, *exc):
        self.prof.leave()
        return False

"""Progress of one run: a bar with % of t_end and ETA on a terminal, plain periodic log lines otherwise.

On a terminal (``stream.isatty()``) the bar is redrawn in place with ``\\r``; anywhere else (a log
file, a pipe, a batch job) every ``every_s`` seconds one INFO line goes to the logger
``dchfrac.solver``, never a ``\\r``.

The ETA is the remaining simulated time at the wall seconds per simulated second measured since the first
report, that is after the set-up and the first step (which hold the one-off costs: the mesh, the symbolic
analysis, the compilation of the kernels on a first run).  It is shown only once it means something: after
``min_steps`` reports and ``min_fraction`` of t_end (the first steps are the smallest, dt grows from dt0, so an
early rate overstates the cost many times: 21 h for a 2 min run, issue #49); before that it reads ``ETA --``.
"""
from __future__ import annotations

import logging
import math
import sys
import time

__all__ = ["StepProgress", "format_duration"]

LOG = logging.getLogger("dchfrac.solver")


def format_duration(s: float) -> str:
    """``1h02m03s`` / ``2m03s`` / ``?`` (not finite)."""
    if not math.isfinite(s):
        return "?"
    s = int(round(s))
    h, r = divmod(s, 3600)
    m, sec = divmod(r, 60)
    return f"{h}h{m:02d}m{sec:02d}s" if h else f"{m}m{sec:02d}s"


class StepProgress:
    """Reports a run's simulated time t (s) out of ``t_end`` (s) with its ETA.

    stream : where a terminal bar goes (default stderr); tty : force the terminal (True) or the
    log-line (False) mode, default ``stream.isatty()``; every_s : seconds between log lines;
    clock : wall clock in s (``time.perf_counter``); min_steps, min_fraction : reports and fraction of t_end
    before an ETA is shown.
    """

    def __init__(self, t_end: float, stream=None, tty: bool | None = None, every_s: float = 10.0,
                 width: int = 24, clock=time.perf_counter, min_steps: int = 5, min_fraction: float = 0.05):
        self.t_end, self.stream = float(t_end), stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self.every_s, self.width, self.clock = every_s, width, clock
        self.min_steps, self.min_fraction = int(min_steps), float(min_fraction)
        self.t0 = clock()
        self.first = None  # (wall clock, simulated time) of the first report: the start of the measured rate
        self.reports = 0
        self.last_line = -math.inf
        self.drawn = False

    def eta(self, t: float) -> float:
        """Wall seconds left at simulated time ``t`` (s), or NaN while the rate does not mean anything yet."""
        frac = t / self.t_end if self.t_end > 0 else 1.0
        if self.first is None or self.reports < self.min_steps or frac < self.min_fraction or t <= self.first[1]:
            return math.nan
        return (self.clock() - self.first[0]) * max(self.t_end - t, 0.0) / (t - self.first[1])

    def line(self, t: float, detail: str = "") -> str:
        """Text of one report: % of t_end, simulated time, elapsed wall time, ETA, then ``detail``."""
        frac = min(max(t / self.t_end, 0.0), 1.0) if self.t_end > 0 else 1.0
        elapsed = self.clock() - self.t0
        eta = self.eta(t)
        text = (f"{100 * frac:5.1f}% t = {t:.4g} of {self.t_end:g} s, elapsed {format_duration(elapsed)}, "
                f"ETA {format_duration(eta) if math.isfinite(eta) else '--'}")
        return f"{text} | {detail}" if detail else text

    def update(self, t: float, detail: str = "") -> None:
        """Report simulated time ``t`` (s): redraw the bar, or log a line when ``every_s`` has passed."""
        self.reports += 1
        if self.first is None:
            self.first = (self.clock(), float(t))
        if self.tty:
            frac = min(max(t / self.t_end, 0.0), 1.0) if self.t_end > 0 else 1.0
            n = int(round(frac * self.width))
            bar = "#" * n + "-" * (self.width - n)
            self.stream.write(f"\r[{bar}] {self.line(t, detail)}  ")
            self.stream.flush()
            self.drawn = True
            return
        now = self.clock()
        if now - self.last_line >= self.every_s or t >= self.t_end:
            self.last_line = now
            LOG.info(self.line(t, detail))

    def close(self) -> None:
        """End the bar's line on a terminal (nothing to do for log lines)."""
        if self.tty and self.drawn:
            self.stream.write("\n")
            self.stream.flush()

"""Where a campaign's hours went: run time, waiting cores, breaks, and the runs per hour it achieved.

Every run record holds ``started_at`` and ``finished_at`` (ISO 8601, s resolution, local time of the host). From
them alone (no log, no clock of the campaign process):

* the campaign's *activity* is the union of the run intervals, joined across gaps shorter than ``break_s``: a gap
  in which no run is in flight is a pause of the campaign process (a sampler fit, table writing) when short, and a
  break (the process was not running) when long;
* the *slots* are the most runs seen in flight at once (the campaign's ``--jobs``);
* busy core time is the sum of the runs' wall times; the slots' time during activity, less that, is *waiting*:
  cores a round leaves idle while its slowest run finishes, and the sampler's pauses between rounds;
* a run resumed from its checkpoint records the times of its last piece only; its earlier pieces
  (:func:`earlier_pieces_s`) count as busy time, and as activity of one slot (``earlier / slots``), since when they
  ran is not recorded.

Units: seconds and hours as named; utilization dimensionless.
"""
from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Iterable, Mapping

__all__ = ["Throughput", "campaign_throughput", "run_intervals", "earlier_pieces_s"]

_RESOLUTION_S = 1.0  # s: the records' times are written to the second
BREAK_S = 600.0  # s: a gap with no run in flight longer than this is a break, not waiting


@dataclass(frozen=True)
class Throughput:
    """A campaign's accounting (see the module docstring). Times in s."""

    runs: int
    slots: int
    periods: int
    active_s: float
    busy_s: float
    waiting_s: float
    breaks_s: float
    resumed_s: float = 0.0  # wall time of the earlier pieces of resumed runs (in busy_s and active_s)

    @property
    def utilization(self) -> float:
        """Busy core time over the slots' time during activity (0..1)."""
        return self.busy_s / (self.slots * self.active_s) if self.active_s > 0 else float("nan")

    @property
    def runs_per_hour(self) -> float:
        """Runs finished per hour of activity."""
        return 3600.0 * self.runs / self.active_s if self.active_s > 0 else float("nan")

    def text(self) -> str:
        """One line for ``dchfrac campaign status`` and the report."""
        if not self.runs:
            return "throughput: no run with start and end times yet"
        return (f"throughput: {self.runs} runs in {self.active_s / 3600:.2f} h of activity "
                f"({self.periods} period(s); breaks {self.breaks_s / 3600:.2f} h not counted): "
                f"{self.runs_per_hour:.1f} runs/h on {self.slots} slot(s); cores busy {100 * self.utilization:.1f} %, "
                f"{self.waiting_s / 3600:.2f} core-h waiting (rounds ending on their slowest run, sampler pauses)"
                + (f"; {self.resumed_s / 3600:.2f} h of it in earlier pieces of runs resumed from their checkpoints "
                   "(when they ran is not recorded: counted busy on one slot)" if self.resumed_s > 0 else ""))


def _time(v: str, key: str, field: str) -> float:
    try:
        return datetime.fromisoformat(v).timestamp()
    except (TypeError, ValueError):
        raise ValueError(f"run {key}: {field}={v!r} is not an ISO 8601 time") from None


def earlier_pieces_s(rec: Mapping) -> float:
    """Wall time (s) that a run resumed from its checkpoint spent in its pieces before the last: the record's
    ``resumed_wall_s`` (``sweep.campaign.scheduler``); for a record written before the scheduler kept it, the excess
    of the solver's own wall time (``metrics.solver_wall_time_s``, which carries the earlier pieces) over the
    record's; 0 for a run made in one piece."""
    if "resumed_wall_s" in rec:
        return float(rec["resumed_wall_s"] or 0.0)
    wall, solver = rec.get("wall_time_s"), (rec.get("metrics") or {}).get("solver_wall_time_s")
    known = all(isinstance(v, (int, float)) and v == v for v in (wall, solver))
    return max(0.0, solver - wall) if known else 0.0


def run_intervals(records: Mapping[str, Mapping]) -> list[tuple[float, float]]:
    """(start, end) in s (POSIX time) of every record with both times, sorted by start; an end up to the
    records' 1 s resolution before its start is taken as the start (ValueError if earlier still)."""
    out = []
    for key, rec in records.items():
        a, b = rec.get("started_at"), rec.get("finished_at")
        if a is None or b is None:
            continue
        t0, t1 = _time(a, key, "started_at"), _time(b, key, "finished_at")
        if t1 < t0 - _RESOLUTION_S:
            raise ValueError(f"run {key}: finished_at {b} is before started_at {a}")
        t1 = max(t1, t0)  # the two times are rounded apart: a run shorter than 1 s may end "before" it starts
        out.append((t0, t1))
    return sorted(out)


def _max_in_flight(intervals: Iterable[tuple[float, float]]) -> int:
    """Most intervals open at once (an interval ending when another starts does not overlap it)."""
    events = sorted([(t0, 1) for t0, _ in intervals] + [(t1, -1) for _, t1 in intervals])
    n = best = 0
    for _, step in events:
        n += step
        best = max(best, n)
    return best


def _activity(intervals: list[tuple[float, float]], break_s: float) -> tuple[float, float, int]:
    """(active s, breaks s, periods): the intervals' union, gaps under ``break_s`` joined in."""
    active = breaks = 0.0
    periods = 0
    start, end = intervals[0]
    for t0, t1 in intervals[1:]:
        if t0 - end > break_s:
            active += end - start
            breaks += t0 - end
            periods += 1
            start = t0
        end = max(end, t1)
    return active + (end - start), breaks, periods + 1


def campaign_throughput(records: Mapping[str, Mapping], *, break_s: float = BREAK_S) -> Throughput:
    """The accounting of a campaign's run records ({key: record}, as ``ResultsStore.records``).

    break_s : s; a gap with no run in flight longer than this is a break (default :data:`BREAK_S`).
    """
    if not break_s >= 0:
        raise ValueError(f"break_s={break_s!r}: must be >= 0 s")
    iv = run_intervals(records)
    if not iv:
        return Throughput(0, 0, 0, 0.0, 0.0, 0.0, 0.0)
    slots = max(1, _max_in_flight(iv))  # runs shorter than the records' 1 s resolution overlap nothing
    active, breaks, periods = _activity(iv, break_s)
    earlier = sum(earlier_pieces_s(r) for r in records.values() if r.get("started_at") and r.get("finished_at"))
    active += earlier / slots
    busy = sum(t1 - t0 for t0, t1 in iv) + earlier
    return Throughput(len(iv), slots, periods, active, busy, max(0.0, slots * active - busy), breaks, earlier)

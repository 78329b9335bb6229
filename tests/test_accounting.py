"""Campaign accounting (sweep.campaign.accounting) on records with known start and end times."""
from __future__ import annotations

from datetime import datetime, timedelta

import pytest

from sweep.campaign.accounting import campaign_throughput, run_intervals

T0 = datetime(2026, 11, 26, 12, 0, 0)


def _rec(start_s: float, end_s: float) -> dict:
    return {"started_at": (T0 + timedelta(seconds=start_s)).isoformat(timespec="seconds"),
            "finished_at": (T0 + timedelta(seconds=end_s)).isoformat(timespec="seconds"), "status": "ok"}


def test_synchronous_rounds_on_two_slots_known_waiting():
    # two rounds of two runs: 100 s and 60 s, then 80 s and 80 s, 10 s of sampler pause between the rounds
    recs = {"a": _rec(0, 100), "b": _rec(0, 60), "c": _rec(110, 190), "d": _rec(110, 190)}
    acc = campaign_throughput(recs)
    assert (acc.runs, acc.slots, acc.periods) == (4, 2, 1)
    assert acc.active_s == 190.0 and acc.busy_s == 320.0 and acc.breaks_s == 0.0
    # 2 x 190 slot-seconds: 40 s waiting for the slow run of round 1, 2 x 10 s of pause
    assert acc.waiting_s == 60.0
    assert acc.utilization == pytest.approx(320.0 / 380.0, rel=1e-12)
    assert acc.runs_per_hour == pytest.approx(4 * 3600.0 / 190.0, rel=1e-12)
    assert "4 runs" in acc.text() and "2 slot(s)" in acc.text()


def test_a_long_gap_is_a_break_not_waiting():
    recs = {"a": _rec(0, 100), "b": _rec(0, 100), "c": _rec(3700, 3800), "d": _rec(3700, 3800)}
    acc = campaign_throughput(recs)
    assert (acc.periods, acc.active_s, acc.breaks_s, acc.waiting_s) == (2, 200.0, 3600.0, 0.0)
    assert acc.utilization == 1.0
    # with a break threshold above the gap, the gap is waiting
    joined = campaign_throughput(recs, break_s=4000.0)
    assert (joined.periods, joined.active_s, joined.waiting_s) == (1, 3800.0, 2 * 3800.0 - 400.0)


def test_touching_runs_are_one_slot_and_records_without_times_are_left_out():
    recs = {"a": _rec(0, 50), "b": _rec(50, 80), "old": {"status": "ok"}}
    acc = campaign_throughput(recs)
    assert (acc.runs, acc.slots, acc.waiting_s) == (2, 1, 0.0)
    assert campaign_throughput({}).runs == 0 and "no run" in campaign_throughput({}).text()


def test_bad_times_are_named():
    with pytest.raises(ValueError, match=r"run x: started_at='yesterday'"):
        run_intervals({"x": {"started_at": "yesterday", "finished_at": "2026-11-26T12:00:00"}})
    with pytest.raises(ValueError, match="run y: finished_at .* is before started_at"):
        run_intervals({"y": _rec(10, 5)})
    # within the records' 1 s resolution an end may be written before the start: an instant run
    assert run_intervals({"z": _rec(10, 9)}) == [(run_intervals({"s": _rec(10, 10)})[0])]
    with pytest.raises(ValueError, match="break_s=-1"):
        campaign_throughput({}, break_s=-1)


def test_runs_shorter_than_the_time_resolution_still_occupy_a_slot():
    # records have 1 s resolution: instant runs (start = end) in successive seconds
    recs = {k: _rec(i, i) for i, k in enumerate("abc")}
    acc = campaign_throughput(recs)
    assert (acc.runs, acc.slots, acc.busy_s, acc.active_s) == (3, 1, 0.0, 2.0)
    assert acc.utilization == 0.0 and "3 runs" in acc.text()


def test_the_earlier_pieces_of_a_resumed_run_count_as_busy_time_on_one_slot():
    # one slot: a run in one piece (100 s), a run resumed after 7,000 s in earlier pieces whose record keeps them
    # (resumed_wall_s), and an older record whose solver wall time carries 2,000 s more than its own
    from sweep.campaign.accounting import earlier_pieces_s

    new = {**_rec(100, 500), "wall_time_s": 7400.0, "resumed_wall_s": 7000.0}
    old = {**_rec(500, 900), "wall_time_s": 400.0, "metrics": {"solver_wall_time_s": 2390.0}}
    assert (earlier_pieces_s(new), earlier_pieces_s(old), earlier_pieces_s(_rec(0, 100))) == (7000.0, 1990.0, 0.0)
    acc = campaign_throughput({"a": _rec(0, 100), "b": new, "c": old})
    assert acc.slots == 1 and acc.resumed_s == 8990.0
    assert acc.active_s == 900.0 + 8990.0 and acc.busy_s == 900.0 + 8990.0 and acc.waiting_s == 0.0
    assert acc.runs_per_hour == pytest.approx(3 * 3600.0 / 9890.0, rel=1e-12)
    assert "2.50 h of it in earlier pieces" in acc.text()

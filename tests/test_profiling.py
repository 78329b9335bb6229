"""solver.profiling: exclusive phase times on a fake clock (known answers), parts, and a run's profile adding up."""
import pytest

from solver import profiling
from solver.profiling import Profile, activate, phase


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


@pytest.fixture
def clock(monkeypatch):
    c = FakeClock()
    monkeypatch.setattr(profiling.time, "perf_counter", c)
    return c


def test_nested_phases_are_exclusive(clock):
    prof = Profile()
    with activate(prof):
        clock.t += 1.0  # python
        with phase("assembly"):
            clock.t += 2.0
            with phase("numeric_factorization"):
                clock.t += 3.0
            clock.t += 0.5
        clock.t += 0.25
    d = prof.to_dict()
    sec = d["total"]["seconds"]
    assert sec["assembly"] == pytest.approx(2.5)
    assert sec["numeric_factorization"] == pytest.approx(3.0)
    assert sec["python"] == pytest.approx(1.25)
    assert d["wall_s"] == pytest.approx(6.75)
    assert d["total"]["wall_s"] == pytest.approx(d["wall_s"])
    assert d["total"]["calls"]["assembly"] == 1


def test_parts_split_by_simulated_time(clock):
    prof = Profile()
    with activate(prof):
        prof.set_part(0.0)
        with phase("solve"):
            clock.t += 1.0
        prof.count("accepted_steps")
        prof.set_part(profiling.STARTUP_S)  # the first step that starts at 0.05 s belongs to the rest
        with phase("solve"):
            clock.t += 4.0
        prof.count("accepted_steps", 2)
    d = prof.to_dict()
    assert d["by_part"]["startup"]["seconds"]["solve"] == pytest.approx(1.0)
    assert d["by_part"]["rest"]["seconds"]["solve"] == pytest.approx(4.0)
    assert d["by_part"]["startup"]["counters"] == {"accepted_steps": 1}
    assert d["total"]["counters"] == {"accepted_steps": 3}


def test_phase_outside_a_profile_does_nothing():
    assert profiling.active().part is None
    with phase("assembly"):
        pass


def test_run_profile_adds_up_to_its_wall_time():
    from solver import Parameters, RunOptions, simulate

    res = simulate(Parameters(), RunOptions(h=8.0, t_end=0.004, dt0=1e-3, snapshot_times=[]))
    assert res.status == "ok"
    tot = res.profile["total"]
    assert sum(tot["seconds"].values()) == pytest.approx(res.profile["wall_s"], rel=1e-9)
    assert res.profile["wall_s"] <= res.wall_time
    assert tot["counters"]["accepted_steps"] == len(res.timeseries)
    assert tot["calls"]["numeric_factorization"] == res.factorizations
    assert tot["seconds"]["assembly"] > 0 and tot["seconds"]["damage"] > 0

"""RunOptions: validation names the option, value and range; TOML round trip is exact."""
import pytest

from solver import RunOptions


@pytest.mark.parametrize("name,value", [
    ("h", 0.0), ("h", -1.0), ("h", 30.0), ("t_end", 0.0), ("dt0", 1.0), ("dt_cut", 1.5), ("dt_grow", 0.5),
    ("newton_max_its", 0), ("newton_rtol", 0.5), ("stagger_tol", 0.0), ("linear_solver", "mumps"),
    ("snapshot_times", [-1.0]), ("stop_front_radius", -5.0), ("jacobian_reuse", 1.5), ("h", "fine"),
])
def test_bad_option_is_rejected_by_name(name, value):
    with pytest.raises(ValueError) as e:
        RunOptions(**{name: value})
    assert name in str(e.value) and repr(value)[:8] in str(e.value)


def test_unknown_option_rejected():
    with pytest.raises(ValueError, match="mesh_size"):
        RunOptions.from_dict({"mesh_size": 1.0})


def test_toml_round_trip(tmp_path):
    o = RunOptions(h=2.5, t_end=1.25, snapshot_times=[0.1, 0.7], stop_front_radius=40.0, linear_solver="superlu")
    o.to_toml(tmp_path / "o.toml")
    assert RunOptions.from_toml(tmp_path / "o.toml") == o


@pytest.mark.parametrize("kw,allowed", [
    (dict(h_inner=0.0), "(0, h = 1.0]"), (dict(h_inner=-0.5), "(0, h = 1.0]"), (dict(h_inner=1.5), "(0, h = 1.0]"),
    (dict(h=2.0, h_inner=2.5), "(0, h = 2.0]"), (dict(h_inner=float("nan")), "a finite number"),
    (dict(h_inner="fine"), "a number"), (dict(h_inner=True), "a number"),
])
def test_h_inner_validation(kw, allowed):
    with pytest.raises(ValueError) as e:
        RunOptions(**kw)
    v = kw["h_inner"]
    assert f"run option h_inner={v!r} is out of range: allowed {allowed}" == str(e.value)


def test_h_inner_accepted_and_round_trips(tmp_path):
    for v in (0.25, 1.0, 1):
        assert RunOptions(h_inner=v).h_inner == v
    o = RunOptions(h=2.0, h_inner=0.5)
    assert o.to_dict()["h_inner"] == 0.5
    assert RunOptions.from_dict(o.to_dict()) == o
    o.to_toml(tmp_path / "o.toml")
    assert RunOptions.from_toml(tmp_path / "o.toml") == o


def test_h_inner_none_keeps_old_option_dicts():
    # runs stored before h_inner existed are keyed on option dicts without it: the default
    # (None) is left out of to_dict, so their run keys / cache hashes are unchanged
    d = RunOptions().to_dict()
    assert "h_inner" not in d
    assert RunOptions.from_dict(d) == RunOptions() and RunOptions.from_dict(d).h_inner is None
    assert RunOptions.from_dict({**d, "h_inner": None}) == RunOptions()

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

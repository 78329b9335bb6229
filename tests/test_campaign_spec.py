"""Campaign specs: grid expansion, validation errors, run keys, and the paper's campaign files."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from sweep.campaign.sampler import GridSampler, grid_points
from sweep.campaign.spec_model import canonical_json
from sweep.campaign.spec import SpecError, load_spec, spec_from_dict
from sweep.campaign.store import run_key

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGNS = ROOT / "campaigns"


def _campaign(name: str) -> Path:
    """The one spec of that name in the campaigns/ folders (examples, paper, studies, discrepancy)."""
    (path,) = CAMPAIGNS.rglob(f"{name}.toml")
    return path


def _swept(spec):
    return [dict(p.swept) for p in grid_points(spec)]


# ---------------------------------------------------------------------------
# grid expansion
# ---------------------------------------------------------------------------
def test_crossed_axes_first_axis_slowest():
    s = spec_from_dict({"name": "c", "axes": {"cement": [0.5, 1.0, 2.0], "eta_o": [0.1, 0.2]}})
    assert _swept(s) == [
        {"cement": 0.5, "eta_o": 0.1}, {"cement": 0.5, "eta_o": 0.2},
        {"cement": 1.0, "eta_o": 0.1}, {"cement": 1.0, "eta_o": 0.2},
        {"cement": 2.0, "eta_o": 0.1}, {"cement": 2.0, "eta_o": 0.2},
    ]


def test_log_and_linear_ranges_give_the_exact_values():
    s = spec_from_dict({"name": "r", "mode": "zip",
                        "axes": {"eta_o": {"log": [1e-4, 1.0, 5]}, "cement": {"linear": [0.5, 3.0, 5]}}})
    pts = _swept(s)
    # log: decades 1e-4 .. 1 in 5 points -> exactly one decade apart (rounded to 12 digits)
    assert [p["eta_o"] for p in pts] == [1e-4, 1e-3, 1e-2, 1e-1, 1.0]
    # linear: 0.5 .. 3.0 in 5 points -> step 0.625
    assert [p["cement"] for p in pts] == [0.5, 1.125, 1.75, 2.375, 3.0]


def test_range_step_includes_stop_and_keeps_integers():
    s = spec_from_dict({"name": "r", "axes": {"seed": {"range": [1, 7, 3]}, "w_i": {"range": [25.0, 100.0, 25.0]}}})
    pts = _swept(s)
    assert sorted({p["seed"] for p in pts}) == [1, 4, 7]
    assert all(isinstance(p["seed"], int) for p in pts)  # Parameters.seed must stay an int
    assert sorted({p["w_i"] for p in pts}) == [25.0, 50.0, 75.0, 100.0]
    assert len(pts) == 12


def test_zip_group_crossed_with_the_rest():
    s = spec_from_dict({"name": "z", "axes": {"cement": [1.0, 2.0], "eta_o": [0.1, 0.2, 0.3], "w_i": [10.0, 20.0, 30.0]},
                        "zip": [["eta_o", "w_i"]]})
    pts = _swept(s)
    assert len(pts) == 6  # 2 cement x 3 zipped pairs, not 2 x 3 x 3
    assert {(p["eta_o"], p["w_i"]) for p in pts} == {(0.1, 10.0), (0.2, 20.0), (0.3, 30.0)}


def test_mode_zip_zips_every_axis():
    s = spec_from_dict({"name": "z", "mode": "zip", "axes": {"cement": [1.0, 2.0], "eta_o": [0.1, 0.2]}})
    assert _swept(s) == [{"cement": 1.0, "eta_o": 0.1}, {"cement": 2.0, "eta_o": 0.2}]


def test_zipped_axis_may_repeat_a_value_when_the_points_differ():
    s = spec_from_dict({"name": "z", "mode": "zip", "axes": {"eta_o": [0.01, 1.0, 1.0], "kbar": [1e-4, 0.1, 1e-4]}})
    assert _swept(s) == [{"eta_o": 0.01, "kbar": 1e-4}, {"eta_o": 1.0, "kbar": 0.1}, {"eta_o": 1.0, "kbar": 1e-4}]
    s = spec_from_dict({"name": "z", "axes": {"cement": [1.0, 2.0], "eta_o": [0.1, 0.1], "w_i": [10.0, 20.0]},
                        "zip": [["eta_o", "w_i"]]})
    assert len(_swept(s)) == 4


def test_axis_over_run_option_and_explicit_namespace():
    s = spec_from_dict({"name": "h", "axes": {"h": [4.0, 2.0], "options": {"t_end": [1.0, 2.0]}}})
    pts = grid_points(s)
    assert [(p.options["h"], p.options["t_end"]) for p in pts] == [(4.0, 1.0), (4.0, 2.0), (2.0, 1.0), (2.0, 2.0)]
    # the model parameters are the defaults (Parameters(): reference experiment C = 1.2)
    assert all(p.params["cement"] == 1.2 for p in pts)


def test_blocks_union_with_shared_point_run_once():
    s = spec_from_dict({"name": "b", "base": {"psi_c": 0.00216, "Gc": 1.7213},
                        "blocks": [{"label": "psi_c", "axes": {"psi_c": [0.000216, 0.00216, 0.0216]}},
                                   {"label": "Gc", "axes": {"Gc": [0.17213, 1.7213, 17.213]}}]})
    pts = grid_points(s)
    assert len(pts) == 5
    shared = [p for p in pts if p.params["psi_c"] == 0.00216 and p.params["Gc"] == 1.7213]
    assert len(shared) == 1 and shared[0].blocks == ("psi_c", "Gc")


def test_derived_parameter_from_an_expression():
    s = spec_from_dict({"name": "d", "axes": {"cement": [1.0, 2.0]}, "derived": {"beta": "10*sqrt(cement) + 1"}})
    # derived values are rounded to 12 significant digits (like every generated value)
    assert [p.params["beta"] for p in grid_points(s)] == [11.0, pytest.approx(10 * math.sqrt(2) + 1, rel=1e-11)]


def test_grid_sampler_never_refines():
    s = spec_from_dict({"name": "g", "axes": {"cement": [1.0]}})
    assert GridSampler().refine(s, None) == []


# ---------------------------------------------------------------------------
# validation: errors name the key
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "d, key",
    [
        ({"name": "x", "axes": {"etao": [1.0]}}, "axes.etao"),
        ({"name": "x", "base": {"foo": 1.0}}, "base.foo"),
        ({"name": "x", "options": {"hh": 1.0}}, "options.hh"),
        ({"name": "x", "colour": 1}, "colour"),
        ({"name": "x", "axes": {"eta_o": []}}, "axes.eta_o"),
        ({"name": "x", "axes": {"eta_o": {"log": [0.0, 1.0, 3]}}}, "axes.eta_o.log"),
        ({"name": "x", "axes": {"eta_o": {"log": [1e-3, 1.0, 2.5]}}}, "axes.eta_o.log"),
        ({"name": "x", "axes": {"eta_o": {"logspace": [1e-3, 1.0, 3]}}}, "axes.eta_o"),
        ({"name": "x", "axes": {"eta_o": [1.0, 2.0], "w_i": [1.0]}, "zip": [["eta_o", "w_i"]]}, "zip"),
        ({"name": "x", "axes": {"eta_o": [1.0]}, "zip": [["eta_o", "kbar"]]}, "zip"),
        ({"name": "x", "mode": "diagonal", "axes": {"eta_o": [1.0]}}, "mode"),
        ({"name": "x", "run": {"timeout": -1}}, "run.timeout"),
        ({"name": "x", "run": {"retry": 2}}, "run.retry"),
        ({"name": "x", "diagrams": [{"kind": "pie"}]}, "diagrams[0].kind"),
        ({"name": "x", "classify": {"min_crack_lenght": 2.0}}, "classify.min_crack_lenght"),
        ({"name": "x", "sampler": {"kind": "adaptive"}}, "sampler.kind"),
        ({"name": "x", "derived": {"beta": "2*cemnt"}}, "derived.beta"),
        ({"name": "bad name!"}, "name"),
    ],
)
def test_invalid_spec_names_the_key(d, key):
    with pytest.raises(SpecError) as e:
        spec_from_dict(d)
    assert f"{key}:" in str(e.value)


def test_out_of_range_value_in_the_grid_names_the_parameter_and_point():
    with pytest.raises(SpecError) as e:
        spec_from_dict({"name": "x", "axes": {"cement": [1.0, 2.0], "eta_o": [0.1, -0.2]}})
    msg = str(e.value)
    assert "eta_o" in msg and "-0.2" in msg and "grid point" in msg


def test_out_of_range_run_option_names_it():
    with pytest.raises(SpecError, match="h=-1.0"):
        spec_from_dict({"name": "x", "axes": {"h": [2.0, -1.0]}})


def test_toml_file_errors_name_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('name = "bad"\n[axes]\neta_o = {log = [1e-3, 1.0, 4]}\nkbar_ = [1e-3]\n')
    with pytest.raises(SpecError) as e:
        load_spec(p)
    assert str(p) in str(e.value) and "axes.kbar_" in str(e.value)


# ---------------------------------------------------------------------------
# run keys
# ---------------------------------------------------------------------------
def test_key_is_stable_under_float_noise_and_int_float():
    p = {"eta_o": 0.1, "seed": 1, "phi_range": 0.2}
    o = {"h": 4.0, "snapshot_times": [0.5, 1.0]}
    k = run_key(p, o, "1.0")
    assert k == run_key({"eta_o": 0.1000000000001, "seed": 1, "phi_range": 0.2}, o, "1.0")
    assert k == run_key({"seed": 1.0, "phi_range": 0.2, "eta_o": 0.1}, o, "1.0")  # order, int vs float
    assert k == run_key(p, {"h": 4, "snapshot_times": [0.5, 1]}, "1.0")
    assert len(k) == 16 and int(k, 16) >= 0


def test_key_changes_with_params_options_and_version():
    p, o = {"eta_o": 0.1}, {"h": 4.0}
    k = run_key(p, o, "1.0")
    assert run_key({"eta_o": 0.1001}, o, "1.0") != k  # 4th significant digit
    assert run_key(p, {"h": 2.0}, "1.0") != k
    assert run_key(p, o, "1.1") != k


def test_canonical_json_rounds_to_twelve_digits():
    assert canonical_json({"a": 0.1 + 0.2}) == canonical_json({"a": 0.3}) == '{"a":0.3}'
    assert canonical_json({"a": 1e-3 * (1 + 1e-9)}) != canonical_json({"a": 1e-3})


def test_range_values_give_the_same_key_as_typed_values():
    a = grid_points(spec_from_dict({"name": "a", "axes": {"eta_o": {"log": [1e-3, 1.0, 4]}}}))
    b = grid_points(spec_from_dict({"name": "b", "axes": {"eta_o": [0.001, 0.01, 0.1, 1.0]}}))
    assert [run_key(p.params, p.options, "v") for p in a] == [run_key(p.params, p.options, "v") for p in b]


# ---------------------------------------------------------------------------
# the paper's campaign files
# ---------------------------------------------------------------------------
EXPECTED_SIZES = {"reference": 1, "mesh_convergence": 3, "ca_star_vs_cement": 30, "fracture_sensitivity": 7,
                  "branching_number": 7, "nf_vs_nb": 80, "demo": 6, "fracture_sensitivity_coarse": 7, "ca_star_vs_cement_coarse": 16,
                  "ca_star_vs_cement_h2": 30, "fracture_sensitivity_h2": 7, "branching_number_h2": 7, "nf_vs_nb_h2": 80}


@pytest.mark.parametrize("name", ["ca_star_vs_cement", "fracture_sensitivity", "branching_number", "nf_vs_nb"])
def test_h2_campaigns_are_their_studies_at_h_2(name):
    """The h = 2 mm versions run exactly the grid of the h = 1 mm study, only the mesh differs."""
    full, h2 = (grid_points(load_spec(_campaign(n))) for n in (name, f"{name}_h2"))
    assert [p.params for p in full] == [p.params for p in h2]
    assert all(p.options["h"] == 1.0 for p in full) and all(p.options["h"] == 2.0 for p in h2)
    assert [{**p.options, "h": 0} for p in full] == [{**p.options, "h": 0} for p in h2]


@pytest.mark.parametrize("name", sorted(EXPECTED_SIZES))
def test_campaign_files_load_with_expected_grid_size(name):
    spec = load_spec(_campaign(name))
    assert spec.name == name
    assert len(grid_points(spec)) == EXPECTED_SIZES[name]


def test_reference_campaign_is_sec_3_5():
    (p,) = grid_points(load_spec(_campaign("reference")))
    assert (p.params["cement"], p.params["eta_o"], p.params["eta_w"], p.params["kbar"]) == (1.2, 0.29, 1e-6, 0.0015)
    assert (p.options["h"], p.options["t_end"]) == (1.0, 2.0)


def test_mesh_convergence_uses_pockets_and_three_meshes():
    pts = grid_points(load_spec(_campaign("mesh_convergence")))
    assert [p.options["h"] for p in pts] == [4.0, 2.0, 1.0]
    assert {p.params["porosity_field"] for p in pts} == {"pockets"}


def test_ca_star_campaign_spans_two_decades_and_the_cement_range():
    pts = grid_points(load_spec(_campaign("ca_star_vs_cement")))
    prod = sorted({p.params["eta_o"] * p.params["w_i"] for p in pts})
    assert prod[-1] / prod[0] == pytest.approx(100.0, rel=1e-9)
    assert sorted({p.params["cement"] for p in pts}) == [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    assert all(p.params["Gc"] is None and p.params["beta"] is None for p in pts)  # laws of C


def test_fracture_sensitivity_is_tenfold_around_the_c12_laws():
    pts = grid_points(load_spec(_campaign("fracture_sensitivity")))
    C = 1.2
    law = {"psi_c": 0.0015 * C**2, "Gc": (0.26 * C + 1.0) ** 2, "beta": 65.7 * math.sqrt(C)}
    for name, ref in law.items():
        vals = sorted({p.params[name] for p in pts})
        # reference values rounded in the spec to 4-5 digits
        assert vals == pytest.approx([ref / 10, ref, ref * 10], rel=2e-4)
        others = [p for p in pts if p.params[name] != vals[1]]
        assert len(others) == 2  # only its own row moves it


def test_branching_number_rows_match_the_paper():
    tomllib = pytest.importorskip("tomllib")
    ref = ROOT.parent / "shared" / "data" / "paper_reported.toml"
    if not ref.exists():
        pytest.skip("shared/data/paper_reported.toml not beside the repository")
    rows = tomllib.loads(ref.read_text())["branching_number_sensitivity"]
    pts = grid_points(load_spec(_campaign("branching_number")))
    for row, var in (("permeability_row", "kbar"), ("water_viscosity_row", "eta_w"), ("oil_viscosity_row", "eta_o")):
        fixed = {k: v for k, v in rows[row].items() if k in ("kbar", "eta_w", "eta_o")}
        got = sorted(p.params[var] for p in pts if all(p.params[k] == v for k, v in fixed.items() if k != var))
        assert got == sorted(fixed[var])


def test_nf_vs_nb_covers_appendix_a_ranges():
    pts = grid_points(load_spec(_campaign("nf_vs_nb")))
    for name, (lo, hi) in {"eta_o": (1e-4, 1.0), "eta_w": (1e-6, 1e-3), "kbar": (1e-4, 1e-1)}.items():
        vals = [p.params[name] for p in pts]
        assert min(vals) == lo and max(vals) == hi


def test_demo_is_coarse_and_spans_both_sides():
    pts = grid_points(load_spec(_campaign("demo")))
    assert {p.options["h"] for p in pts} == {4.0}
    cs = sorted({p.params["cement"] for p in pts})
    assert cs[0] <= 0.5 and cs[-1] >= 3.0


def test_draws_campaign_is_the_h2_boundary_points_on_three_seeds():
    """ca_star_boundary_h2_draws reruns exactly the 46 points of ca_star_boundary_h2_floor (its table) with every
    setting of that campaign; only the porosity seed varies (0, 1, 2)."""
    import csv

    pts = grid_points(load_spec(_campaign("ca_star_boundary_h2_draws")))
    floor = load_spec(_campaign("ca_star_boundary_h2_floor"))
    with open(ROOT / "results" / "ca_star_boundary_h2_floor" / "table.csv", newline="") as f:
        table = [(float(r["cement"]), float(r["eta_o"])) for r in csv.DictReader(f)]
    assert len(table) == 46 and len(pts) == 3 * 46
    for seed in (0, 1, 2):
        assert [(p.params["cement"], p.params["eta_o"]) for p in pts if p.params["seed"] == seed] == table
    ref = grid_points(floor)[0]  # the floor campaign's initial grid: the same settings at every point
    varied = {"cement", "eta_o", "seed"}
    for p in pts:
        assert {k: v for k, v in p.params.items() if k not in varied} == {
            k: v for k, v in ref.params.items() if k not in varied}
        assert p.options == ref.options
        assert p.params["w_i"] == 50.0 and p.options["h"] == 2.0
    assert floor.classify == load_spec(_campaign("ca_star_boundary_h2_draws")).classify


def test_pocket_mesh_stage_is_the_sampler_points_on_a_perturbed_mesh():
    """ca_star_boundary_h2_pockets_meshes reruns exactly the points of ca_star_boundary_h2_pockets (its table; the
    order is the sampler's, which a report may change in the table) with every setting of that campaign; only
    mesh_seed is added (1)."""
    import csv

    pts = grid_points(load_spec(_campaign("ca_star_boundary_h2_pockets_meshes")))
    sampler = load_spec(_campaign("ca_star_boundary_h2_pockets"))
    with open(ROOT / "results" / "ca_star_boundary_h2_pockets" / "table.csv", newline="") as f:
        table = [(float(r["cement"]), float(r["eta_o"])) for r in csv.DictReader(f)]
    assert len(table) == 60 and sorted((p.params["cement"], p.params["eta_o"]) for p in pts) == sorted(table)
    ref = grid_points(sampler)[0]
    for p in pts:
        assert {k: v for k, v in p.params.items() if k not in {"cement", "eta_o"}} == {
            k: v for k, v in ref.params.items() if k not in {"cement", "eta_o"}}
        assert p.options == {**ref.options, "mesh_seed": 1}
        assert p.params["porosity_field"] == "pockets" and p.options["h"] == 2.0
    assert sampler.classify == load_spec(_campaign("ca_star_boundary_h2_pockets_meshes")).classify

"""Figure conventions: units on axes, legends in swept values with units, one colour scale and one
colorbar per grid, diverging maps centred at zero, PNG at >= 200 dpi plus PDF.

Run folders in the solver's format are written by ``fake_runs.field_runner`` with known fields: the
volumetric strain of run (C, eta_o) is eps_v = C * eta_o * cos(theta) (both signs, a different
range in every run), so a grid that autoscaled each panel would give each panel its own limits.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from fake_runs import field_runner

from sweep.campaign import figures
from sweep.campaign.plot import plot_campaign
from sweep.campaign.run import run_campaign
from sweep.campaign.spec import spec_from_dict

VERSION = "test-fig"


@pytest.fixture()
def captured(monkeypatch):
    """The figures the campaign saves, kept open for inspection (and written too)."""
    figs = {}
    real = figures.save_figure

    def keep(fig, path, formats=("png", figures.VECTOR_FORMAT)):
        figs[Path(path).stem] = fig
        return real(fig, path, formats)

    monkeypatch.setattr(figures, "save_figure", keep)
    monkeypatch.setattr("matplotlib.pyplot.close", lambda *a, **k: None)
    return figs


def _spec():
    return spec_from_dict({"name": "fig", "axes": {"cement": [1.0, 2.0], "eta_o": [0.25, 1.0]},
                           "diagrams": [{"kind": "timeseries", "x": "t", "y": "p_inj"},
                                        {"kind": "fields", "field": "eps_v", "rows": "cement", "cols": "eta_o",
                                         "file": "grid.png"}]})


def test_fields_grid_shares_one_scale_centred_at_zero_with_one_colorbar(tmp_path, captured):
    spec = _spec()
    run_campaign(spec, tmp_path, runner=field_runner, jobs=1, code_hash=VERSION, progress=None)
    paths = plot_campaign(spec, tmp_path, code_hash=VERSION)
    fig = captured["grid"]
    panels = [ax for ax in fig.axes if ax.collections and ax.get_label() != "<colorbar>"]
    assert len(panels) == 4
    clims = {ax.collections[0].get_clim() for ax in panels}
    assert len(clims) == 1  # one scale for the grid
    lo, hi = clims.pop()
    # largest |eps_v| over all runs: C eta_o = 2 at the element centroid nearest theta = 0
    assert lo == -hi and 0.99 * 2.0 < hi <= 2.0
    assert panels[0].collections[0].get_cmap().name == figures.DIVERGING
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1 and bars[0].get_ylabel() == "eps_v (-)"
    titles = [ax.get_title() for ax in panels]
    assert not any("cement" in t for t in titles)  # the row variable is the row label, not in each title
    assert {t.splitlines()[0] for t in titles} == {"eta_o = 0.25 kPa·s", "eta_o = 1 kPa·s"}
    labels = [t.get_text() for ax in panels for t in ax.texts]
    assert sorted(labels) == ["cement = 1 %", "cement = 2 %"]
    assert {p.suffix for p in paths} == {".png", ".pdf"}


def test_timeseries_axes_have_units_and_legends_swept_values(tmp_path, captured):
    spec = _spec()
    run_campaign(spec, tmp_path, runner=field_runner, jobs=1, code_hash=VERSION, progress=None)
    plot_campaign(spec, tmp_path, code_hash=VERSION)
    ax = captured["timeseries"].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("t (s)", "p_inj (kPa)")
    legend = sorted(t.get_text() for t in ax.get_legend().get_texts())
    assert legend == sorted(f"cement = {c:g} %, eta_o = {e:g} kPa·s" for c in (1, 2) for e in (0.25, 1))


def test_png_at_200_dpi_and_a_vector_copy(tmp_path):
    from matplotlib.figure import Figure
    from PIL import Image

    fig = Figure(figsize=(2, 1))
    fig.subplots().plot([0, 1], [0, 1])
    png, pdf = figures.save_figure(fig, tmp_path / "a.png")
    assert Image.open(png).info["dpi"] == pytest.approx((200, 200), abs=0.01) and pdf.read_bytes().startswith(b"%PDF")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pdf", "a.png"]  # no temporary left


def test_colour_scale_known_answers():
    cmap, lo, hi = figures.colour_scale("eps_v", [np.array([-0.1, 0.3]), np.array([0.05])])
    assert (cmap, lo, hi) == (figures.DIVERGING, -0.3, 0.3)
    assert figures.colour_scale("phi", [np.array([0.2, 0.9])]) == ("cividis", 0.2, 0.9)
    assert figures.colour_scale("d", [np.array([0.2])], fixed=(0.0, 1.0)) == ("magma", 0.0, 1.0)


def test_reference_fields_volumetric_strain_is_white_at_zero(tmp_path, monkeypatch):
    """The reference report on a short real run: the diverging maps have limits symmetric about zero."""
    import sweep.studies.reference as ref
    from solver import Parameters, RunOptions, simulate

    run = tmp_path / "run"
    res = simulate(Parameters(), RunOptions(h=4.0, t_end=0.02, snapshot_times=(0.0, 0.02)), out_dir=run)
    assert res.status == "ok"
    figs = {}
    monkeypatch.setattr(ref, "save_figure", lambda fig, path: figs.setdefault(Path(path).stem, fig))
    ref.reference_report(run, tmp_path / "out")
    axes = {ax.get_title(): ax for f in figs.values() for ax in f.axes}
    for title in ("volumetric strain ε_v (-)", "hoop stress σ'θθ (kPa)"):
        lo, hi = axes[title].collections[0].get_clim()
        assert lo == -hi and hi > 0


def _label_runner(params, options, run_dir):
    """Fracturing iff eta_o > 0.5; the run at C = 2, eta_o = 1 finishes but its classifier fails (no label)."""
    if params["cement"] == 2.0 and params["eta_o"] == 1.0:
        return {"status": "ok", "metrics": {"classify_error": "ValueError: no snapshot"}}
    frac = params["eta_o"] > 0.5
    return {"status": "ok", "classification": {"regime": "invasive_fracturing" if frac else "viscous_fingering",
                                               "fracturing": frac}}


def test_phase_diagram_names_the_finished_runs_it_leaves_out(tmp_path, capsys):
    # 4 finished runs, one without a fracturing label: the Ca*-C diagram draws 3 and says which run it left out
    spec = spec_from_dict({"name": "lab", "axes": {"cement": [1.0, 2.0], "eta_o": [0.25, 1.0]},
                           "diagrams": [{"kind": "ca_star_vs_cement", "fit": False}]})
    run_campaign(spec, tmp_path, runner=_label_runner, jobs=1, code_hash=VERSION, progress=None)
    from sweep.campaign.table import build_table

    t = build_table(spec, tmp_path, code_hash=VERSION)
    (key,) = t.loc[t["fracturing"].isna(), "key"]
    capsys.readouterr()
    paths = plot_campaign(spec, tmp_path, code_hash=VERSION)
    assert [p.name for p in paths] == ["ca_star_vs_cement.png", "ca_star_vs_cement.pdf"]
    err = capsys.readouterr().err
    assert f"ca_star_vs_cement.png leaves out 1 run(s)" in err and key in err

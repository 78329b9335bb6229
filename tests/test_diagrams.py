"""Phase diagrams: exponential separatrix fit, regime map, plots written."""
import math

import numpy as np
import pandas as pd
import pytest

from sweep.regimes.classify import REGIMES
from sweep.regimes.diagrams import REGIME_STYLE, plot_ca_star_vs_cement, plot_nf_vs_nb, regime_map
from sweep.regimes.separatrix import fit_exponential_separatrix

A_TRUE, B_TRUE = 1e7, 1.5  # Ca*_c = A exp(B C), C in %


def draw(seed, n=400, steep=2.0):
    """Labels from a logistic boundary in ln Ca*: P = 1/(1 + exp(-steep (ln Ca* - ln Ca*_c(C))))."""
    rng = np.random.default_rng(seed)
    C = rng.uniform(0.0, 3.0, n)
    L = rng.uniform(math.log(1e6), math.log(1e10), n)
    y = rng.random(n) < 1 / (1 + np.exp(-steep * (L - math.log(A_TRUE) - B_TRUE * C)))
    return C, np.exp(L), y


def test_separatrix_recovers_A_B_within_its_uncertainty():
    # one draw: within 2 sigma of its own (delta-method) uncertainty, and sigma is small
    C, cs, y = draw(0)
    f = fit_exponential_separatrix(C, cs, y)
    s_lnA = math.sqrt(f.cov_lnA_B[0, 0])
    assert abs(math.log(f.A / A_TRUE)) <= 2 * s_lnA
    assert abs(f.B - B_TRUE) <= 2 * f.sigma_B
    assert f.sigma_B < 0.15 * B_TRUE and s_lnA < 0.4
    assert f.sigma_A == pytest.approx(f.A * s_lnA, rel=1e-9)
    assert f(1.0) == pytest.approx(f.A * math.exp(f.B), rel=1e-12)
    # the uncertainty is calibrated: over 20 draws, 2-sigma coverage ~95 %
    # (P[coverage < 30/40] < 1e-4 for a true 95 % rate)
    hits = 0
    for seed in range(1, 21):
        f = fit_exponential_separatrix(*draw(seed))
        hits += int(abs(math.log(f.A / A_TRUE)) <= 2 * math.sqrt(f.cov_lnA_B[0, 0]))
        hits += int(abs(f.B - B_TRUE) <= 2 * f.sigma_B)
    assert hits >= 30


def test_separatrix_sharp_labels():
    """Deterministic labels on a grid (spacing 0.125 in C, 0.38 in ln Ca*): the fitted
    boundary lies within one grid cell of the true one."""
    C, L = np.meshgrid(np.linspace(0, 3, 25), np.linspace(math.log(1e6), math.log(1e10), 25))
    C, L = C.ravel(), L.ravel()
    f = fit_exponential_separatrix(C, np.exp(L), L > math.log(A_TRUE) + B_TRUE * C)
    dL = (math.log(1e10) - math.log(1e6)) / 24
    assert abs(math.log(f.A / A_TRUE)) <= dL
    assert abs(f.B - B_TRUE) <= 2 * dL / 3.0  # end-to-end over C in [0, 3]


def test_separatrix_bad_input():
    with pytest.raises(ValueError, match="ca_star"):
        fit_exponential_separatrix([0, 1, 2], [1.0, -1.0, 2.0], [0, 1, 1])
    with pytest.raises(ValueError, match="lengths"):
        fit_exponential_separatrix([0, 1, 2], [1.0, 2.0], [0, 1, 1])
    with pytest.raises(ValueError, match="does not increase"):
        C, cs, y = draw(0)
        fit_exponential_separatrix(C, cs, ~y)


def test_regime_map_quadrants():
    x = np.array([-1.0, 1.0, -1.0, 1.0, 1.2])
    y = np.array([-1.0, -1.0, 1.0, 1.0, 1.2])
    lab = ["uniform_invasion", "viscous_fingering", "invasive_fracturing",
           "non_invasive_fracturing", "non_invasive_fracturing"]
    gx = np.array([-0.9, 0.9, -0.9, 0.9, 0.1])
    gy = np.array([-0.8, -0.8, 0.8, 0.8, 0.05])
    got = regime_map(x, y, lab, gx, gy)
    assert list(got[:4]) == lab[:4]
    # k = 3 vote: near (1, 1) the two non-invasive runs outvote the third neighbour
    got3 = regime_map(x, y, lab, np.array([0.6]), np.array([0.6]), k=3)
    assert got3[0] == "non_invasive_fracturing"
    with pytest.raises(ValueError, match="k="):
        regime_map(x, y, lab, gx, gy, k=0)


def _png_pixels(path):
    from matplotlib.image import imread

    return imread(path)


def test_plot_ca_star(tmp_path):
    C, cs, y = draw(0, n=120)
    df = pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": y,
                       "source": np.where(np.arange(120) % 4 == 0, "experiment", "simulation")})
    df.loc[0, "Ca_star"] = np.nan  # dropped, reported
    out = plot_ca_star_vs_cement(df, tmp_path / "ca_star.png")
    paths = out["paths"]
    assert [p.suffix for p in paths] == [".png", ".svg"]
    assert all(p.stat().st_size > 10_000 for p in paths)
    assert paths[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<svg" in paths[1].read_text()[:2000]
    assert out["n_dropped"] == 1
    ref = fit_exponential_separatrix(C[1:], cs[1:], y[1:])
    assert out["fit"].A == pytest.approx(ref.A) and out["fit"].B == pytest.approx(ref.B)
    assert out["no_fit_reason"] is None
    # the separatrix's simultaneous 95 % band (profile likelihood, each run one Bernoulli draw) is drawn with it:
    # significant, around the drawn line at every C, and (one draw, 119 runs) holding the true boundary
    band = out["band"]
    assert band.significant and band.covers(np.log(ref(band.C))) and band.covers(np.log(A_TRUE) + B_TRUE * band.C)
    assert np.all(band.half_width_decades > 0)
    # fracturing that decreases with Ca*: no separatrix, and the figure says why instead of omitting it
    inv = plot_ca_star_vs_cement(df.assign(fracturing=~df["fracturing"].astype(bool)), tmp_path / "inv.png")
    assert inv["fit"] is None and "does not increase with Ca*" in inv["no_fit_reason"]
    with pytest.raises(ValueError, match="cement"):
        plot_ca_star_vs_cement(df.drop(columns="cement"), tmp_path / "x")


def test_plot_ca_star_does_not_draw_a_separatrix_outside_the_sampled_range(tmp_path):
    """Labels fracturing at both ends of Ca* and porous in between (the mixed grid of
    results/ca_star_vs_cement_h2_wall): the fit increases with Ca* overall but its line lies decades below every
    run; it is not drawn, and the figure says why."""
    rows = {0.5: "FFFFp", 1.0: "F-FFF", 1.5: "FFFFF", 2.0: "FpFFF", 2.5: "FpFFF", 3.0: "FpFFF"}  # Ca* up
    ca = [5.2e6, 1.65e7, 5.2e7, 1.65e8, 5.2e8]
    pts = [(c, ca[i], ch == "F") for c, lab in rows.items() for i, ch in enumerate(lab) if ch != "-"]
    C, cs, fr = (np.array(v) for v in zip(*pts))
    df = pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": fr})
    out = plot_ca_star_vs_cement(df, tmp_path / "mixed.png")
    assert out["fit"] is None and "outside the sampled Ca* range" in out["no_fit_reason"]
    assert out["band"] is None                               # no line, no band
    # a separatrix through the sampled range is still drawn (the first test's fit)
    C2, cs2, y2 = draw(0, n=120)
    assert plot_ca_star_vs_cement(pd.DataFrame({"cement": C2, "Ca_star": cs2, "fracturing": y2}),
                                  tmp_path / "ok.png")["fit"] is not None


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from scipy.spatial import Delaunay

    d = tmp_path_factory.mktemp("thumb")
    (d / "snapshots").mkdir()
    th = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    pts = np.vstack([np.c_[r * np.cos(th + r), r * np.sin(th + r)] for r in np.linspace(5, 53, 13)])
    tri = Delaunay(pts).simplices
    c = pts[tri].mean(axis=1)
    tri = tri[np.hypot(*c.T) > 5]
    np.savez(d / "snapshots" / "mesh.npz", points=pts, triangles=tri)
    S = (np.hypot(*pts.T) < 25).astype(float)
    phi = np.random.default_rng(0).uniform(0.2, 0.6, len(tri))
    np.savez(d / "snapshots" / "snap_00000.npz", t=1.0, S=S, phi=phi)
    return d


def test_plot_nf_nb(tmp_path, run_dir):
    rng = np.random.default_rng(1)
    rows = []
    for _ in range(40):
        nb, nf = 10 ** rng.uniform(-2, 3), 10 ** rng.uniform(-1.5, 1.5)
        if nf < 1:
            r = "uniform_invasion" if nb < 1 else "viscous_fingering"
        else:
            r = "invasive_fracturing" if nb < 1 else ("non_invasive_fracturing" if nf > 5 else "fracturing_fingering")
        rows.append({"N_b": nb, "N_f": nf, "regime": r, "run_dir": str(run_dir)})
    rows.append({"N_b": 1.0, "N_f": 1.0, "regime": "bogus", "run_dir": ""})
    df = pd.DataFrame(rows)
    out = plot_nf_vs_nb(df, tmp_path / "nfnb", experimental_range=(0.01, 0.1, 1.0, 10.0),
                        thumbnails=[{"row": 0, "pos": (0.15, 0.85)},
                                    {"run_dir": run_dir, "xy": (10.0, 10.0), "pos": (0.85, 0.2)}],
                        dp_cri=1.2e5, formats=("svg", "pdf"))
    assert [p.suffix for p in out["paths"]] == [".png", ".svg", ".pdf"]
    assert all(p.stat().st_size > 10_000 for p in out["paths"])
    assert out["n_dropped"] == 1
    expect = df["regime"].value_counts()
    assert out["counts"] == {r: int(expect.get(r, 0)) for r in REGIMES}
    # the red rectangle of the experimental range is drawn (pure red pixels), and only then
    img = _png_pixels(out["paths"][0])
    red = (img[..., 0] > 0.9) & (img[..., 1] < 0.1) & (img[..., 2] < 0.1)
    assert red.sum() > 100
    out2 = plot_nf_vs_nb(df, tmp_path / "nfnb2", shade=False, formats=())
    img2 = _png_pixels(out2["paths"][0])
    red2 = (img2[..., 0] > 0.9) & (img2[..., 1] < 0.1) & (img2[..., 2] < 0.1)
    assert red2.sum() == 0
    with pytest.raises(ValueError, match="experimental_range"):
        plot_nf_vs_nb(df, tmp_path / "x", experimental_range=(1.0, 0.1, 1.0, 10.0))
    with pytest.raises(ValueError, match="N_f"):
        plot_nf_vs_nb(df.drop(columns="N_f"), tmp_path / "x")


def test_paper_symbols():
    assert {r: (REGIME_STYLE[r]["marker"], REGIME_STYLE[r]["color"]) for r in REGIMES} == {
        "uniform_invasion": ("o", "#1f77b4"),
        "viscous_fingering": ("*", "#1f77b4"),
        "invasive_fracturing": ("^", "#ff7f0e"),
        "non_invasive_fracturing": ("s", "#ff7f0e"),
        "fracturing_fingering": ("x", "#ff7f0e"),
    }


def test_plot_ca_star_does_not_draw_a_separatrix_no_better_than_the_base_rate(tmp_path):
    """The mixed grid with the porosity floor (results/ca_star_vs_cement_h2_wall_floor, L_min = 2 mm): the fitted
    line crosses the sampled range at the largest C but every porous run lies above it and one fracturing run below,
    4 runs on the wrong side against 3 porous runs: the line says nothing calling every run fracturing does not, so
    it is not drawn.  Moving the three porous runs to the lowest row makes the labels locate a line again."""
    rows = {0.5: "FFFFF", 1.0: "FFFFF", 1.5: "FFFFF", 2.0: "FpFFF", 2.5: "FpFFF", 3.0: "FpFFF"}  # Ca* up
    ca = [5.2e6, 1.65e7, 5.2e7, 1.65e8, 5.2e8]
    pts = [(c, ca[i], ch == "F") for c, lab in rows.items() for i, ch in enumerate(lab)]
    C, cs, fr = (np.array(v) for v in zip(*pts))
    out = plot_ca_star_vs_cement(pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": fr}), tmp_path / "m.png")
    assert out["fit"] is None and "on the wrong side" in out["no_fit_reason"]
    moved = fr | (cs == ca[1])
    moved[(C >= 2.0) & (cs == ca[0])] = False            # porous invasion at the lowest Ca*, high C
    located = plot_ca_star_vs_cement(pd.DataFrame({"cement": C, "Ca_star": cs, "fracturing": moved}),
                                     tmp_path / "ok.png")
    assert located["fit"] is not None and located["no_fit_reason"] is None


def test_one_placement_rule_for_every_diagram(tmp_path):
    """The one-run and the replicate diagrams place the same rows (``placed_rows``) and name the rest by index."""
    from sweep.regimes.diagrams import placed_rows
    from sweep.regimes.probability import plot_nf_vs_nb_probabilities, plot_probability_diagram

    ca = pd.DataFrame({"cement": [1.0, 2.0, np.nan, 1.5, 2.5, 1.0, 2.0, 3.0],
                       "Ca_star": [1e6, 1e7, 1e6, 0.0, 1e6, -1.0, 1e5, 1e8],
                       "fracturing": [True, False, True, True, None, True, False, True]},
                      index=[10, 11, 12, 13, 14, 15, 16, 17])
    expect = [12, 13, 14, 15]                 # C missing, Ca* = 0, no label, Ca* < 0
    assert list(ca.index[~placed_rows(ca, "cement", "Ca_star", "fracturing")]) == expect
    one = plot_ca_star_vs_cement(ca, tmp_path / "one", formats=())
    rep = plot_probability_diagram(ca, tmp_path / "rep", formats=())
    assert one["dropped"] == rep["dropped"] == expect and one["n_dropped"] == rep["n_dropped"] == 4
    nf = pd.DataFrame({"N_b": [0.1, 10.0, 0.0, 5.0, 1.0, np.inf],
                       "N_f": [2.0, 0.5, 1.0, -1.0, 1.0, 1.0],
                       "regime": ["invasive_fracturing", "uniform_invasion", "uniform_invasion",
                                  "uniform_invasion", "bogus", "uniform_invasion"]})
    one = plot_nf_vs_nb(nf, tmp_path / "nf1", formats=())
    rep = plot_nf_vs_nb_probabilities(nf, tmp_path / "nf2", formats=())
    assert one["dropped"] == rep["dropped"] == [2, 3, 4, 5]   # N_b = 0, N_f < 0, unknown regime, N_b infinite

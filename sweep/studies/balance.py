"""Volume balance by phase of a run: where the injected water and the displaced oil go (issue #47, item 5).

From a run's ``timeseries.csv`` (units mm² per unit cell height, i.e. mm³ per mm of cell height; time s):

* water: in through r_i (``water_inflow_volume``), out through r_o (``water_outflow_volume``), stored in the
  pores and gap (change of ``water_stored_volume`` since t = 0) and the second-order source
  (``water_source_volume``);
* oil: in through r_i (what enters there besides water: injected − line storage − water in), out through r_o
  (``outflow_volume`` − water out), stored (change of ``stored_volume`` − ``water_stored_volume``), source
  (``source_volume`` − ``water_source_volume``);
* the injection line's storage (``line_stored_volume``).

The stored volumes at t = 0 are not rows of the time series: they follow from the first step's balance, whose
error is that row's ``mass_error`` / ``water_mass_error`` (≤ 1e-9 of the injected volume).  Each phase's closure
(in − out − stored change − source) is returned with the balance so that a reader sees it is zero.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

NEEDED = ("t", "injected_volume", "water_inflow_volume", "water_outflow_volume", "outflow_volume",
          "water_stored_volume", "water_source_volume", "stored_volume", "source_volume", "line_stored_volume")


def phase_balance(ts: pd.DataFrame) -> pd.DataFrame:
    """The cumulative volumes by phase (mm²) at each time of the time series ``ts``: columns t, water_in,
    water_out, water_stored, water_source, oil_in, oil_out, oil_stored, oil_source, line, water_closure,
    oil_closure.  ValueError naming the missing columns for a run made before they existed."""
    missing = [c for c in NEEDED if c not in ts.columns]
    if missing:
        raise ValueError(f"timeseries lacks the column(s) {missing}: allowed runs made by a solver that writes "
                         f"{list(NEEDED)} (rerun it)")
    first = ts.iloc[0]
    total_in = ts["injected_volume"] - ts["line_stored_volume"]
    w0 = first["water_stored_volume"] - (first["water_inflow_volume"] - first["water_outflow_volume"]
                                         - first["water_source_volume"])
    v0 = first["stored_volume"] - (first["injected_volume"] - first["line_stored_volume"] - first["outflow_volume"]
                                   - first["source_volume"])
    b = pd.DataFrame({"t": ts["t"]})
    b["water_in"] = ts["water_inflow_volume"]
    b["water_out"] = ts["water_outflow_volume"]
    b["water_stored"] = ts["water_stored_volume"] - w0
    b["water_source"] = ts["water_source_volume"]
    b["oil_in"] = total_in - ts["water_inflow_volume"]
    b["oil_out"] = ts["outflow_volume"] - ts["water_outflow_volume"]
    b["oil_stored"] = (ts["stored_volume"] - v0) - b["water_stored"]
    b["oil_source"] = ts["source_volume"] - ts["water_source_volume"]
    b["line"] = ts["line_stored_volume"]
    for ph in ("water", "oil"):
        b[f"{ph}_closure"] = b[f"{ph}_in"] - b[f"{ph}_out"] - b[f"{ph}_stored"] - b[f"{ph}_source"]
    return b


def plot_phase_balance(runs: dict, out) -> Path:
    """One panel per run (``runs``: label -> run folder or time series): water and oil in, stored and out
    (cumulative, mm² per unit cell height) against t (s), and the line's storage; written to ``out``
    (its suffix sets the format) atomically.  Returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sweep.campaign.figures import save_figure

    if not runs:
        raise ValueError("runs: allowed one or more label -> run folder entries, got none")
    series = {k: (v if isinstance(v, pd.DataFrame) else _read_run(v)) for k, v in runs.items()}
    fig, axes = plt.subplots(1, len(series), figsize=(5.2 * len(series), 4.0), squeeze=False, sharey=True)
    styles = {"water_in": ("tab:blue", "-"), "water_stored": ("tab:blue", "--"), "water_out": ("tab:blue", ":"),
              "oil_in": ("tab:brown", "-"), "oil_out": ("tab:brown", ":"), "oil_stored": ("tab:brown", "--"), "line": ("grey", "-.")}
    for ax, (label, ts) in zip(axes[0], series.items()):
        b = phase_balance(ts)
        for col, (colour, ls) in styles.items():
            ax.plot(b["t"], b[col], color=colour, ls=ls, label=col.replace("_", " "))
        ax.plot(ts["t"], ts["injected_volume"], color="k", lw=0.8, label="pumped")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_title(label)
        ax.set_xlabel("t (s)")
    axes[0][0].set_ylabel("cumulative volume (mm² per unit cell height)")
    axes[0][-1].legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out = Path(out)
    paths = save_figure(fig, out, formats=(out.suffix.lstrip(".") or "png",))
    plt.close(fig)
    return paths[0]


def _read_run(folder) -> pd.DataFrame:
    path = Path(folder) / "timeseries.csv"
    if not path.is_file():
        raise ValueError(f"run {str(folder)!r}: not a run folder (no timeseries.csv)")
    return pd.read_csv(path)

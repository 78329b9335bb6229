"""A campaign report as one self-contained HTML file (``<root>/<name>/report.html``).

    dchfrac campaign report SPEC --html

It holds the counts and regimes, the failures, every diagram, what the paper reports for the
campaign's section (``paper_reported.toml``, matched on the spec's ``paper`` string), and the run
table with units in its header and a thumbnail per run (porosity with the S = 0.5 front). Every
image is embedded as a data URI, so the file can be sent on its own.
"""
from __future__ import annotations

import base64
import html
import io
import re
from pathlib import Path

__all__ = ["write_html_report", "paper_sections"]

_CSS = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; }
th { background: #f3f3f3; }
td.l, th.l { text-align: left; }
img.fig { max-width: min(100%, 820px); margin: 0.5em 0; }
img.thumb { width: 110px; height: 110px; }
.failed { background: #fde8e8; }
dt { font-weight: bold; } dd { margin: 0 0 0.6em 1.5em; }
"""


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode()


def paper_sections(paper: str) -> dict[str, dict]:
    """The sections of the paper's reported figures that a spec's ``paper`` string cites: those whose
    header comment names a "Sec. N.N" or "Fig. name" that ``paper`` contains."""
    from sweep.paper import paper_reported

    if not paper:
        return {}
    try:
        data = paper_reported()
    except FileNotFoundError:
        return {}
    from sweep.paper import PACKAGED_PAPER_TOML

    out = {}
    for m in re.finditer(r"^\[(\w+)\]\s*#\s*(.*)$", PACKAGED_PAPER_TOML.read_text(), re.M):
        name, comment = m.group(1), m.group(2)
        cites = re.findall(r"(Sec\. [\d.]*\d|Fig\. \w+)", comment)
        if name in data and any(c in paper for c in cites):
            out[name] = data[name]
    return out


def _thumbnail(run_dir: Path) -> str | None:
    """Porosity (0..1) of the last snapshot with the S = 0.5 front, as a small PNG data URI."""
    from matplotlib.figure import Figure

    from sweep.campaign.plot import _snapshot

    snap = _snapshot(run_dir)
    if snap is None or "phi" not in snap[2]:
        return None
    pts, tri, s = snap
    fig = Figure(figsize=(1.6, 1.6))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.tripcolor(pts[:, 0], pts[:, 1], tri, s["phi"], cmap="cividis", vmin=0.0, vmax=1.0, shading="flat")
    if "S" in s and len(s["S"]) == len(pts) and s["S"].min() < 0.5 < s["S"].max():
        ax.tricontour(pts[:, 0], pts[:, 1], tri, s["S"], levels=[0.5], colors="w", linewidths=0.6)
    ax.set_aspect("equal")
    ax.set_axis_off()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    return _data_uri(buf.getvalue())


def _cell(v) -> str:
    import pandas as pd

    if isinstance(v, float):
        return "" if pd.isna(v) else f"{v:.4g}"
    return "" if v is None or v is pd.NA else html.escape(str(v))


def _runs_table(spec, store, table) -> list[str]:
    from sweep.campaign.figures import axis_label

    cols = [c for c in ["key", "status", "regime", *spec.axis_names, "Ca_star", "N_b", "N_f", "crack_length",
                        "n_fingers", "wall_time_s"] if c in table.columns]
    cols = list(dict.fromkeys(cols))
    head = "".join(f'<th class="l">{html.escape(axis_label(c) if c not in ("key", "status", "regime") else c)}</th>'
                   for c in cols)
    out = ["<table>", f"<tr><th>run</th>{head}</tr>"]
    for _, row in table.iterrows():
        uri = _thumbnail(store.run_dir(row["key"]))
        img = f'<img class="thumb" alt="porosity of run {row["key"]}" src="{uri}">' if uri else ""
        cls = ' class="failed"' if row.get("status") != "ok" else ""
        tds = "".join(f'<td class="l">{_cell(row[c])}</td>' if c in ("key", "status", "regime")
                      else f"<td>{_cell(row[c])}</td>" for c in cols)
        out.append(f"<tr{cls}><td>{img}</td>{tds}</tr>")
    out.append("</table>")
    return out


def _paper_block(spec) -> list[str]:
    secs = paper_sections(spec.paper)
    if not secs:
        return []
    out = ["<h2>What the paper reports</h2>",
           f"<p>From <code>paper_reported.toml</code> (the sections that <i>{html.escape(spec.paper)}</i> cites); "
           "compare with the diagrams above.</p>"]
    for name, d in secs.items():
        out.append(f"<h3>{html.escape(name)}</h3><dl>")
        out += [f"<dt>{html.escape(str(k))}</dt><dd>{html.escape(str(v))}</dd>" for k, v in d.items()]
        out.append("</dl>")
    return out


def write_html_report(spec, root="results", *, code_hash: str | None = None, plot: bool = True) -> Path:
    """Write ``<root>/<name>/report.html`` (self-contained: every image a data URI); returns its path.
    ``plot``: draw the figures first (else the ones in ``figures/`` are shown)."""
    from sweep.campaign.plan import _archived_text, as_spec, check_not_emptier, plan_campaign
    from sweep.campaign.table import build_table
    from sweep.campaign.plot import plot_campaign
    from sweep.campaign.paths import results_root
    from sweep.campaign.store import ResultsStore, write_text_atomic

    spec = as_spec(spec)
    root = results_root(spec, root)
    store = ResultsStore(root, spec.name)
    plan = plan_campaign(spec, root, code_hash=code_hash)
    table = build_table(spec, root, plan=plan)
    check_not_emptier(store, table)
    figs = plot_campaign(spec, root, code_hash=code_hash, table=table) if plot else sorted(store.figures_dir.glob("*"))
    figs = [Path(f) for f in figs if Path(f).suffix == ".png"]
    if not table.empty:   # the table and, with [replicates], its points from the same rows
        from sweep.campaign.replicates import write_points

        store.write_table(table, swept=spec.axis_names)
        write_points(spec, table, store)
    e = html.escape
    L = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
         f"<title>Campaign {e(spec.name)}</title><style>{_CSS}</style></head><body>",
         f"<h1>Campaign <code>{e(spec.name)}</code></h1>"]
    if spec.description:
        L.append(f"<p>{e(spec.description.strip())}</p>")
    if spec.paper:
        L.append(f"<p>Paper: {e(spec.paper)}</p>")
    L.append(f"<p>Runs in the grid: {len(plan.points)}; done {len(plan.done)}, failed {len(plan.failed)}, "
             f"pending {len(plan.pending)}"
             + (f", archived {e(_archived_text(plan))} (rows of the committed table, run folders not here)"
                if plan.archived or plan.unmatched_rows else "") + f". Solver code hash <code>{e(plan.code_hash)}</code>. Units mm, s, kPa.</p>")
    if not table.empty and table["regime"].notna().any():
        L.append("<h2>Regimes</h2><table><tr><th class='l'>regime</th><th>runs</th></tr>")
        L += [f"<tr><td class='l'>{e(str(r))}</td><td>{n}</td></tr>"
              for r, n in table["regime"].fillna("(none)").value_counts().items()]
        L.append("</table>")
    if plan.failed:
        L.append("<h2>Failures</h2><table><tr><th class='l'>key</th><th class='l'>reason</th></tr>")
        L += [f"<tr><td class='l'><code>{k}</code></td><td class='l'>{e(str(plan.records[k].get('reason')))}</td></tr>"
              for _, k in plan.failed]
        L.append("</table>")
    if figs:
        L.append("<h2>Figures</h2>")
        for f in figs:
            vec = [v.name for v in (f.with_suffix(".pdf"), f.with_suffix(".svg")) if v.is_file()]
            also = f" (also {', '.join(vec)} in figures/)" if vec else ""
            L.append(f'<figure><img class="fig" alt="{e(f.stem)}" src="{_data_uri(f.read_bytes())}">'
                     f"<figcaption>{e(f.name)}{e(also)}</figcaption></figure>")
    L += _paper_block(spec)
    if not table.empty:
        L.append("<h2>Runs</h2><p>The full table: <code>table.csv</code> / <code>table.parquet</code>, column "
                 "units and meanings in <code>columns.csv</code> (<code>dchfrac campaign columns SPEC</code>).</p>")
        L += _runs_table(spec, store, table)
    L.append("</body></html>")
    path = store.dir / "report.html"
    store.dir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, "\n".join(L) + "\n")
    return path

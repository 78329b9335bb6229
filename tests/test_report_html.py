"""`dchfrac campaign report SPEC --html`: one self-contained file (every image a data URI that decodes to
a PNG: the diagrams and one thumbnail per run), the paper's reported claims of the cited section, and
a real headless browser (Chromium, when installed) that renders it with every image loaded."""
from __future__ import annotations

import base64
import io
import re
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import pytest
from fake_runs import field_runner

from sweep.campaign.run import run_campaign
from sweep.campaign.report_html import paper_sections, write_html_report
from sweep.campaign.spec import spec_from_dict

VERSION = "test-html"
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("html")
    spec = spec_from_dict({"name": "fig", "paper": "Sec. 3.6 (coarse)", "axes": {"cement": [1.0, 2.0], "eta_o": [0.25, 1.0]},
                           "diagrams": [{"kind": "timeseries", "x": "t", "y": "p_inj"},
                                        {"kind": "fields", "field": "eps_v", "rows": "cement", "cols": "eta_o"}]})
    run_campaign(spec, root, runner=field_runner, jobs=1, code_hash=VERSION, progress=None)
    return write_html_report(spec, root, code_hash=VERSION)


def test_every_image_is_embedded_and_decodes(report):
    from PIL import Image

    text = report.read_text()
    srcs = re.findall(r'<img[^>]* src="([^"]*)"', text)
    assert len(srcs) == 2 + 4  # two diagrams, a thumbnail per run
    for s in srcs:
        assert s.startswith("data:image/png;base64,")
        Image.open(io.BytesIO(base64.b64decode(s.split(",", 1)[1]))).verify()
    assert not re.search(r'(src|href)="(?!data:)', text)  # nothing to fetch: the file stands alone


def test_paper_claims_of_the_cited_section(report):
    text = report.read_text()
    assert "ca_star_vs_cement" in text and "separatrix" in text
    assert list(paper_sections("Sec. 3.8, Fig. branching_number")) == ["nf_vs_nb", "branching_number_sensitivity"]
    assert paper_sections("") == {}


def test_runs_table_has_units_in_its_header(report):
    text = report.read_text()
    assert "cement (%)" in text and "eta_o (kPa·s)" in text


def test_chromium_renders_it_with_every_image_loaded(report, tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    from check_report_browser import find_browser

    if find_browser() is None:
        pytest.skip("no Chromium on PATH (system package 'chromium')")
    shot = tmp_path / "shot.png"
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_report_browser.py"), str(report),
                        "--screenshot", str(shot)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    images, tables = r.stdout.strip().split(" tables=")
    assert images == "images=6 broken=0" and tables.endswith(" empty=0") and int(tables.split()[0]) >= 2
    assert shot.stat().st_size > 10_000


def test_the_browser_check_sees_a_broken_image(report, tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    from check_report_browser import find_browser

    if find_browser() is None:
        pytest.skip("no Chromium on PATH (system package 'chromium')")
    bad = tmp_path / "bad.html"
    bad.write_text(report.read_text().replace("data:image/png;base64,", "data:image/png;base64,AAAA", 1))
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_report_browser.py"), str(bad)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 1 and r.stdout.strip().startswith("images=6 broken=1 ")


def test_cli_report_html(tmp_path, capsys):
    from sweep.campaign.cli import main

    spec = tmp_path / "figcli.toml"
    spec.write_text('name = "figcli"\n[axes]\ncement = [1.0, 2.0]\neta_o = [0.5]\n'
                    '[[diagrams]]\nkind = "timeseries"\nx = "t"\ny = "p_inj"\n[run]\nrunner = "fake_runs:field_runner"\n')
    root = tmp_path / "res"
    assert main(["run", str(spec), "--results", str(root)]) == 0
    capsys.readouterr()
    assert main(["report", str(spec), "--results", str(root), "--html"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [f"report: {root / 'figcli' / 'report.md'}", f"report: {root / 'figcli' / 'report.html'}"]
    assert len(re.findall(r"<img ", (root / "figcli" / "report.html").read_text())) == 1 + 2

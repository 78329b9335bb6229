"""Open a campaign's report.html in headless Chromium: it renders, and every image loads.

    python scripts/check_report_browser.py results/demo/report.html [--screenshot shot.png]

Prints ``images=N broken=B tables=T empty=E`` and exits 0 when the page rendered with N >= 1 images, B = 0,
T >= 1 tables and E = 0, 1 when an image failed to load, a table was drawn without rows or with no height, or the
page did not render, 2 when no Chromium is found or the file is missing.  The check loads a copy of the report
with a script appended that counts, once the page has loaded, the images that are not complete or have no
natural width and the tables with no data row or no height (the report itself holds no script).
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

_PROBE = """<script>
window.addEventListener('load', () => {
  const imgs = Array.from(document.images);
  const broken = imgs.filter(i => !i.complete || i.naturalWidth === 0).length;
  const tables = Array.from(document.querySelectorAll('table'));
  const shown = tables.filter(t => t.rows.length > 1 && t.getBoundingClientRect().height > 0).length;
  const m = document.createElement('div');
  m.id = 'dchfrac-check';
  m.textContent = 'images=' + imgs.length + ' broken=' + broken + ' tables=' + tables.length + ' empty=' + (tables.length - shown);
  document.body.appendChild(m);
});
</script>"""
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_browser() -> str | None:
    """Path of a Chromium-family browser on PATH, or None."""
    return next((p for b in BROWSERS if (p := shutil.which(b))), None)


def _chromium(browser: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           "--virtual-time-budget=15000", *args], capture_output=True, text=True, timeout=180)


def check(report: Path, browser: str, screenshot: Path | None = None) -> tuple[int, int, int, int]:
    """(images, broken images, tables, empty tables) of ``report`` as Chromium renders it; raises RuntimeError
    if it did not render."""
    with tempfile.TemporaryDirectory() as d:
        probe = Path(d) / "report_probe.html"
        probe.write_text(report.read_text().replace("</body>", _PROBE + "</body>"))
        r = _chromium(browser, "--dump-dom", probe.as_uri())
        m = re.search(r'id="dchfrac-check">images=(\d+) broken=(\d+) tables=(\d+) empty=(\d+)<', r.stdout)
        if m is None:
            raise RuntimeError(f"the page did not render (chromium exit {r.returncode}): {r.stderr.strip()[-300:]}")
        if screenshot is not None:
            _chromium(browser, f"--screenshot={Path(screenshot).resolve()}", "--window-size=1280,2400", report.resolve().as_uri())
        return tuple(int(g) for g in m.groups())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report", type=Path)
    ap.add_argument("--screenshot", type=Path, default=None, help="also save a PNG of the rendered page")
    a = ap.parse_args(argv)
    browser = find_browser()
    if browser is None:
        print(f"no Chromium found (tried {', '.join(BROWSERS)}); install the system package 'chromium'", file=sys.stderr)
        return 2
    if not a.report.is_file():
        print(f"report {str(a.report)!r} not found", file=sys.stderr)
        return 2
    try:
        n, broken, tables, empty = check(a.report, browser, a.screenshot)
    except RuntimeError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    print(f"images={n} broken={broken} tables={tables} empty={empty}")
    return 0 if n >= 1 and broken == 0 and tables >= 1 and empty == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

"""The campaigns/ folders as the README describes them: every spec parses, every committed campaign result
(a results/<name>/ folder with a table) belongs to a spec of that name and loads as a campaign by itself."""
from __future__ import annotations

from pathlib import Path

import pytest

from sweep.campaign.spec import load_spec
from sweep.discrepancy.twins import load_twin_campaign

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGNS = ROOT / "campaigns"
FOLDERS = ("examples", "paper", "studies", "discrepancy")
SPECS = sorted(p.relative_to(CAMPAIGNS).as_posix() for p in CAMPAIGNS.rglob("*.toml"))


def test_every_spec_is_in_one_of_the_documented_folders():
    assert SPECS, "no campaign specs found"
    outside = [s for s in SPECS if s.split("/")[0] not in FOLDERS or s.count("/") != 1]
    assert not outside, f"campaign specs outside campaigns/{{{','.join(FOLDERS)}}}/: {outside}"


@pytest.mark.parametrize("rel", [s for s in SPECS if not s.startswith("discrepancy/")])
def test_every_campaign_spec_parses(rel):
    spec = load_spec(CAMPAIGNS / rel)
    assert spec.name


@pytest.mark.parametrize("rel", [s for s in SPECS if s.startswith("discrepancy/")])
def test_every_twin_campaign_parses(rel):
    camp = load_twin_campaign(CAMPAIGNS / rel)
    assert camp["twin"] and camp["conditions"]


def test_every_committed_campaign_table_has_its_spec():
    names = {load_spec(CAMPAIGNS / s).name for s in SPECS if not s.startswith("discrepancy/")}
    tables = sorted(d.name for d in (ROOT / "results").iterdir() if (d / "table.csv").is_file())
    assert tables, "no committed campaign tables under results/"
    orphans = [t for t in tables if t not in names]
    assert not orphans, f"results/<name>/table.csv without a campaign spec of that name: {orphans}"


def test_every_committed_campaign_folder_loads_as_it_is():
    """A committed results/<name>/ folder is itself a campaign (`dchfrac campaign compare` and `report` take the
    folder): its spec copy loads from a fresh clone, with the [base] model files it names (base_models/)."""
    copies = sorted((ROOT / "results").glob("*/spec.toml"))
    assert copies, "no committed campaign folders under results/"
    broken = []
    for p in copies:
        try:
            load_spec(p)
        except Exception as e:  # noqa: BLE001 - every failure is listed, whatever its kind
            broken.append(f"{p.parent.name}: {e}")
    assert not broken, "committed campaign folders whose spec copy does not load:\n" + "\n".join(broken)


def test_no_script_outside_the_archive():
    """A script a result depends on is package code (tested, a `dchfrac` subcommand) or sits in results/archive/."""
    scripts = sorted(str(f.relative_to(ROOT)) for ext in ("*.py", "*.sh") for f in (ROOT / "results").rglob(ext)
                     if "archive" not in f.relative_to(ROOT / "results").parts[:1])
    assert not scripts, f"untested scripts outside results/archive/: {scripts}"

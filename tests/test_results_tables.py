"""The Markdown tables of the committed results render whole (every row of a table has as many cells as its header), and
the folder index of results/README.md states each campaign's run count as its tables hold it.

A row with one cell too few drops a cell from the rendered table, and an unescaped "|" inside a cell (|w|, say) adds
one, so a number or a command silently moves to the wrong column.  The archive (one-off outputs kept as they were
made, ``results/archive/``) is not checked.  A "|" inside backticks or escaped as "\\|" is text, as in GitHub's
renderer.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results"
DOCS = sorted(p for p in RESULTS.rglob("*.md") if "archive" not in p.relative_to(RESULTS).parts)
RULE = re.compile(r"^\|\s*:?-{3,}")


def cell_count(line: str) -> int:
    """The cells of a table row: the "|" outside code spans and not escaped, less the two at its ends."""
    n, code, i = 0, False, 0
    while i < len(line):
        c = line[i]
        if c == "\\" and line[i + 1:i + 2] == "|":
            i += 2
            continue
        code ^= c == "`"
        n += c == "|" and not code
        i += 1
    return n - 1


def ragged_rows(text: str) -> list[tuple[int, int, int]]:
    """(line number, cells, header's cells) of every row whose cell count differs from its table's header."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        if lines[i].startswith("|") and i + 1 < len(lines) and RULE.match(lines[i + 1]):
            width, j = cell_count(lines[i]), i + 2
            while j < len(lines) and lines[j].startswith("|"):
                if cell_count(lines[j]) != width:
                    out.append((j + 1, cell_count(lines[j]), width))
                j += 1
            i = j
        else:
            i += 1
    return out


def test_cell_count_reads_code_spans_and_escapes_as_text():
    assert cell_count("| a | `x|y` | b \\| c |") == 3
    assert ragged_rows("| a | b |\n|---|---|\n| 1 | 2 |\n| 1 | |x| |\n") == [(4, 4, 2)]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.relative_to(RESULTS).as_posix())
def test_every_table_row_has_its_header_s_cells(doc):
    assert not ragged_rows(doc.read_text(encoding="utf-8")), doc


def index_rows() -> list[tuple[list[str], str]]:
    """The rows of results/README.md's folder index: the folders named in the first cell, and the last cell (runs,
    wall time)."""
    lines = (RESULTS / "README.md").read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("## Result folders"))
    rows = []
    for line in lines[start + 1:]:
        if line.startswith("## "):
            break
        if line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            rows.append((re.findall(r"`([^`]+/)`", cells[0]), cells[-1]))
    return rows


def _runs(table: Path) -> int:
    with open(table, newline="", encoding="utf-8") as f:
        return sum(1 for _ in csv.DictReader(f))


def test_the_index_states_each_campaign_s_run_count_as_its_tables_hold():
    """The index's "N runs" (or "N of M runs") is the number of rows of the tables of the folders its row names."""
    counted = 0
    for folders, last in index_rows():
        stated = re.match(r"(?:(\d+) of )?(\d[\d,]*) runs?\b", last)
        tables = [RESULTS / f / "table.csv" for f in folders if (RESULTS / f / "table.csv").is_file()]
        if not (stated and tables):
            continue
        rows = sum(_runs(t) for t in tables)
        done = int((stated.group(1) or stated.group(2)).replace(",", ""))
        assert done == rows, (folders, last[:60], rows)
        counted += 1
    assert counted > 30

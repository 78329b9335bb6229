"""Figures are written atomically and reproducibly (sweep.figio): the same figure drawn at two different dates is
the same file byte for byte, a failed write leaves the old file as it was, and a bad format is refused."""
from __future__ import annotations

import pytest

from sweep.figio import write_figure


def _figure():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot([0.0, 1.0, 2.0], [1.0, 3.0, 2.0], "o-", label="p_inj (kPa)")
    ax.legend()
    return fig


@pytest.mark.parametrize("fmt", ["png", "pdf", "svg"])
def test_a_figure_redrawn_at_another_date_is_the_same_file(tmp_path, monkeypatch, fmt):
    # matplotlib stamps PDF and SVG with SOURCE_DATE_EPOCH when set, else the clock: two dates, one file
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")
    a = write_figure(_figure(), tmp_path / f"a.{fmt}", dpi=50)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    b = write_figure(_figure(), tmp_path / f"b.{fmt}", dpi=50)
    assert a.read_bytes() == b.read_bytes()
    assert a.stat().st_size > 100


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    class Broken:
        def savefig(self, path, **kw):
            with open(path, "wb") as f:
                f.write(b"half a figure")
            raise RuntimeError("renderer failed")

    path = tmp_path / "fig.png"
    path.write_bytes(b"the old figure")
    with pytest.raises(RuntimeError, match="renderer failed"):
        write_figure(Broken(), path)
    assert path.read_bytes() == b"the old figure"
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]


def test_a_bad_format_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match=r"'jpg'.*png, pdf, svg"):
        write_figure(_figure(), tmp_path / "fig.jpg")
    assert not list(tmp_path.iterdir())

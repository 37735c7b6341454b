import base64

import pytest

from kinred.errors import InvalidInput
from kinred.report import Report, Table, figure_png, validate_report_html
from kinred.report._figures import pyplot


def _png():
    plt = pyplot()
    fig, ax = plt.subplots()
    ax.semilogy([0, 1, 2], [1, 1e-10, 1e-30])
    return figure_png(fig)


def test_report_embeds_figures_and_tables():
    r = Report("t", subtitle="s")
    sec = r.section("a", ["x < y & z"])
    sec.tables.append(Table(["k", "value"], [[1, 1e-30], [2, 0.5]]))
    sec.add_figure("gamma", _png())
    sec.add_figure("gamma 2", _png())
    text = r.to_html()
    assert validate_report_html(text) == 2
    assert "x &lt; y &amp; z" in text
    assert "1.000e-30" in text


def test_validator_rejects_broken_html_and_empty_images():
    with pytest.raises(InvalidInput, match="DOCTYPE"):
        validate_report_html("<html></html>")
    with pytest.raises(InvalidInput, match="unclosed"):
        validate_report_html("<!DOCTYPE html><html><body><p>")
    bad = base64.b64encode(b"\x89PNG\r\n\x1a\n").decode()
    with pytest.raises(InvalidInput, match="non-empty PNG"):
        validate_report_html(f'<!DOCTYPE html><html><body><img src="data:image/png;base64,{bad}"></body></html>')
    with pytest.raises(InvalidInput, match="non-embedded"):
        validate_report_html('<!DOCTYPE html><html><body><img src="fig.png"></body></html>')


def test_add_figure_requires_png():
    r = Report("t")
    with pytest.raises(InvalidInput, match="PNG"):
        r.section("a").add_figure("x", b"GIF89a")


def test_table_text_rendering():
    t = Table(["dim", "pos"], [[200, 1], [10, 14]])
    lines = t.to_text().splitlines()
    assert lines[0].split("|")[0].strip() == "dim"
    assert lines[3].split("|")[1].strip() == "14"

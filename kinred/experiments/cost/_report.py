"""The result folder of ``kinred cost``: JSON, one PNG per study, text tables, HTML report."""

from __future__ import annotations

from pathlib import Path

from ...errors import InvalidInput
from ._config import CostResult
from ._registry import REGISTRY


def _tidy(fig):
    """Decade labels only on the log axes of a study's figure (no crowded minor labels)."""
    from ...report import tidy_log_axes

    tidy_log_axes(*fig.axes)
    return fig


def write_outputs(result, out_dir) -> Path:
    """Write the result folder of ``result``.

    ``cost.json``, ``cost.txt`` and ``summary.json`` first (the numbers are on disk before any
    figure is drawn), then ``cost_<study>.png`` and ``report.html``; a figure that cannot be
    drawn becomes a note in the report.

    Parameters
    ----------
    result : CostResult
    out_dir : path
        The result folder (created if missing).

    Returns
    -------
    Path
        The path of ``summary.json``.
    """
    from ...io import ResultFolder
    from ...report import Report, draw_figure

    if not isinstance(result, CostResult):
        raise InvalidInput(f"result must be a CostResult, got {type(result).__name__}")
    folder = ResultFolder(out_dir)
    studies = [(name, study) for name, study in REGISTRY.items() if name in result.studies]
    tables = {name: study.table(result.studies[name]) for name, study in studies}
    text_lines = ["kinred cost -- headline", ""]
    text_lines += [f"- {h['text']}" for h in result.headline.values()]
    for name, study in studies:
        text_lines += ["", study.title, tables[name].to_text()]
    folder.write_json("cost.json", result.to_json())
    folder.write_text("cost.txt", "\n".join(text_lines) + "\n")
    summary = folder.mark_complete({"study": "cost", "wall_time_s": result.wall_time,
                                    "headline": {k: v["text"] for k, v in result.headline.items()},
                                    "machine": result.machine})
    m = result.machine
    rep = Report("kinred cost: what accuracy costs in time",
                 subtitle=f"{m['cpu']}, {m['cores']} logical cores, Python {m['python']}, "
                          f"NumPy {m['numpy']}; total wall time {result.wall_time:.1f} s. "
                          "Timings are wall-clock on this machine (noisy if it is shared).")
    rep.section("Headline", [h["text"] for h in result.headline.values()])
    for name, study in studies:
        st = result.studies[name]
        setting = ", ".join(f"{k}={v}" for k, v in st.get("setting", {}).items())
        loaded = " (loaded from the previous run)" if result.stages.get(name) == "loaded" else ""
        sec = rep.section(study.title, [setting, f"wall time of this study: "
                                                 f"{result.study_times.get(name, 0.0):.1f} s"
                                                 f"{loaded}"])
        sec.tables.append(tables[name])
        drawn = draw_figure(f"cost_{name}.png", study.title,
                            lambda plt, study=study, st=st: _tidy(study.figure(st, plt)))
        if drawn.png is not None:
            folder.write_bytes(drawn.name, drawn.png)
        sec.add_drawn(drawn)
    folder.write_text("report.html", rep.to_html())
    return summary

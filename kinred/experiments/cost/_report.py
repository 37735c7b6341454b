"""The result folder of ``kinred cost``: JSON, one PNG per study, text tables, HTML report."""

from __future__ import annotations

from pathlib import Path

from ...errors import InvalidInput
from ._registry import REGISTRY


def write_outputs(result, out_dir) -> Path:
    """Write the result folder of ``result``.

    ``cost.json``, ``cost_<study>.png``, ``cost.txt``, ``report.html``; ``summary.json`` last.

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
    from ...report import Report, figure_png
    from ...report._figures import pyplot
    from . import CostResult

    if not isinstance(result, CostResult):
        raise InvalidInput(f"result must be a CostResult, got {type(result).__name__}")
    plt = pyplot()
    folder = ResultFolder(out_dir)
    m = result.machine
    rep = Report("kinred cost: what accuracy costs in time",
                 subtitle=f"{m['cpu']}, {m['cores']} logical cores, Python {m['python']}, "
                          f"NumPy {m['numpy']}; total wall time {result.wall_time:.1f} s. "
                          "Timings are wall-clock on this machine (noisy if it is shared).")
    rep.section("Headline", [h["text"] for h in result.headline.values()])
    text_lines = ["kinred cost -- headline", ""]
    text_lines += [f"- {h['text']}" for h in result.headline.values()]
    for name, study in REGISTRY.items():
        if name not in result.studies:
            continue
        st = result.studies[name]
        table = study.table(st)
        setting = ", ".join(f"{k}={v}" for k, v in st.get("setting", {}).items())
        sec = rep.section(study.title, [setting, f"wall time of this study: "
                                                 f"{result.study_times.get(name, 0.0):.1f} s"])
        sec.tables.append(table)
        png = figure_png(study.figure(st, plt))
        folder.write_bytes(f"cost_{name}.png", png)
        sec.add_figure(study.title, png)
        text_lines += ["", study.title, table.to_text()]
    folder.write_text("cost.txt", "\n".join(text_lines) + "\n")
    folder.write_text("report.html", rep.to_html())
    folder.write_json("cost.json", result.to_json())
    return folder.mark_complete({"study": "cost", "wall_time_s": result.wall_time,
                                 "headline": {k: v["text"] for k, v in result.headline.items()},
                                 "machine": result.machine})

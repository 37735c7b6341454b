"""The output rule of the long commands (kinred.commands._output): default folders, rerun,
refusal of folders kinred did not write, resume."""

import io
import json

import pytest

from kinred.cli import build_parser
from kinred.commands import _output
from kinred.commands._output import LAYOUTS, MARKER, default_out, prepare, record
from kinred.errors import InvalidInput
from kinred._lock import LOCK_NAME as LOCK

LONG = {  # argv of every long command -> its default folder
    ("demo",): "results/demo",
    ("demo", "--smoke"): "results/demo-smoke",
    ("run", "examples/scenes/cucker-smale-200.toml"): "results/run-cucker-smale-200",
    ("run", "x/my-scene.toml", "--smoke"): "results/run-my-scene-smoke",
    ("paper", "table1"): "results/paper-table1",
    ("paper", "calibrate", "--quick"): "results/paper-calibrate-quick",
    ("paper", "fig4", "--quick"): "results/paper-fig4-quick",
    ("paper", "strategies"): "results/paper-strategies",
    ("cost",): "results/cost",
    ("cost", "--quick"): "results/cost-quick",
}


def _default(argv) -> str:
    """The default folder a command computes from its parsed arguments."""
    args = build_parser().parse_args(list(argv))
    size = ("smoke" if getattr(args, "smoke", False) else
            "quick" if getattr(args, "quick", False) else None)
    command = "paper " + args.study if args.command == "paper" else args.command
    scene = args.scene.rsplit("/", 1)[-1].removesuffix(".toml") if command == "run" else None
    return default_out(command, scene=scene, size=size).as_posix()


@pytest.mark.parametrize("argv", list(LONG), ids=lambda a: " ".join(a))
def test_one_default_folder_rule_and_options(argv):
    assert _default(argv) == LONG[argv]
    args = build_parser().parse_args(list(argv))
    assert args.out is None and args.resume is False          # every long command has both
    assert "kinred-results" not in build_parser().format_help()


def test_every_long_command_has_a_layout():
    assert set(LAYOUTS) == {"demo", "run", "certify", "paper table1", "paper calibrate", "paper fig4",
                            "paper strategies", "cost"}
    for argv in LONG:     # every long command can hide its progress bar
        assert build_parser().parse_args(list(argv)).no_progress is False


def _result(folder, layout="paper fig4", extra=()):
    """A folder as the command leaves it: marker, summary, a stage, a figure."""
    (folder / "stages").mkdir(parents=True)
    (folder / "stages" / "config.json").write_text("{}")
    (folder / "stages" / "left.npz").write_bytes(b"PK")
    (folder / "summary.json").write_text("{}")
    (folder / "fig4.png").write_bytes(b"\x89PNG")
    for name in extra:
        (folder / name).write_text("x")
    record(folder, LAYOUTS[layout])


def test_new_and_empty_folders(tmp_path):
    out = prepare(tmp_path / "a" / "b", LAYOUTS["cost"], resume=False)
    assert out.is_dir() and json.loads((out / MARKER).read_text())["command"] == "cost"
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / ".x.123.tmp").write_text("left by a killed writer")   # not a result file
    stream = io.StringIO()
    prepare(empty, LAYOUTS["cost"], resume=False, stream=stream)
    assert stream.getvalue() == ""
    # a folder left with only the marker (the command failed before computing): no notice
    prepare(out, LAYOUTS["cost"], resume=False, stream=stream)
    assert stream.getvalue() == "" and [p.name for p in out.iterdir() if p.name != LOCK] == [MARKER]
    with pytest.raises(InvalidInput, match="is a file"):
        prepare(tmp_path / "a" / "b" / MARKER, LAYOUTS["cost"], resume=False)


def test_previous_result_is_replaced_and_said_so(tmp_path):
    out = tmp_path / "f"
    _result(out)
    stream = io.StringIO()
    prepare(out, LAYOUTS["paper fig4"], resume=False, stream=stream)
    assert stream.getvalue() == (f"kinred paper fig4: replacing the previous run in {out}; "
                                 "use --resume to continue it\n")
    assert sorted(p.name for p in out.rglob("*") if p.name != LOCK) == [MARKER]   # emptied


def test_resume_keeps_the_previous_result(tmp_path):
    out = tmp_path / "f"
    _result(out)
    before = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    stream = io.StringIO()
    prepare(out, LAYOUTS["paper fig4"], resume=True, stream=stream)
    after = sorted(p.relative_to(out).as_posix() for p in out.rglob("*")
                   if p.is_file() and p.name != LOCK)                # (held until record)
    assert stream.getvalue() == "" and after == before


def test_foreign_files_are_refused_and_kept(tmp_path):
    _result(tmp_path / "g")
    (tmp_path / "g" / "notes.txt").write_text("mine")
    for resume in (False, True):
        with pytest.raises(InvalidInput, match=r"holds files kinred did not write for "
                                               r"`kinred paper fig4` \(notes.txt\)"):
            prepare(tmp_path / "g", LAYOUTS["paper fig4"], resume=resume)
    assert (tmp_path / "g" / "notes.txt").read_text() == "mine"
    assert (tmp_path / "g" / "summary.json").exists()
    # a folder of someone else's files, without any kinred result
    (tmp_path / "h").mkdir()
    for i in range(6):
        (tmp_path / "h" / f"data{i}.csv").write_text("1")
    with pytest.raises(InvalidInput, match=r"data0.csv, data1.csv, data2.csv, data3.csv, … "
                                           r"\(6 files\)"):
        prepare(tmp_path / "h", LAYOUTS["cost"], resume=False)
    # files named like a result (report.html) without the marker or the command's summary
    (tmp_path / "i").mkdir()
    (tmp_path / "i" / "report.html").write_text("<html>")
    with pytest.raises(InvalidInput, match="report.html"):
        prepare(tmp_path / "i", LAYOUTS["cost"], resume=False)


def test_result_of_another_command_is_refused(tmp_path):
    out = tmp_path / "f"
    _result(out)
    with pytest.raises(InvalidInput, match="holds the result of `kinred paper fig4`, not of "
                                           "`kinred cost`"):
        prepare(out, LAYOUTS["cost"], resume=False)
    assert (out / "summary.json").exists()


def test_legacy_result_without_marker(tmp_path):
    """A result written before the marker existed is recognized by its summary/stage index."""
    out = tmp_path / "f"
    _result(out)
    (out / MARKER).unlink()
    stream = io.StringIO()
    prepare(out, LAYOUTS["paper fig4"], resume=False, stream=stream)
    assert "replacing the previous run" in stream.getvalue()


def test_recorded_files_count_as_the_commands_own(tmp_path):
    """A file a newer version writes (not in the layout) is the command's once recorded."""
    out = tmp_path / "f"
    _result(out, extra=("extra-figure.svg",))
    assert "extra-figure.svg" in json.loads((out / MARKER).read_text())["files"]
    prepare(out, LAYOUTS["paper fig4"], resume=False, stream=io.StringIO())
    assert not (out / "extra-figure.svg").exists()


def test_results_root_is_results():
    assert _output.RESULTS.as_posix() == "results"

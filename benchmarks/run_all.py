"""Run every ``benchmarks/bench_*.py`` script, one process each, sequentially; collect the output.

Usage::

    python benchmarks/run_all.py [--quick] [--only NAME ...] [--out FILE] [--timeout S]

``--quick`` is passed to the scripts that accept it (those whose source declares a
``--quick`` option); the others run with their defaults. Each script runs in its own process
(``sys.executable``) with the repository on ``PYTHONPATH``, one after the other so that the
timings do not compete with each other. The combined log -- a header naming the machine (CPU
model, logical cores, Python and NumPy versions), then every script's output and wall time --
is printed and, with ``--out``, written to a file. The exit code is the number of scripts that
failed (0 when all succeeded).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def machine() -> str:
    """One line: CPU model, logical cores, Python and NumPy versions."""
    import numpy

    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{model}, {os.cpu_count()} logical cores, Python {platform.python_version()}, "
            f"NumPy {numpy.__version__}, {platform.system()} {platform.release()}")


def scripts(only=None) -> list[Path]:
    found = sorted(HERE.glob("bench_*.py"))
    if only:
        want = {o if o.startswith("bench_") else f"bench_{o}" for o in only}
        want = {w if w.endswith(".py") else w + ".py" for w in want}
        found = [p for p in found if p.name in want]
    return found


def accepts_quick(path: Path) -> bool:
    return '"--quick"' in path.read_text(encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="pass --quick to the scripts that take it")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="e.g. peers w1 (bench_ prefix optional)")
    ap.add_argument("--out", metavar="FILE", help="also write the combined log here")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per-script limit in seconds")
    args = ap.parse_args(argv)

    env = dict(os.environ)
    root = str(HERE.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    log: list[str] = []

    def emit(text: str = "") -> None:
        print(text, flush=True)
        log.append(text)

    emit(f"# kinred benchmarks ({'quick' if args.quick else 'full'}), "
         f"{time.strftime('%Y-%m-%d %H:%M %Z')}")
    emit(f"# machine: {machine()}")
    failed, summary = 0, []
    t_all = time.perf_counter()
    for path in scripts(args.only):
        cmd = [sys.executable, str(path)] + (["--quick"] if args.quick and accepts_quick(path) else [])
        emit()
        emit(f"## {path.name} ({' '.join(cmd[1:]).replace(str(HERE) + os.sep, '')})")
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True,
                                  timeout=args.timeout)
            out, code = proc.stdout + (("\n[stderr]\n" + proc.stderr) if proc.returncode else ""), proc.returncode
        except subprocess.TimeoutExpired as exc:
            out = (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            out += f"\n[timed out after {args.timeout:g} s]"
            code = -1
        secs = time.perf_counter() - t0
        emit(out.rstrip())
        status = "ok" if code == 0 else f"FAILED (exit {code})"
        emit(f"[{path.name}: {status}, {secs:.1f} s]")
        summary.append((path.name, status, secs))
        failed += code != 0
    emit()
    emit(f"# total {time.perf_counter() - t_all:.1f} s: "
         + ", ".join(f"{n} {s} {t:.0f} s" for n, s, t in summary))
    if args.out:
        Path(args.out).write_text("\n".join(log) + "\n", encoding="utf-8")
    return failed


if __name__ == "__main__":
    sys.exit(main())

"""kinred._parallel: one home for the thread count and parallel regions, shared by the
dynamics engine, the recovery solver and ensembles (none of them reaches into another
package's private modules for it)."""

import ast
import threading
from pathlib import Path

import kinred
from kinred import _parallel

PKG = Path(kinred.__file__).resolve().parent


def _imports(path: Path) -> set:
    """Absolute names of the modules imported by ``path`` (relative imports resolved)."""
    package = list(path.relative_to(PKG.parent).parts[:-1])     # e.g. ["kinred", "recovery"]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            names.add(mod)
            names.update(f"{mod}.{a.name}" for a in node.names)
    return names


def test_no_package_imports_a_private_module_of_dynamics():
    offenders = []
    for path in PKG.rglob("*.py"):
        if (PKG / "dynamics") in path.parents:
            continue
        for name in _imports(path):
            if name.startswith("kinred.dynamics._"):
                offenders.append((str(path.relative_to(PKG)), name))
    assert not offenders, offenders


def test_parallel_module_has_no_numba():
    names = _imports(PKG / "_parallel.py")
    assert not any(n == "numba" or n.startswith("numba.") for n in names), names


def test_thread_count_is_one_setting_everywhere():
    from kinred.dynamics import get_num_threads, set_num_threads

    assert set_num_threads is _parallel.set_num_threads is kinred.set_num_threads
    assert get_num_threads is _parallel.get_num_threads
    old = get_num_threads()
    try:
        set_num_threads(1)
        with _parallel.num_threads(2):
            assert _parallel.get_num_threads() == 2
        assert get_num_threads() == 1
    finally:
        set_num_threads(old)


def test_run_parallel_runs_group_zero_in_the_caller_and_keeps_order():
    seen = []

    def fn(g, arg):
        seen.append((g, threading.get_ident()))
        return arg * 10

    assert _parallel.run_parallel(fn, [1, 2, 3]) == [10, 20, 30]
    me = threading.get_ident()
    assert [t for g, t in seen if g == 0] == [me]
    assert all(t != me for g, t in seen if g != 0)

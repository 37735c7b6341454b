"""The layering of docs/architecture.md, read from the source (ast): no import cycles, each
package imports only what its row of the import table allows, and no module imports a private
module (or a private name) of another package.

The table is read from docs/architecture.md itself, so that the page and the rule cannot
drift. An import inside ``if TYPE_CHECKING:`` is not executed and does not count; an import
inside a function does (a lazy import hides a cycle, it does not remove it).
"""

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "kinred"
DOC = ROOT.parent / "docs" / "architecture.md"


def _modules() -> dict:
    mods = {}
    for p in ROOT.rglob("*.py"):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        pkg = parts[-1] == "__init__"
        mods[".".join(parts[:-1] if pkg else parts)] = (p, pkg)
    return mods


def _imports(tree) -> list:
    """Import nodes of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    out, todo = [], [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            todo.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.append(node)
        todo.extend(ast.iter_child_nodes(node))
    return out


def _edges():
    """``(module, imported module, name or None)`` for every import of a kinred module
    (``from .pkg import name`` names the module ``pkg.name`` when that is a module, else
    ``pkg`` with the name)."""
    mods = _modules()
    for mod, (path, pkg) in mods.items():
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in mods:
                        yield mod, a.name, None
                continue
            base = mod.split(".") if pkg else mod.split(".")[:-1]
            if node.level:
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                full = f"{target}.{a.name}"
                if full in mods:
                    yield mod, full, None
                elif target in mods:
                    yield mod, target, a.name


def import_graph() -> dict:
    """``{module: {kinred modules it imports}}``."""
    graph = {m: set() for m in _modules()}
    for mod, target, _ in _edges():
        if target != mod:
            graph[mod].add(target)
    return graph


def cycles(graph: dict) -> list:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_graph_sees_lazy_imports_and_skips_type_checking():
    g = import_graph()
    assert "kinred.quantize._planning" in g["kinred.quantize._quantization"]
    assert "kinred.quantize._quantization" not in g["kinred.quantize._planning"]  # TYPE_CHECKING
    assert "kinred.experiments.demo" in g["kinred.commands.demo"] or any(
        m.startswith("kinred.experiments") for m in g["kinred.commands.demo"])


def test_no_import_cycles():
    assert cycles(import_graph()) == []


# ---------------------------------------------------------------------------- the import table
#: Names of the "may import" column that are not kinred's (third-party libraries).
EXTERNAL = {"numpy", "scipy"}


def unit(module: str) -> str:
    """The package a module belongs to, as the table names it: ``kinred.pairsum._kernels`` →
    ``pairsum``, ``kinred._rng`` → ``_rng``, ``kinred`` (the top level) → ``kinred``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "kinred"


def private_inside(module: str) -> bool:
    """Whether ``module`` is a private module of its package (``kinred.pairsum._kernels``)."""
    return any(p.startswith("_") for p in module.split(".")[2:])


def parse_table(text: str):
    """``(allowed, base)`` from docs/architecture.md: ``{package: set of packages its row allows}``
    and the base layer every package may import (the sentence "Every package may import ...").

    A row is ``| `kinred.X` | role | may import |``; the last cell lists names separated by
    commas, parenthesised remarks ignored; ``–`` is nothing, ``everything`` every package,
    ``all of the above`` every package of the rows above.
    """
    rows = []
    for line in text.splitlines():
        m = re.match(r"\|\s*`kinred(\.[\w.]+)?`\s*(?:\(([^)]*)\))?\s*\|.*\|([^|]*)\|\s*$", line)
        if m:
            name = m.group(1)[1:] if m.group(1) else "kinred"
            rows.append((name, m.group(3)))
    names = [r[0] for r in rows]
    allowed = {}
    for i, (name, cell) in enumerate(rows):
        cell = re.sub(r"\([^)]*\)", "", cell).replace("`", "")
        out = set()
        for tok in (t.strip() for t in cell.split(",")):
            if tok in ("", "–", "-"):
                continue
            if tok == "everything":
                out.update(names)
            elif tok == "all of the above":
                out.update(names[:i])
            elif tok.removeprefix("kinred.") in names:
                out.add(tok.removeprefix("kinred."))
            elif tok not in EXTERNAL:
                raise ValueError(f"row {name}: {tok!r} is no package of the table")
        allowed[name] = out - {name}
    m = re.search(r"^Every package may import(.*?)\.(\s|$)", text, re.M | re.S)
    base = {b.removeprefix("kinred.") for b in re.findall(r"`([\w.]+)`", m.group(1))} if m else set()
    return allowed, base


def violations(edges, allowed: dict, base: set) -> list:
    """Imports that the table forbids, as readable lines: a package outside its row and the
    base layer, a private module of another package, a private name of another public package
    or module (the private top-level modules, ``kinred._validate`` and the like, are shared
    helpers: their names may be imported where their row allows)."""
    out = []
    for mod, target, name in edges:
        a, b = unit(mod), unit(target)
        if a == b:
            continue
        if a not in allowed:
            out.append(f"{mod}: package {a} has no row in the import table")
        elif b not in allowed[a] and b not in base:
            out.append(f"{mod} imports {target}: {b} is not in the row of {a}")
        if private_inside(target):
            out.append(f"{mod} imports the private module {target} of {b}")
        elif (name is not None and name.startswith("_") and not name.startswith("__")
              and not b.startswith("_")):
            out.append(f"{mod} imports the private name {name} of {target}")
    return list(dict.fromkeys(out))


def _table():
    return parse_table(DOC.read_text(encoding="utf-8"))


def test_table_reader_reads_the_rows_and_their_keywords():
    text = """
| package | role | may import |
|---|---|---|
| `kinred.errors` | errors | – |
| `kinred.a` | the a (with `b`) | errors, numpy (arrays) |
| `kinred.b` | bee | all of the above |
| `kinred.c` | sea | everything |

Every package may import the base layer: `kinred.errors` and
`kinred._base`. Other text: `kinred.a`.
"""
    allowed, base = parse_table(text)
    assert allowed == {"errors": set(), "a": {"errors"}, "b": {"errors", "a"},
                       "c": {"errors", "a", "b"}}
    assert base == {"errors", "_base"}
    with pytest.raises(ValueError, match="'bee'"):
        parse_table("| `kinred.a` | x | bee |")


def test_violations_finds_each_kind():
    allowed = {"a": {"b"}, "b": set(), "c": set()}
    edges = [("kinred.a.x", "kinred.b", "f"),              # allowed
             ("kinred.a.x", "kinred.b._k", None),          # private module
             ("kinred.a.x", "kinred.b.pub", "_helper"),    # private name
             ("kinred.b", "kinred.c.y", None),             # not in the row
             ("kinred.b", "kinred._base", "_short"),       # the base layer, its helpers
             ("kinred.d", "kinred.b", None),               # no row
             ("kinred.a._p", "kinred.a._q", "_r")]         # inside a package: anything
    assert violations(edges, allowed, {"_base"}) == [
        "kinred.a.x imports the private module kinred.b._k of b",
        "kinred.a.x imports the private name _helper of kinred.b.pub",
        "kinred.b imports kinred.c.y: c is not in the row of b",
        "kinred.d: package d has no row in the import table"]


def test_every_package_has_a_row_and_every_row_a_package():
    allowed, base = _table()
    units = {unit(m) for m in _modules()}
    assert units - set(allowed) == set(), "packages missing from the table of docs/architecture.md"
    assert set(allowed) - units == set(), "rows of docs/architecture.md naming no package"
    assert base and base <= set(allowed)


def test_imports_follow_the_table_of_docs_architecture():
    allowed, base = _table()
    assert violations(_edges(), allowed, base) == []


# ---------------------------------------------------------------------------- third-party imports
#: Import names of libraries the table names otherwise.
_IMPORT_NAME = {"POT": "ot"}


def external_imports():
    """``(module, top-level name)`` of every import of a library outside kinred."""
    for mod, (path, _) in _modules().items():
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                if name.split(".")[0] != "kinred":
                    yield mod, name.split(".")[0]


def sole_importers(text: str) -> dict:
    """``{library import name: package}`` from the rows saying "only package importing X"."""
    out = {}
    for line in text.splitlines():
        m = re.match(r"\|\s*`kinred\.(\w+)`\s*\|([^|]*)\|", line)
        if m:
            for lib in re.findall(r"only package importing (\w+)", m.group(2)):
                out[_IMPORT_NAME.get(lib, lib)] = m.group(1)
    return out


def test_libraries_stay_where_the_table_and_the_house_rules_put_them():
    """POT only in distance, matplotlib only in report (their rows say so); numba (and
    llvmlite, its code generator) only in private ``_kernels`` modules."""
    sole = sole_importers(DOC.read_text(encoding="utf-8"))
    assert sole == {"ot": "distance", "matplotlib": "report"}
    bad = []
    for mod, lib in external_imports():
        if lib in sole and unit(mod) != sole[lib]:
            bad.append(f"{mod} imports {lib}, which only kinred.{sole[lib]} may import")
        last = mod.rsplit(".", 1)[-1]
        if lib in ("numba", "llvmlite") and not (last.startswith("_") and last.endswith("kernels")):
            bad.append(f"{mod} imports {lib} outside a private _kernels module")
    assert bad == []


def test_import_kinred_leaves_the_slow_scipy_modules_for_later():
    """``import kinred`` (so every CLI call) does not import scipy.stats or scipy.integrate:
    they took 1 s of its 2 s; the functions that need them import them when called."""
    import subprocess
    import sys

    code = ("import sys, kinred, kinred.cli; "
            "print(sorted(m for m in ('scipy.stats', 'scipy.integrate') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout.strip()
    assert out == "[]"

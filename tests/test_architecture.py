"""The layering of docs/architecture.md, read from the source (ast): no import cycles.

An import inside ``if TYPE_CHECKING:`` is not executed and does not count; an import inside a
function does (a lazy import hides a cycle, it does not remove it).
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "kinred"


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


def import_graph() -> dict:
    """``{module: {kinred modules it imports}}`` (``from .pkg import name`` names the module
    ``pkg.name`` when that is a module, else ``pkg``)."""
    mods = _modules()
    graph = {m: set() for m in mods}
    for mod, (path, pkg) in mods.items():
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                graph[mod].update(a.name for a in node.names if a.name in mods)
                continue
            base = mod.split(".") if pkg else mod.split(".")[:-1]
            if node.level:
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                full = f"{target}.{a.name}"
                name = full if full in mods else target
                if name in mods and name != mod:
                    graph[mod].add(name)
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

"""The house rules the code can check: no library module imports the CLI; no private name crosses modules."""

from __future__ import annotations

import ast

from conftest import REPO

SRC = REPO / "src" / "wallcal"


def _imports(path):
    """(module, names) of every ``from ... import ...`` in the file, module resolved against wallcal."""
    rel = path.relative_to(SRC)
    package = ["wallcal", *rel.parts[:-1]]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            yield module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []


def _library_modules():
    return [p for p in SRC.rglob("*.py") if p.relative_to(SRC).parts[0] not in ("commands", "cli.py")]


def test_no_library_module_imports_the_cli():
    bad = []
    for path in _library_modules():
        for module, names in _imports(path):
            if module.startswith(("wallcal.commands", "wallcal.cli")) or (
                module == "wallcal" and {"commands", "cli"} & set(names)
            ):
                bad.append(f"{path.relative_to(SRC)}: {module}")
    assert not bad, bad


def test_no_private_name_is_imported_from_another_module():
    bad = []
    for path in SRC.rglob("*.py"):
        rel = path.relative_to(SRC)
        for module, names in _imports(path):
            for name in names:
                own_package = module == ".".join(["wallcal", *rel.parts[:-1]])  # a package's private module
                if name.startswith("_") and not name.startswith("__") and not own_package:
                    bad.append(f"{rel}: from {module} import {name}")
    assert not bad, bad


# ----------------------------------------------------------------------------- import circles
def _module_name(path) -> str:
    parts = ["wallcal", *path.relative_to(SRC).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(*, lazy: bool) -> dict[str, set[str]]:
    """``{module: modules of wallcal it imports}``; with ``lazy`` the imports inside functions count too.

    ``from .pkg import name`` points at the module ``pkg.name`` when there is one, else at ``pkg``. An import
    of a module does not count as one of its parent packages (Python runs those first, but a package's
    ``__init__`` importing its own modules is the normal layout, not a circle). Imports of the root package
    ``wallcal`` are left out: every wallcal module runs after ``wallcal/__init__`` has started (the only
    such import is the version lookup of :mod:`wallcal.outputs`).
    """
    paths = {_module_name(p): p for p in SRC.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        tree = ast.parse(path.read_text())
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        if lazy:
            nodes = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]
        else:  # the statements that run at import: the module's body, its if/try blocks included
            nodes, todo = [], list(tree.body)
            while todo:
                n = todo.pop()
                if isinstance(n, (ast.Import, ast.ImportFrom)):
                    nodes.append(n)
                elif isinstance(n, (ast.If, ast.Try)):
                    todo += n.body + n.orelse + getattr(n, "finalbody", [])
                    todo += [s for h in getattr(n, "handlers", []) for s in h.body]
        deps = set()
        for n in nodes:
            if isinstance(n, ast.Import):
                targets = [a.name for a in n.names]
            else:
                base = n.module or ""
                if n.level:
                    up = package.split(".")[: len(package.split(".")) - n.level + 1]
                    base = ".".join(up + ([n.module] if n.module else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in paths else base for a in n.names]
            deps |= {t for t in targets if t in paths and t not in (name, "wallcal")}
        graph[name] = deps
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
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

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle_among_module_level_imports():
    assert _cycles(_import_graph(lazy=False)) == []


def test_no_import_circle_even_counting_the_imports_inside_functions():
    """A lazy import defers a circle to run time but keeps it: none is allowed (idf <-> engines.energyplus was
    one; both now use :mod:`wallcal.eplus`, which imports no model writer)."""
    graph = _import_graph(lazy=True)
    assert _cycles(graph) == []
    assert not any(d.startswith("wallcal.engines") for d in graph["wallcal.idf"])


def test_the_cycle_finder_finds_a_circle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_one_module_launches_energyplus():
    """Only :mod:`wallcal.eplus` starts a process (EnergyPlus: the wall engine, building runs, IDF conversion)."""
    starters = []
    for path in SRC.rglob("*.py"):
        for module, names in _imports(path):
            if module == "subprocess" or (module == "os" and {"system", "popen", "spawnv"} & set(names)):
                starters.append(str(path.relative_to(SRC)))
        tree = ast.parse(path.read_text())
        if any(isinstance(n, ast.FunctionDef) and n.name == "energyplus_binary" for n in ast.walk(tree)):
            starters.append(f"{path.relative_to(SRC)}: defines energyplus_binary")
    assert sorted(set(starters)) == ["eplus.py", "eplus.py: defines energyplus_binary"]

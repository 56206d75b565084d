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

"""The package's layers and the one rule between them: a module imports only from its own layer
or the layers below it (docs/LAYOUT.md). Imports that only annotate (`if TYPE_CHECKING:`) and the
entry points (`__main__.py`, `if __name__ == "__main__":`) may look up: they run nothing at import.
The studies (`studies/`) stand above the lab, outside the package, which never imports them."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "dqfd_bc_keras"
STUDIES = REPO / "studies"

LAYERS = [
    ("base", ["errors", "choices", "seeds", "runtime", "files", "plugins"]),
    ("tasks", ["tasks"]),
    ("envs", ["envs"]),
    ("core", ["core"]),
    ("evaluation", ["evaluation"]),
    ("demos", ["demos"]),
    ("training", ["training"]),
    ("runs", ["runs"]),
    ("interfaces", ["model", "arguments", "commands", "__init__"]),
    ("lab", ["experiments"]),
    ("tuning", ["tuning"]),
]
"""Lowest first; each entry names the top-level modules and folders of `dqfd_bc_keras/` in it. Above
them all, outside the package, `studies/`: it may import any layer, and no layer may import it."""
RANK = {name: rank for rank, (_, names) in enumerate(LAYERS) for name in names}


def top_name(path: Path) -> str:
    """The top-level module or folder of the package a file belongs to."""
    return path.relative_to(PACKAGE).with_suffix("").parts[0]


def runtime_imports(path: Path) -> list[tuple[int, str]]:
    """(line, top-level name in the package) of each import that runs when the module does."""
    tree = ast.parse(path.read_text(), filename=str(path))
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = ast.unparse(node.test)
            if test in ("TYPE_CHECKING", "typing.TYPE_CHECKING") or test.startswith("__name__ =="):
                skipped |= {id(child) for child in ast.walk(node)}
    found = []
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path}:{node.lineno}: relative import; the package imports absolutely"
            parts = (node.module or "").split(".")
            if parts[0] != "dqfd_bc_keras":
                continue
            names = [parts[1]] if len(parts) > 1 else [alias.name for alias in node.names]
            found += [(node.lineno, name) for name in names if name in RANK]
        elif isinstance(node, ast.Import):
            found += [
                (node.lineno, alias.name.split(".")[1])
                for alias in node.names
                if alias.name.startswith("dqfd_bc_keras.")
            ]
    return found


MODULES = sorted(p for p in PACKAGE.rglob("*.py") if p.name != "__main__.py")


def test_every_module_has_a_layer():
    assert sorted({top_name(p) for p in MODULES} - set(RANK)) == []


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_point_down(path: Path):
    rank = RANK[top_name(path)]
    upward = [
        f"line {line}: {name} ({LAYERS[RANK[name]][0]})" for line, name in runtime_imports(path) if RANK[name] > rank
    ]
    assert upward == [], f"{path.relative_to(PACKAGE)} ({LAYERS[rank][0]}) imports from above: {upward}"


def imported_anywhere(source: str) -> set[str]:
    """Every module name an import statement of `source` names, wherever it stands (in a function,
    under TYPE_CHECKING, in an entry point)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.add(node.module or "")
    return names


def test_imports_anywhere_are_found_lazy_annotating_and_entry_point_ones_included():
    source = """
import os, studies.pixels
from typing import TYPE_CHECKING
if TYPE_CHECKING:
    from studies import sigma0
def report():
    from studies.minatar_study import ANCHORS
if __name__ == "__main__":
    import studies
"""
    assert imported_anywhere(source) == {"os", "studies.pixels", "typing", "studies", "studies.minatar_study"}


def test_nothing_in_the_package_imports_the_studies():
    """The wheel holds `dqfd_bc_keras` alone: an import of `studies` anywhere in it, even one that
    runs late, fails in every installed copy."""
    assert (STUDIES / "__init__.py").is_file() and not (PACKAGE / "studies").exists()
    found = [
        f"{path.relative_to(REPO)}: {name}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for name in imported_anywhere(path.read_text())
        if name.split(".")[0] == "studies"
    ]
    assert found == []

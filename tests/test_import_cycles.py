"""The package has no import cycle: the modules each module imports anywhere in its source (function
bodies and `if __name__ == "__main__":` blocks included) form a graph without one. Imports under
`if TYPE_CHECKING:` never run (they name a type for the checker), so they are not edges. (Which layer may
import which: tests/test_layers.py.)"""

import ast

from helpers import REPO

PACKAGE = REPO / "dqfd_bc_keras"


def import_graph() -> dict[str, set[str]]:
    """Each module of the package and the package modules it imports anywhere in its source
    (function bodies and `if __name__ == "__main__":` blocks included)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(REPO).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = set()
        tree = ast.parse(path.read_text())
        typing_only = {
            id(child)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
            for child in ast.walk(node)
        }
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.Import):
                edges |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                source = ".".join([*base, *([node.module] if node.module else [])])
                for alias in node.names:
                    edges.add(f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source)
        graph[name] = {edge for edge in edges if edge in modules} - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle found by a depth-first search, each as the path that closes it."""
    found, state = [], {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = "open"
        for child in sorted(graph[module]):
            if state.get(child) == "open":
                found.append([*path[path.index(child) :], child])
            elif child not in state:
                visit(child, [*path, child])
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    return found


def test_the_import_graph_check_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    graph = import_graph()
    assert "dqfd_bc_keras.demos.recording" in graph["dqfd_bc_keras.demos.experts"]  # relative imports are resolved
    assert "dqfd_bc_keras.commands.experts" in graph["dqfd_bc_keras.demos.experts"]  # the __main__ block counts


def test_the_package_has_no_import_cycle():
    assert cycles(import_graph()) == []

"""The layers of docs/design.md section 3, read from the source: who imports whom.

The import graph of ``app/`` and ``sitl/`` is built with ``ast`` from every ``import`` statement,
at the top of a module or inside a function alike (a cycle hidden in a function body is still a
cycle). An import of a package counts as an import of its ``__init__``.
"""

import ast
import subprocess
import sys
from collections.abc import Iterator
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("app", "sitl")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(
    tree: ast.Module, module: str, is_package: bool, modules: frozenset[str] = frozenset()
) -> Iterator[str]:
    """What ``module`` imports: ``from X import y`` is an import of ``X.y`` when that is one of
    ``modules``, else of ``X`` (its ``__init__``)."""
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                yield f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base


@cache
def import_graph() -> dict[str, frozenset[str]]:
    """Each module of app/ and sitl/ -> the modules of app/ and sitl/ it imports."""
    files = {
        _module_name(path): path for package in PACKAGES for path in (ROOT / package).rglob("*.py")
    }
    graph = {}
    for module, path in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        names = _imported(tree, module, path.name == "__init__.py", frozenset(files))
        graph[module] = frozenset(n for n in names if n in files and n != module)
    return graph


def _external(module: str) -> set[str]:
    """The top-level packages outside app/ and sitl/ that ``module`` imports."""
    path = ROOT / Path(*module.split("."))
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set(_imported(tree, module, path.name == "__init__.py"))
    return {n.split(".")[0] for n in names if n and n.split(".")[0] not in PACKAGES}


def cycles(graph: dict[str, frozenset[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def _in(module: str, *layers: str) -> bool:
    return any(module == layer or module.startswith(layer + ".") for layer in layers)


def _violations(layer: str, allowed: tuple[str, ...]) -> dict[str, list[str]]:
    graph = import_graph()
    return {
        m: sorted(d for d in deps if not _in(d, *allowed))
        for m, deps in sorted(graph.items())
        if _in(m, layer) and any(not _in(d, *allowed) for d in deps)
    }


def test_the_cycle_finder_names_a_cycle() -> None:
    graph = {"a": frozenset({"b"}), "b": frozenset({"c"}), "c": frozenset({"a"}), "d": frozenset()}
    assert cycles(graph) == [["a", "b", "c"]]


def test_no_import_cycles_between_modules() -> None:
    found = cycles(import_graph())
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def _named(violations: dict[str, list[str]]) -> str:
    return "\n".join(f"{m} imports {', '.join(deps)}" for m, deps in violations.items())


def test_core_imports_only_core_and_the_numerical_libraries() -> None:
    inside = _violations("app.core", ("app.core", "app.errors"))
    assert not inside, _named(inside)
    allowed = {"numpy", "scipy", "filterpy", "__future__"}
    stdlib = set(sys.stdlib_module_names)
    external = {
        m: sorted(bad)
        for m in import_graph()
        if _in(m, "app.core") and (bad := _external(m) - allowed - stdlib)
    }
    assert not external, _named(external)


def test_runtime_imports_no_adapters_cli_config_report_or_sitl() -> None:
    outside = _violations("app.runtime", ("app.runtime", "app.core", "app.errors"))
    assert not outside, _named(outside)


def test_sitl_imports_only_sitl_and_the_pure_core() -> None:
    outside = _violations("sitl", ("sitl", "app.core", "app.errors"))
    assert not outside, _named(outside)


def test_importing_the_mission_fast_simulation_loads_no_mavlink_or_mqtt() -> None:
    code = (
        "import sys, app.compose.mission_fastsim\n"
        "print(sorted(m for m in ('mavsdk', 'aiomqtt', 'pymavlink') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"

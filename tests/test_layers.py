"""The package layers only look down, without circles or private reach.

Layers: ``stereovo`` (numpy / numba) < ``vo_gym`` (the environment) < ``agents`` (torch,
stable-baselines3) < the command line (``vo_gym_cli``), one top-level package each. The checks
read the source with :mod:`ast`, so they see every import, also those inside functions that only
run on some paths.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("stereovo", "vo_gym", "agents", "vo_gym_cli")  # bottom to top


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES: dict[str, Path] = {
    _module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))
}
SCRIPTS: dict[str, Path] = {f"scripts/{p.name}": p for p in sorted((ROOT / "scripts").glob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.AST, module_level: bool) -> list[ast.Import | ast.ImportFrom]:
    """Import statements; ``module_level``: only those run on import (not in functions, not TYPE_CHECKING)."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            elif module_level and isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            elif module_level and isinstance(child, ast.If) and _is_type_checking(child):
                visit(ast.Module(body=child.orelse, type_ignores=[]))
            else:
                visit(child)

    visit(tree)
    return found


def _absolute(module: str, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module if MODULES.get(module, Path()).name == "__init__.py" else module.rpartition(".")[0]
    for _ in range(node.level - 1):
        package = package.rpartition(".")[0]
    return f"{package}.{node.module}" if node.module else package


def _project(name: str) -> str | None:
    """The project module ``name`` refers to (itself or the package holding the name), or None."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> list[tuple[str, str | None]]:
    """``(project module imported, name taken from it or None)`` for each name of the statement."""
    out: list[tuple[str, str | None]] = []
    if isinstance(node, ast.Import):
        out += [(t, None) for alias in node.names if (t := _project(alias.name))]
        return out
    base = _absolute(module, node)
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        if sub in MODULES:  # ``from package import submodule``
            out.append((sub, None))
        elif (t := _project(base)) is not None:
            out.append((t, alias.name))
    return out


def _graph(module_level: bool) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for module, path in MODULES.items():
        for node in _imports(ast.parse(path.read_text(), str(path)), module_level):
            graph[module] |= {t for t, _ in _targets(module, node) if t != module}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
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

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def _layer(module: str) -> int:
    return PACKAGES.index(module.partition(".")[0])


def test_the_walk_sees_every_package():
    assert {"stereovo", "stereovo.estimation.loop", "vo_gym.env", "agents.ppo.train",
            "agents.evaluation.run", "vo_gym_cli.main", "vo_gym_cli.commands.train"} <= set(
        MODULES
    )


def test_no_import_cycles_among_project_modules_at_module_level():
    assert _cycles(_graph(module_level=True)) == []


def test_no_import_cycles_even_through_imports_inside_functions():
    # a deferred import hides a circle from Python, not from a reader
    assert _cycles(_graph(module_level=False)) == []


def test_layers_only_look_down():
    upward = [
        f"{module} imports {target}"
        for module, targets in _graph(module_level=False).items()
        for target in sorted(targets)
        if _layer(target) > _layer(module)
    ]
    assert upward == []


@pytest.mark.parametrize("source", [*MODULES, *SCRIPTS])
def test_no_private_name_is_imported_from_another_module(source):
    path = MODULES.get(source) or SCRIPTS[source]
    private = [
        f"from {target} import {name} (line {node.lineno})"
        for node in _imports(ast.parse(path.read_text(), str(path)), module_level=False)
        for target, name in _targets(source, node)
        if name is not None and name.startswith("_") and not name.startswith("__") and target != source
    ]
    assert private == []


def test_scripts_read_no_private_attribute_of_the_environment():
    reach = [
        f"{name}: line {node.lineno} reads .{node.attr}"
        for name, path in SCRIPTS.items()
        for node in ast.walk(ast.parse(path.read_text(), str(path)))
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
        and isinstance(node.value, ast.Name) and node.value.id in {"env", "base", "unwrapped"}
    ]
    assert reach == []


def test_importing_the_simulator_and_environment_loads_no_torch_and_no_ray():
    code = (
        "import sys, gymnasium, stereovo, vo_gym, vo_gym.env, stereovo.estimation, stereovo.simulation\n"
        "env = gymnasium.make('vo_gym/StereoVO-v0', n_frames=2)\n"
        "print(sorted(m for m in ('torch', 'ray', 'stable_baselines3', 'tensorboard') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


# stereovo.estimation's floors, bottom to top (its package docstring draws the same map); a module
# imports only from its own floor or below. Sub-packages are one floor each.
ESTIMATION_FLOORS = (
    ("stereovo.estimation.kernels",),
    ("stereovo.estimation.problem",),
    ("stereovo.estimation.roles", "stereovo.estimation.covariance"),
    ("stereovo.estimation.estimator_options",),
    ("stereovo.estimation.loop", "stereovo.estimation.compiled_search"),
    ("stereovo.estimation.registry",),
    ("stereovo.estimation.recipes",),
    ("stereovo.estimation.methods",),
    ("stereovo.estimation.api",),
)


def _estimation_floor(module: str) -> int | None:
    """The floor of an estimation module; None outside it, and for the package itself (the top)."""
    for floor, prefixes in enumerate(ESTIMATION_FLOORS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return floor
    return len(ESTIMATION_FLOORS) if module == "stereovo.estimation" else None


def test_every_estimation_module_has_a_floor():
    assert [m for m in MODULES if m.startswith("stereovo.estimation") and _estimation_floor(m) is None] == []


def test_estimation_floors_only_look_down():
    upward = [
        f"{module} (floor {_estimation_floor(module)}) imports {target} (floor {_estimation_floor(target)})"
        for module, targets in _graph(module_level=False).items()
        if _estimation_floor(module) is not None
        for target in sorted(targets)
        if _estimation_floor(target) is not None and _estimation_floor(target) > _estimation_floor(module)
    ]
    assert upward == []


def _architecture_rooms(package: str) -> list[list[str]]:
    """The rows of docs/architecture.md's table for ``package``: each row's rooms as module prefixes
    (``options.py`` -> ``stereovo.options``, ``simulation/`` -> ``stereovo.simulation``)."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split(f"\n## {package}\n", 1)[1].split("\n## ", 1)[0].split("\n### ", 1)[0]
    rows = []
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        first = line.split("|")[1]
        rooms = [name.strip().strip("`").removesuffix(".py").removesuffix("/") for name in first.split(",")]
        rows.append([f"{package}.{room}" for room in rooms])
    return rows


@pytest.mark.parametrize("package", ["stereovo", "vo_gym", "agents"])
def test_the_architecture_lists_every_room_in_import_order(package):
    # docs/architecture.md: "a room imports only rooms above it in its list, or packages below it"
    rows = _architecture_rooms(package)
    row_of = {room: i for i, row in enumerate(rows) for room in row}

    def room_of(module: str) -> str | None:
        parts = module.split(".")
        return ".".join(parts[:2]) if len(parts) > 1 and parts[0] == package else None

    rooms = {room_of(m) for m in MODULES if room_of(m) is not None}
    assert sorted(rooms - set(row_of)) == [], "rooms missing from docs/architecture.md"
    assert sorted(set(row_of) - rooms) == [], "rooms in docs/architecture.md that do not exist"
    upward = sorted(
        f"{module} imports {target}"
        for module, targets in _graph(module_level=False).items() if room_of(module) is not None
        for target in targets
        if room_of(target) is not None and room_of(target) != room_of(module)
        and row_of[room_of(target)] > row_of[room_of(module)]
    )
    assert upward == []

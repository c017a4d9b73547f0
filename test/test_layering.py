"""Imports run one way and in no circle (read from the source with ``ast``).

Layers, lowest first: ``core.exceptions`` and ``core.input_checks`` <- ``core.model`` <-
``core.method`` <- ``core.analyses`` <- ``core.pipeline`` and ``core.options`` <- the adapters
(``cli``, ``ros``, ``validation``, ``dataset``, ``paths``). A module may import its own layer
or lower ones. ``core.kernels`` imports only itself and is imported only by ``core.method``;
``core`` never imports rclpy, ROS interface packages or an adapter; neither ``core`` nor the
ROS node (with all it imports) imports the batch's dependencies (BATCH_ONLY). Imports inside
functions count. For the layers, those under ``if TYPE_CHECKING:`` do not (they never run); for
cycles they do, at every level (a type-only circle still says a value type lives in the wrong
module).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

PACKAGE = "grasp_safety_ros"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE

LAYERS = (
    ("core.exceptions", "core.input_checks"),
    ("core.model",),
    ("core.method",),
    ("core.analyses", "core"),  # core/__init__.py re-exports model and method names
    ("core.pipeline", "core.options"),
    ("paths", "scenario"),  # where the config files are; the scenario and SPEC schema
    ("dataset", "ros", "validation"),  # the adapters on the pipeline
    ("cli",),  # the command line dispatches to batch and reproduce
)
"""Module prefixes (below the package) of each layer, lowest first. The adapters are layered
too: one adapter imports another only from a higher layer (a cli <-> dataset circle fails)."""

KERNELS = "core.kernels"
ROS_ONLY = ("rclpy", "builtin_interfaces", "rcl_interfaces", "ament_index_python")
BATCH_ONLY = ("dask", "distributed", "pyarrow", "h5py", "tqdm")
"""Imported by ``dataset`` (``grasp-safety batch``) only."""


def _short(module: str) -> str:
    return module.removeprefix(PACKAGE).removeprefix(".")


def _matches(module: str, prefix: str) -> bool:
    short = _short(module)
    return short == prefix or short.startswith(prefix + ".")


def layer_of(module: str) -> int | None:
    """Index in LAYERS of a package module (longest matching prefix); None for the kernels
    and the top-level package."""
    if _matches(module, KERNELS) or _short(module) == "":
        return None
    best: tuple[int, int] | None = None
    for index, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if _matches(module, prefix) and (best is None or len(prefix) > best[1]):
                best = (index, len(prefix))
    if best is None:
        raise AssertionError(f"{module}: in no layer; add it to LAYERS in {__file__}")
    return best[0]


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_of(
    source: str,
    module: str,
    is_package: bool,
    known: Iterable[str],
    type_checking: bool = False,
) -> set[str]:
    """Modules imported anywhere in ``source`` (module level and in functions), those under
    ``if TYPE_CHECKING:`` only when ``type_checking``; relative imports resolved,
    ``from pkg import submodule`` counted as the submodule when it is one of ``known``."""
    known = set(known)
    package = module if is_package else module.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test) and not type_checking:
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                target = f"{base}.{node.module}" if node.module else base
            else:
                target = node.module or ""
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                found.add(submodule if submodule in known else target)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source))
    return found


def package_imports(type_checking: bool = False) -> dict[str, set[str]]:
    """Every module of the package -> the modules it imports (with the type-only imports when
    ``type_checking``)."""
    files = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        files[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return {
        module: imports_of(path.read_text(), module, is_package, files, type_checking)
        for module, (path, is_package) in files.items()
    }


def layer_violations(graph: Mapping[str, Iterable[str]]) -> list[str]:
    """Imports that break the layering rule, as readable lines."""
    problems = []
    for module, targets in sorted(graph.items()):
        in_core = _matches(module, "core")
        for target in sorted(targets):
            top = target.split(".")[0]
            if in_core and (top in ROS_ONLY or top.endswith("_msgs")):
                problems.append(f"{module} imports {target}: core must stay free of ROS")
            if in_core and top in BATCH_ONLY:
                problems.append(f"{module} imports {target}: core must not need the batch's")
            if top != PACKAGE:
                continue
            if _matches(module, KERNELS):
                if not _matches(target, KERNELS):
                    problems.append(f"{module} imports {target}: kernels import only kernels")
                continue
            if _matches(target, KERNELS):
                if not _matches(module, "core.method"):
                    problems.append(f"{module} imports {target}: only core.method uses kernels")
                continue
            low, high = layer_of(target), layer_of(module)
            if low is not None and high is not None and low > high:
                problems.append(
                    f"{module} (layer {high}) imports {target} (layer {low}): upward import"
                )
    return problems


def find_cycle(graph: Mapping[str, Iterable[str]]) -> list[str] | None:
    """One import cycle among the graph's own modules, as [a, b, ..., a]; None if acyclic."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph.get(node, ())):
            if target not in graph:
                continue
            if state.get(target) == 1:
                return [*path[path.index(target) :], target]
            if target not in state and (cycle := visit(target)) is not None:
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)) is not None:
            return cycle
    return None


def test_package_imports_follow_the_layers() -> None:
    graph = package_imports()
    assert f"{PACKAGE}.core.method.ranking" in graph  # the walk found the package
    problems = layer_violations(graph)
    assert not problems, "\n".join(problems)


def reachable(graph: Mapping[str, Iterable[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through the package's own modules."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        module = todo.pop()
        for target in graph.get(module, ()):
            if target not in seen:
                seen.add(target)
                todo.append(target)
    return seen


def test_ros_node_does_not_import_the_batch_dependencies() -> None:
    graph = package_imports()
    imported = reachable(graph, f"{PACKAGE}.ros.node")
    assert f"{PACKAGE}.core.method.ranking" in imported  # the walk follows the package
    assert not {m for m in imported if m.split(".")[0] in BATCH_ONLY}
    batch = reachable(graph, f"{PACKAGE}.dataset.batch")
    assert {"pyarrow", "dask"} <= {m.split(".")[0] for m in batch}  # the check can fail
    module = f"{PACKAGE}.core.model.inertia"
    problems = layer_violations({module: {"h5py"}})
    assert len(problems) == 1 and "batch" in problems[0]


def test_package_has_no_import_cycle() -> None:
    cycle = find_cycle(package_imports(type_checking=True))
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def room_of(module: str) -> str:
    """The room (the package's top-level module or subpackage) of a package module."""
    return _short(module).split(".")[0]


def room_graph(graph: Mapping[str, Iterable[str]]) -> dict[str, set[str]]:
    """Room -> the other rooms its modules import."""
    rooms: dict[str, set[str]] = {}
    for module, targets in graph.items():
        for target in targets:
            if target.split(".")[0] == PACKAGE and room_of(target) != room_of(module):
                rooms.setdefault(room_of(module), set()).add(room_of(target))
    return rooms


def test_rooms_import_in_no_circle() -> None:
    rooms = room_graph(package_imports(type_checking=True))
    assert "core" in rooms.get("cli", set())  # the walk found the rooms
    cycle = find_cycle(rooms)
    assert cycle is None, "rooms import in a circle: " + " -> ".join(cycle or [])


def private_imports(source: str) -> list[tuple[str, str]]:
    """(module, name) of every ``from module import _name`` in ``source`` (relative modules as
    written, with their dots; dunder names such as ``__version__`` are public)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            module = "." * node.level + (node.module or "")
            found += [
                (module, a.name)
                for a in node.names
                if a.name.startswith("_") and not a.name.startswith("__")
            ]
    return found


def test_no_private_name_crosses_a_room() -> None:
    problems = []
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).parts
        room = parts[0].removesuffix(".py")
        for module, name in private_imports(path.read_text()):
            dots = len(module) - len(module.lstrip("."))
            # a relative import leaves the room when it climbs to the package (depth + 1 dots)
            leaves = dots and dots >= len(parts) and module.lstrip(".").split(".")[0] != room
            absolute = not dots and module.startswith(f"{PACKAGE}.")
            if leaves or (absolute and module.split(".")[1] != room):
                problems.append(f"{'/'.join(parts)} imports {name} from {module}")
    assert not problems, "\n".join(problems)


def test_checker_sees_lazy_imports_and_skips_type_checking_blocks() -> None:
    source = (
        "from typing import TYPE_CHECKING\n"
        "from .robot import RobotModel\n"
        "if TYPE_CHECKING:\n"
        "    from ..method.ranking import Grasp\n"
        "def f():\n"
        "    from ..method import ik\n"
        "    import rclpy\n"
    )
    module = f"{PACKAGE}.core.model.inertia"
    known = {f"{PACKAGE}.core.method.ik"}
    found = imports_of(source, module, False, known)
    assert found == {
        "typing",
        f"{PACKAGE}.core.model.robot",
        f"{PACKAGE}.core.method.ik",
        "rclpy",
    }
    with_types = imports_of(source, module, False, known, type_checking=True)
    assert with_types == found | {f"{PACKAGE}.core.method.ranking"}
    problems = layer_violations({module: found})
    assert len(problems) == 2
    assert "upward import" in problems[0] and "free of ROS" in problems[1]


def test_checker_rejects_kernels_outside_method_and_finds_cycles() -> None:
    core = f"{PACKAGE}.core"
    graph = {
        f"{core}.analyses.effort": {f"{core}.kernels.grasp"},
        f"{core}.kernels.grasp": {f"{core}.model.robot"},
        f"{core}.method.ik": {f"{core}.kernels.ik", f"{core}.method.compiled"},
        f"{core}.method.compiled": {f"{core}.method.ik"},
    }
    problems = layer_violations(graph)
    assert len(problems) == 2
    assert "only core.method uses kernels" in problems[0]
    assert "kernels import only kernels" in problems[1]
    compiled, ik = f"{core}.method.compiled", f"{core}.method.ik"
    assert find_cycle(graph) == [compiled, ik, compiled]
    del graph[f"{core}.method.compiled"]
    assert find_cycle(graph) is None

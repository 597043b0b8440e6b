"""The package's shape: stages import only upstream, modules import no cycle and no other
module's private names, functions stay short, the source cites no private notes, and test-only
code does not ship.

Every check reads the source with :mod:`ast` (nothing is imported), so a failure names the file,
the line and what to change.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

import pytest

PACKAGE = "undertow"
SRC = Path(__file__).resolve().parents[1] / "src" / PACKAGE

#: Stages in pipeline order: a module may import from its own stage or an earlier one. The
#: top-level modules of the package are keyed by their first name under ``undertow``.
STAGE_OF = {
    "": "core",  # the package __init__
    "errors": "core",
    "rotations": "core",
    "log": "core",
    "records": "core",
    "robot": "core",
    "trajectory": "core",
    "trajectory_chunks": "core",
    "occupancy": "core",
    "wavetrack": "core",
    "_util": "core",
    "io": "io",
    "sim": "sim",
    "estimation": "estimation",
    "seastate": "estimation",
    "peers": "peers",
    "mapping": "mapping",
    "settings": "settings",
    "evaluation": "evaluation",
    "report": "report",
    "study": "study",
    "live": "live",
    "commands": "commands",
    "cli": "cli",
}
RANK = {
    stage: rank
    for rank, stage in enumerate(
        ("core", "io", "sim", "estimation", "peers", "mapping", "settings", "evaluation", "report",
         "study", "live", "commands", "cli")
    )
}  # fmt: skip

MAX_FUNCTION_LINES = 80
#: decorators that compile a function with numba (long straight-line kernels are allowed)
NUMBA_DECORATORS = {"njit", "jit"}
#: packages only the tests use; the installed package must not import them
TEST_ONLY = {"pytest", "filterpy", "hypothesis", "_pytest"}
PRIVATE_NOTES = re.compile(r"\b(NOTES|DESIGN)(\.md)?\b")


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def _is_submodule(dotted: str) -> bool:
    rel = Path(*dotted.split(".")[1:])
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def _from_target(path: Path, node: ast.ImportFrom) -> str:
    """The absolute dotted name of the module ``from X import ...`` in ``path`` names as X."""
    if not node.level:
        return node.module or ""
    module = _module_name(path)
    base = (module if _is_package(path) else module.rpartition(".")[0]).split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imported_modules(path: Path, tree: ast.Module | None = None):
    """(line, absolute dotted name) of every ``undertow`` module ``path`` (or ``tree`` read as
    the file at ``path``) imports, at any depth (lazy imports inside functions count);
    ``from X import y`` names X.y when y is a module."""
    for node in ast.walk(tree or _tree(path)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == PACKAGE:
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            target = _from_target(path, node)
            if target.split(".")[0] != PACKAGE:
                continue
            for alias in node.names:
                candidate = f"{target}.{alias.name}"
                yield node.lineno, candidate if _is_submodule(candidate) else target


def _stage(dotted: str) -> str:
    parts = dotted.split(".")
    key = parts[1] if len(parts) > 1 else ""
    if key not in STAGE_OF:
        raise AssertionError(
            f"{dotted}: not in the stage table of tests/test_structure.py; add "
            f"{key!r} to STAGE_OF with the stage it belongs to"
        )
    return STAGE_OF[key]


def test_the_stage_table_covers_every_top_level_module():
    names = {p.stem if p.is_file() else p.name for p in SRC.iterdir()}
    top = {n for n in names if (SRC / f"{n}.py").is_file() or (SRC / n / "__init__.py").is_file()}
    missing = sorted(top - set(STAGE_OF) - {"__init__"})
    assert not missing, f"modules without a stage in STAGE_OF: {missing}"
    assert set(STAGE_OF.values()) <= set(RANK)


def test_no_module_imports_from_a_downstream_stage():
    edges = []
    for path in _modules():
        here = _module_name(path)
        for line, target in _imported_modules(path):
            a, b = _stage(here), _stage(target)
            if RANK[b] > RANK[a]:
                edges.append(f"{here} ({a}) -> {target} ({b})  at {path.relative_to(SRC)}:{line}")
    order = " < ".join(RANK)
    assert not edges, f"imports from a downstream stage (order: {order}):\n" + "\n".join(edges)


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_imports(path: Path):
    """(line, module, name) of every private name ``path`` takes from another undertow module:
    ``from X import _y`` (y not a submodule) and ``X._y`` on a module X it imported."""
    here = _module_name(path)
    modules = {}  # local name -> undertow module, for the attribute form
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            target = _from_target(path, node)
            if target.split(".")[0] != PACKAGE:
                continue
            for alias in node.names:
                if _is_submodule(f"{target}.{alias.name}"):
                    modules[alias.asname or alias.name] = f"{target}.{alias.name}"
                elif _is_private(alias.name) and target != here:
                    yield node.lineno, target, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname and alias.name.split(".")[0] == PACKAGE:
                    modules[alias.asname] = alias.name
    for node in ast.walk(_tree(path)):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in modules and _is_private(node.attr)):  # fmt: skip
            yield node.lineno, modules[node.value.id], node.attr


def test_no_private_name_is_imported_across_modules():
    hits = []
    for path in _modules():
        rel = path.relative_to(SRC).as_posix()
        for line, module, name in _private_imports(path):
            hits.append(f"{rel}:{line}: {name} from {module}")
    assert not hits, (
        "private names imported from another module; make the shared name public in its home "
        "module (or move it to the one module that uses it):\n" + "\n".join(dict.fromkeys(hits))
    )


def _import_graph() -> dict[str, dict[str, str]]:
    """module -> {imported undertow module: where (file:line)}, lazy imports included."""
    graph = {}
    for path in _modules():
        here = _module_name(path)
        edges = graph.setdefault(here, {})
        for line, target in _imported_modules(path):
            if target != here:
                edges.setdefault(target, f"{path.relative_to(SRC)}:{line}")
    return graph


def _cycles(graph: dict[str, dict[str, str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each as one cycle
    through its first module (a path back to itself inside the component)."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    cycles = []
    for component in components:
        start = min(component)
        paths = {start: [start]}  # breadth first inside the component, back to start
        queue = [start]
        while queue:
            v = queue.pop(0)
            for w in sorted(graph[v]):
                if w == start:
                    cycles.append(paths[v] + [start])
                    queue = []
                    break
                if w in component and w not in paths:
                    paths[w] = paths[v] + [w]
                    queue.append(w)
    return cycles


def test_the_import_graph_has_no_cycles():
    graph = _import_graph()
    lines = []
    for cycle in _cycles(graph):
        where = ", ".join(graph[a][b] for a, b in zip(cycle[:-1], cycle[1:], strict=True))
        lines.append(f"{' -> '.join(cycle)}  ({where})")
    assert not lines, (
        "import cycles between modules (lazy imports count: they only hide a cycle); move what "
        "both need to a module both can import:\n" + "\n".join(lines)
    )


def test_the_cycle_finder_names_a_cycle():
    graph = {"a": {"b": "a.py:1"}, "b": {"c": "b.py:1"}, "c": {"a": "c.py:1", "d": ""}, "d": {}}
    assert _cycles(graph) == [["a", "b", "c", "a"]]


def _decorator_names(node) -> set[str]:
    names = set()
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if isinstance(target, ast.Attribute):
            names.add(target.attr)
        elif isinstance(target, ast.Name):
            names.add(target.id)
    return names


def _functions(path: Path):
    """(qualified name, line, length in lines) of every function and method in ``path``."""

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                name = f"{prefix}{child.name}"
                if not _decorator_names(child) & NUMBA_DECORATORS:
                    yield name, child.lineno, child.end_lineno - child.lineno + 1
                yield from visit(child, f"{name}.")
            elif isinstance(child, ast.ClassDef):
                yield from visit(child, f"{prefix}{child.name}.")
            else:
                yield from visit(child, prefix)

    yield from visit(_tree(path), "")


def test_no_function_is_longer_than_80_lines_outside_numba_kernels():
    long = [
        f"{path.relative_to(SRC)}:{line} {name}: {length} lines"
        for path in _modules()
        for name, line, length in _functions(path)
        if length > MAX_FUNCTION_LINES
    ]
    assert not long, (
        f"functions longer than {MAX_FUNCTION_LINES} lines (numba njit/jit kernels excepted):\n"
        + "\n".join(long)
    )


def test_the_source_cites_public_sources_not_private_notes():
    hits = []
    for path in sorted(p for p in SRC.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if PRIVATE_NOTES.search(line):
                hits.append(f"{path.relative_to(SRC)}:{number}: {line.strip()}")
    assert not hits, (
        "the package mentions NOTES.md / DESIGN.md, files it does not ship; state the fact or "
        "cite a public source (the paper, a standard, a datasheet, a textbook):\n" + "\n".join(hits)
    )


def test_test_only_packages_are_not_imported_by_the_package():
    hits = []
    for path in _modules():
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            else:
                continue
            for name in names:
                if name.split(".")[0] in TEST_ONLY:
                    hits.append(f"{path.relative_to(SRC)}:{node.lineno}: imports {name}")
    assert not hits, "test-only code ships in the package:\n" + "\n".join(hits)


@pytest.mark.parametrize(
    ("source", "module", "expected"),
    [
        ("from ..io import read_log", "undertow/commands/common.py", {"undertow.io"}),
        ("from .. import settings", "undertow/commands/common.py", {"undertow.settings"}),
        ("from . import data", "undertow/cli/__init__.py", {"undertow.cli.data"}),
        ("from .tum import write_tum", "undertow/io/results.py", {"undertow.io.tum"}),
        ("import undertow.sim.waves as w", "undertow/log.py", {"undertow.sim.waves"}),
        ("from undertow import log", "undertow/io/tum.py", {"undertow.log"}),
        ("import numpy", "undertow/log.py", set()),
    ],
)
def test_relative_imports_resolve_to_the_module_they_name(source, module, expected):
    got = {name for _, name in _imported_modules(SRC.parent / module, ast.parse(source))}
    assert got == expected


#: project-level tests at the root of tests/ (not of one stage)
ROOT_TESTS = {
    "test_structure.py", "test_examples.py", "test_readme_example.py", "test_compile_once.py"
}  # fmt: skip


def test_the_tests_mirror_the_source():
    """Each test file sits in the folder of the stage it tests (tests/io/, tests/live/, ...:
    a package of src/undertow, or tests/core/ for the core modules); the root holds only the
    project-level tests and the shared fixtures."""
    tests = Path(__file__).resolve().parent
    packages = {p.name for p in SRC.iterdir() if (p / "__init__.py").is_file()} | {"core"}
    misplaced = [
        str(path.relative_to(tests))
        for path in tests.rglob("test_*.py")
        if (path.parent == tests and path.name not in ROOT_TESTS)
        or (path.parent != tests and path.parent.name not in packages)
    ]
    assert not misplaced, f"test files outside a stage's folder: {misplaced}"


MAX_MODULE_LINES = 600


def test_no_module_is_longer_than_600_lines_outside_numba_kernels():
    long = []
    for path in _modules():
        tree = _tree(path)
        kernels = sum(
            node.end_lineno - node.lineno + 1
            for node in ast.walk(tree)
            if isinstance(node, ast.FunctionDef) and _decorator_names(node) & NUMBA_DECORATORS
        )
        lines = len(path.read_text(encoding="utf-8").splitlines()) - kernels
        if lines > MAX_MODULE_LINES:
            long.append(f"{path.relative_to(SRC)}: {lines} lines")
    assert not long, f"modules longer than {MAX_MODULE_LINES} lines outside numba kernels: {long}"

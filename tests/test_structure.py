"""The package's shape: stages import only upstream, functions stay short, the source cites no
private notes, and test-only code does not ship.

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
    "trajectory": "core",
    "occupancy": "core",
    "wavetrack": "core",
    "_util": "core",
    "io": "io",
    "sim": "sim",
    "estimation": "estimation",
    "seastate": "estimation",
    "mapping": "mapping",
    "settings": "settings",
    "evaluation": "evaluation",
    "report": "report",
    "study": "study",
    "jobs": "jobs",
    "cli": "cli",
}
RANK = {
    stage: rank
    for rank, stage in enumerate(
        ("core", "io", "sim", "estimation", "mapping", "settings", "evaluation", "report",
         "study", "jobs", "cli")
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


def _imported_modules(path: Path, tree: ast.Module | None = None):
    """(line, absolute dotted name) of every ``undertow`` module ``path`` (or ``tree`` read as
    the file at ``path``) imports, at any depth (lazy imports inside functions count);
    ``from X import y`` names X.y when y is a module."""
    module = _module_name(path)
    package = module if _is_package(path) else module.rpartition(".")[0]
    for node in ast.walk(tree or _tree(path)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == PACKAGE:
                    yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
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
        ("from ..io import read_log", "undertow/jobs/common.py", {"undertow.io"}),
        ("from .. import settings", "undertow/jobs/common.py", {"undertow.settings"}),
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

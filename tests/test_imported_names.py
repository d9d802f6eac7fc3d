"""Every name imported from the package exists, in the package, benchmarks, examples and docs.

Read from the source, not imported: an import inside a function (an extra's lazy import, a
benchmark's set-up) runs only when that code does, so a rename could leave it stale, unseen
until someone runs the script. A name exists when the module binds it at its top level (a
definition, an assignment or an import), lists it in ``__all__`` (a lazily loaded name), or is
one of its submodules; failing those (a module that binds names in a loop, as
:mod:`delayed_rl.agents` binds the registry's classes), when the imported module has it.
"""

from __future__ import annotations

import ast
import importlib
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import pytest

import delayed_rl

PACKAGE = Path(delayed_rl.__file__).parent
ROOT = PACKAGE.parent
SCRIPT_FOLDERS = ("delayed_rl", "benchmarks", "examples", "docs", "tests")


def _module_file(module: str) -> Path | None:
    """The source of a ``delayed_rl`` module, or ``None`` when there is none."""
    base = ROOT.joinpath(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@cache
def _bound_names(module: str) -> frozenset[str]:
    """The names ``module`` binds at its top level or lists in ``__all__``."""
    tree = ast.parse(_module_file(module).read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in _run_at_import(tree.body):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                names.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
                if isinstance(target, ast.Name) and target.id == "__all__":  # its strings
                    names.update(
                        item.value
                        for item in ast.walk(node.value)
                        if isinstance(item, ast.Constant) and isinstance(item.value, str)
                    )
    return frozenset(names)


def _run_at_import(statements: list[ast.stmt]) -> Iterator[ast.stmt]:
    """The statements that run at import: these, and those under their ``if`` and ``try``."""
    for statement in statements:
        yield statement
        if isinstance(statement, ast.If | ast.Try):
            yield from _run_at_import(statement.body + statement.orelse)
        if isinstance(statement, ast.Try):
            yield from _run_at_import(statement.finalbody)
            for handler in statement.handlers:
                yield from _run_at_import(handler.body)


def _has_name(module: str, name: str) -> bool:
    """Whether ``module`` has ``name``: read from its source, else from the module imported."""
    if name in _bound_names(module) or _module_file(f"{module}.{name}") is not None:
        return True
    return hasattr(importlib.import_module(module), name)


def _importing_module(path: Path) -> str | None:
    """The dotted name of a package file, for its relative imports (``None`` outside it)."""
    if PACKAGE not in path.parents:
        return None
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _absolute(node: ast.ImportFrom, path: Path) -> str | None:
    """The module a ``from ... import`` reads, as an absolute name."""
    if not node.level:
        return node.module
    importer = _importing_module(path)
    if importer is None:
        return None
    package = importer.split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    package = package[: len(package) - node.level + 1]
    return ".".join(package + ([node.module] if node.module else []))


def missing_names(source: str, path: Path) -> list[str]:
    """``module.name`` for every ``delayed_rl`` import of ``source`` that names nothing."""
    missing = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
            missing += [m for m in modules if m.startswith("delayed_rl") and not _module_file(m)]
        elif isinstance(node, ast.ImportFrom):
            module = _absolute(node, path)
            if module is None or not module.startswith("delayed_rl"):
                continue
            if _module_file(module) is None:
                missing.append(module)
                continue
            for alias in node.names:
                name = alias.name
                if name != "*" and not _has_name(module, name):
                    missing.append(f"{module}.{name}")
    return missing


def _scripts() -> list[Path]:
    return sorted(
        path
        for folder in SCRIPT_FOLDERS
        for path in (ROOT / folder).rglob("*.py")
        if ".venv" not in path.parts and "_build" not in path.parts
    )


@pytest.mark.parametrize("path", _scripts(), ids=lambda path: str(path.relative_to(ROOT)))
def test_every_name_imported_from_the_package_exists(path):
    assert missing_names(path.read_text(encoding="utf-8"), path) == []


def test_the_check_sees_a_stale_name_imported_inside_a_function():
    source = (
        "def run():\n"
        "    from delayed_rl.deep import IRCRRewardModel, RelabelingReplayBuffer\n"
        "    import delayed_rl.nowhere\n"
        "    from delayed_rl.agents.mmq import mmq, no_such_module\n"
    )
    assert missing_names(source, ROOT / "benchmarks" / "example.py") == [
        "delayed_rl.deep.IRCRRewardModel",
        "delayed_rl.nowhere",
        "delayed_rl.agents.mmq.no_such_module",
    ]


def test_the_check_resolves_relative_imports_from_the_importing_package():
    inside = PACKAGE / "deep" / "buffers.py"
    assert missing_names("from .ircr import IRCRReplayBuffer\n", inside) == []
    assert missing_names("from .ircr import IRCRRewardModel\n", inside) == [
        "delayed_rl.deep.ircr.IRCRRewardModel"
    ]
    assert missing_names("from ..delays import Poisson, Poison\n", inside) == [
        "delayed_rl.delays.Poison"
    ]

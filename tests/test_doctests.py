"""Every ``>>>`` example in the package's docstrings runs and prints what it claims.

The modules are found, not listed: every module under ``delayed_rl/`` whose source holds a
``>>>`` line is a test case of its own, imported and searched with ``doctest.DocTestFinder`` by
its test (not at collection: ``delayed_rl.wrappers.sb3`` imports stable-baselines3, so torch).
``test_every_module_imports_and_the_search_misses_no_example`` imports every module, those that
need an optional extra (stable-baselines3, matplotlib) too: CI installs the extras, so a missing
one fails there instead of silently skipping examples.
"""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import pkgutil
from pathlib import Path

import pytest

import delayed_rl

OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _reraise(name: str) -> None:
    """``walk_packages``' ``onerror``: a subpackage that fails to import fails the tests."""
    raise  # called inside walk_packages' except clause: re-raises the error it caught


def _module_names() -> list[str]:
    """The package and every module below it, by dotted name (subpackages are imported, modules not)."""
    found = pkgutil.walk_packages(delayed_rl.__path__, prefix="delayed_rl.", onerror=_reraise)
    return ["delayed_rl", *sorted(info.name for info in found)]


def _has_examples(name: str) -> bool:
    """Whether module ``name``'s source has a ``>>>`` line: read, not imported."""
    source = Path(importlib.util.find_spec(name).origin).read_text(encoding="utf-8")
    return any(line.lstrip().startswith(">>>") for line in source.splitlines())


def _examples(name: str) -> list[doctest.DocTest]:
    """The doctests of module ``name`` that hold at least one example."""
    module = importlib.import_module(name)
    tests = doctest.DocTestFinder().find(module, name)
    return [test for test in tests if test.examples]


MODULES = [name for name in _module_names() if _has_examples(name)]
TORCH_PACKAGES = ("delayed_rl.deep", "delayed_rl.multiagent.sb3")
"""Their examples import torch (the ``sb3`` extra): their cases are ``sb3``-marked."""


def _case(name: str):
    """``name`` as a case of :func:`test_doctests`, marked ``sb3`` when its examples need torch."""
    if any(name == package or name.startswith(f"{package}.") for package in TORCH_PACKAGES):
        return pytest.param(name, marks=pytest.mark.sb3)
    return name


def test_the_search_finds_the_examples():
    # a search that found nothing would leave test_doctests with no case, and pass
    assert {"delayed_rl.delays", "delayed_rl.wrappers.reward_delay"} <= set(MODULES)


@pytest.mark.sb3  # delayed_rl.wrappers.sb3 imports stable-baselines3, so torch
def test_every_module_imports_and_the_search_misses_no_example():
    assert [name for name in _module_names() if _examples(name)] == MODULES


@pytest.mark.parametrize("name", [_case(name) for name in MODULES])
def test_doctests(name: str) -> None:
    """Each example runs; an agent class one defines leaves the model-file class table after."""
    from delayed_rl.agents.common import persistence

    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    classes = dict(persistence.AGENT_CLASSES)
    try:
        for test in _examples(name):
            runner.run(test)
    finally:
        persistence.AGENT_CLASSES.clear()
        persistence.AGENT_CLASSES.update(classes)
    result = runner.summarize(verbose=False)
    assert result.attempted > 0, f"{name}'s >>> lines are no doctest example"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"

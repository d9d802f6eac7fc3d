"""Every ``>>>`` example in the package's docstrings runs and prints what it claims.

The modules are found, not listed: every module under ``delayed_rl/`` is imported and searched
with ``doctest.DocTestFinder``; each one with at least one example is a test case of its own.
Modules that need an optional extra (stable-baselines3, matplotlib) are imported too: CI
installs the extras, so a missing one fails here instead of silently skipping examples.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import delayed_rl

OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _reraise(name: str) -> None:
    """``walk_packages``' ``onerror``: a subpackage that fails to import fails the tests."""
    raise  # called inside walk_packages' except clause: re-raises the error it caught


def _module_names() -> list[str]:
    """The package and every module below it, by dotted name."""
    found = pkgutil.walk_packages(delayed_rl.__path__, prefix="delayed_rl.", onerror=_reraise)
    return ["delayed_rl", *sorted(info.name for info in found)]


def _examples(name: str) -> list[doctest.DocTest]:
    """The doctests of module ``name`` that hold at least one example."""
    module = importlib.import_module(name)
    tests = doctest.DocTestFinder().find(module, name)
    return [test for test in tests if test.examples]


MODULES = [name for name in _module_names() if _examples(name)]


def test_the_search_finds_the_examples():
    # a search that found nothing would leave test_doctests with no case, and pass
    assert {"delayed_rl.delays", "delayed_rl.wrappers.reward_delay"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_doctests(name: str) -> None:
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    for test in _examples(name):
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"

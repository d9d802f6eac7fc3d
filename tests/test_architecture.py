"""The package's shape: no import cycles, and user subclasses of the agents save and load."""

from __future__ import annotations

import ast
import inspect
import warnings
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl
from delayed_rl.agents import (
    DEFAULTS,
    MMQ,
    FixedDelayQLearning,
    QLearning,
    TabularAgent,
    load_agent,
)
from delayed_rl.agents.hyperparameters import HYPERPARAMETER_NAMES

PACKAGE = Path(delayed_rl.__file__).parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(path: Path, modules: set[str]) -> set[str]:
    """The package modules ``path`` imports anywhere (lazy imports in functions included).

    ``from a.b import c`` is an edge to ``a.b.c`` when that is a module, else to ``a.b``; imports
    under ``if TYPE_CHECKING:`` never run and are left out.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped = {
        id(node)
        for branch in ast.walk(tree)
        if isinstance(branch, ast.If) and _is_type_checking(branch)
        for node in ast.walk(branch)
    }
    package = (
        _module_name(path)
        if path.name == "__init__.py"
        else _module_name(path.parent / "__init__.py")
    )
    found = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base)
    return {name for name in found if name in modules} - {_module_name(path)}


def import_graph() -> dict[str, set[str]]:
    """Every module of ``delayed_rl`` and the package modules it imports."""
    paths = sorted(PACKAGE.rglob("*.py"))
    modules = {_module_name(path) for path in paths}
    return {_module_name(path): _imports(path, modules) for path in paths}


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph.get(node, ())):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return components


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycles(graph) == [["a", "b", "c"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_graph_sees_the_package():
    graph = import_graph()
    assert "delayed_rl._validation" in graph["delayed_rl.agents.base"]
    assert "delayed_rl.agents.save_util" in graph["delayed_rl.agents._persistence"]
    assert len(graph) > 30


def test_no_import_cycles_in_the_package():
    assert find_cycles(import_graph()) == []


def test_save_util_imports_no_agent():
    imported = import_graph()["delayed_rl.agents.save_util"]
    assert not {name for name in imported if name.startswith("delayed_rl.agents")}


class MyMMQ(MMQ):
    """A user's subclass, defined at module level."""


def test_a_user_subclass_saves_and_loads_as_itself(tmp_path):
    env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=1)
    agent = MyMMQ(env, max_delay_estimate=3, q_init=5.0, seed=1).learn(2_000)
    path = agent.save(tmp_path / "mine")
    for loaded in (MyMMQ.load(path), MMQ.load(path), load_agent(path), TabularAgent.load(path)):
        assert type(loaded) is MyMMQ
        np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    with pytest.raises(ValueError, match="holds a MyMMQ model, not a QLearning"):
        QLearning.load(path)


def test_a_subclass_defined_in_a_function_saves_and_loads(tmp_path):
    class Local(QLearning):
        pass

    path = Local("delayed_rl/Roulette-v0", seed=0).learn(100).save(tmp_path / "local")
    assert type(load_agent(path)) is Local


def test_a_file_of_an_undefined_class_names_it(tmp_path):
    class Gone(QLearning):
        pass

    path = Gone("delayed_rl/Roulette-v0", seed=0).save(tmp_path / "gone")
    from delayed_rl.agents import _persistence

    del _persistence.AGENT_CLASSES[_persistence.class_key(Gone)]
    with pytest.raises(ValueError, match="unknown agent class .*Gone.*import the module"):
        load_agent(path)


def test_deprecated_names_still_work(tmp_path):
    agent = QLearning("delayed_rl/GridWorld-3x3-v0", seed=0).learn(50, record=True)
    with pytest.warns(DeprecationWarning, match="episode_end"):
        np.testing.assert_array_equal(agent.training_log["done"], agent.training_log["episode_end"])
    from delayed_rl.agents import serialization

    with pytest.warns(DeprecationWarning, match="agent.save"):
        path = serialization.save_agent(agent, tmp_path / "old")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert type(load_agent(path)) is QLearning


@pytest.mark.parametrize("cls", [MMQ, QLearning, FixedDelayQLearning])
def test_every_agent_shows_the_shared_hyperparameters_with_the_one_set_of_defaults(cls):
    shown = inspect.signature(cls).parameters
    for name, default in {**asdict(DEFAULTS), "seed": None, "verbose": 0}.items():
        assert shown[name].default == default, name
    base = inspect.signature(TabularAgent.__init__).parameters
    assert {name: base[name].default for name in HYPERPARAMETER_NAMES} == {
        name: shown[name].default for name in HYPERPARAMETER_NAMES
    }
    agent = cls("delayed_rl/GridWorld-3x3-v0", gamma=0.5, q_init=2.0, **_own_arguments(cls))
    assert agent.gamma == 0.5 and agent.q_init == 2.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'gammma'"):
        cls("delayed_rl/GridWorld-3x3-v0", gammma=0.5, **_own_arguments(cls))


def _own_arguments(cls):
    return {"delay_estimate": 1} if cls is FixedDelayQLearning else {}

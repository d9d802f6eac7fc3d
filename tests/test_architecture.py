"""The package's shape: layers, no import cycles, and user subclasses of the agents save and load.

The layers, from the bottom: the base (validation, delays, the delay line, the numba helpers,
the portable maths) < {wrappers, envs} < the compiled training path < agents < {experiments,
sweeps} < the command line. A module imports only from its own layer or below, counting what
the ``__init__`` of every package on an imported module's path runs (importing
``delayed_rl.envs.linefollow.env`` runs ``delayed_rl/envs/__init__.py`` and
``delayed_rl/envs/linefollow/__init__.py``). The root package ``delayed_rl`` is every module's
parent: it registers the env ids and imports its agents only on first use, so it is not a layer.
"""

from __future__ import annotations

import ast
import inspect
import json
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl
from delayed_rl import agents
from delayed_rl.agents import (
    DEFAULTS,
    FixedDelayQLearning,
    MultipleModelQLearning,
    QLearning,
    TabularAgent,
    load_agent,
)
from delayed_rl.agents.common.hyperparameters import HYPERPARAMETER_NAMES
from delayed_rl.agents.registry import REGISTRY, agent_class

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
    return _source_imports(
        _module_name(path), path.name == "__init__.py", path.read_text(encoding="utf-8"), modules
    )


def _source_imports(module: str, is_package: bool, source: str, modules: set[str]) -> set[str]:
    """:func:`_imports` of the ``source`` of ``module`` (a package's ``__init__`` if ``is_package``)."""
    tree = ast.parse(source)
    skipped = {
        id(node)
        for branch in ast.walk(tree)
        if isinstance(branch, ast.If) and _is_type_checking(branch)
        for node in ast.walk(branch)
    }
    package = module if is_package else module.rpartition(".")[0]
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
    return {name for name in found if name in modules} - {module}


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


#: The layers, bottom first: (name, the module prefixes in it).
LAYERS = [
    (
        "base",
        (
            "delayed_rl._validation",
            "delayed_rl._version",
            "delayed_rl.delays",
            "delayed_rl._delay_line",
            "delayed_rl._numba",
            "delayed_rl._portable_math",
            "delayed_rl._lazy",
        ),
    ),
    ("wrappers and envs", ("delayed_rl.wrappers", "delayed_rl.multiagent", "delayed_rl.envs")),
    ("the compiled path", ("delayed_rl.compiled",)),
    ("agents", ("delayed_rl.agents", "delayed_rl.deep")),
    ("parallel runs and figures", ("delayed_rl.parallel", "delayed_rl.figures")),
    ("experiments and sweeps", ("delayed_rl.experiments", "delayed_rl.sweep")),
    ("the command line", ("delayed_rl.cli",)),
]


def layer_of(module: str) -> int | None:
    """The index in :data:`LAYERS` of ``module`` (``None``: the root package)."""
    for index, (_, prefixes) in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return index
    return None


def _packages_of(module: str) -> set[str]:
    """The packages on ``module``'s path, the root's subpackages down to its parent."""
    parts = module.split(".")
    return {".".join(parts[:k]) for k in range(2, len(parts))}


def with_parents(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """``graph`` plus the ``__init__`` of every package an import runs.

    Importing ``N`` from ``M`` runs the ``__init__`` of ``N``'s packages, except those on
    ``M``'s own path, which were imported before ``M`` was.
    """
    full = {}
    for module, imported in graph.items():
        edges = set(imported)
        for name in imported:
            edges |= _packages_of(name) - _packages_of(module) - {module}
        full[module] = {name for name in edges if name in graph} - {module}
    return full


def test_every_module_is_in_a_layer():
    assert [m for m in import_graph() if layer_of(m) is None] == ["delayed_rl"]


def test_imports_only_go_down_the_layers():
    upward = [
        f"{module} ({LAYERS[layer_of(module)][0]}) imports {name} ({LAYERS[layer_of(name)][0]})"
        for module, imported in sorted(with_parents(import_graph()).items())
        if module != "delayed_rl"
        for name in sorted(imported)
        if name != "delayed_rl" and layer_of(name) > layer_of(module)
    ]
    assert upward == []


def test_the_layer_check_sees_an_upward_import_through_a_parent_package():
    graph = {"delayed_rl.envs.x": {"delayed_rl.agents.y"}, "delayed_rl.agents": set()}
    graph["delayed_rl.agents.y"] = set()
    assert with_parents(graph)["delayed_rl.envs.x"] == {"delayed_rl.agents", "delayed_rl.agents.y"}


def test_the_root_package_imports_only_the_registration():
    assert import_graph()["delayed_rl"] == {
        "delayed_rl.envs",
        "delayed_rl._version",
        "delayed_rl.agents",
    }
    imported = _modules_after("import delayed_rl")
    assert {m for m in imported if m.startswith("delayed_rl")} == {
        "delayed_rl",
        "delayed_rl.envs",
        "delayed_rl._version",
    }


def test_no_group_of_modules_imports_each_other_counting_parent_packages():
    graph = with_parents(import_graph())
    graph.pop("delayed_rl")  # every module's parent (see the module docstring)
    assert find_cycles({m: edges - {"delayed_rl"} for m, edges in graph.items()}) == []


EXPERIMENTS = PACKAGE / "experiments"
#: The experiments' own groups: the thesis's experiments and those beyond it.
GROUPS = ("thesis", "beyond")


def experiment_modules() -> set[str]:
    """Every experiment module: those ``get_experiment`` imports, and every module of the groups."""
    from delayed_rl.experiments import _MODULES

    named = {f"delayed_rl.experiments.{module}" for module in _MODULES.values()}
    grouped = {
        _module_name(path)
        for group in GROUPS
        for path in (EXPERIMENTS / group).rglob("*.py")
        if path.name != "__init__.py"
    }
    return named | grouped


def experiment_imports(graph: dict[str, set[str]], experiments: set[str]) -> list[str]:
    """``"A imports B"`` for every experiment module A of ``graph`` importing another, B."""
    return [
        f"{module} imports {other}"
        for module in sorted(experiments & set(graph))
        for other in sorted(graph[module] & experiments)
    ]


def test_no_experiment_module_imports_another():
    """What experiments share is in ``experiments/framework/``, not in one of them."""
    assert experiment_imports(import_graph(), experiment_modules()) == []


def test_every_experiment_is_a_module_of_the_thesis_or_beyond_it():
    from delayed_rl.experiments import _MODULES

    assert [m for m in _MODULES.values() if m.split(".")[0] not in GROUPS] == []
    assert {m.split(".")[0] for m in _MODULES.values()} == set(GROUPS)


def test_the_framework_imports_no_experiment_module():
    graph = with_parents(import_graph())
    experiments = experiment_modules() | {f"delayed_rl.experiments.{g}" for g in GROUPS}
    framework = {m for m in graph if m.startswith("delayed_rl.experiments.framework")}
    assert len(framework) > 5
    assert [
        f"{m} imports {o}" for m in sorted(framework) for o in sorted(graph[m] & experiments)
    ] == []


#: The old layout's experiment modules, flat in ``experiments/``, and their imports of each other
#: (at module level, inside a function, as ``from package import module``, relative).
OLD_LAYOUT = {
    "delayed_rl.experiments.controllers": (
        "from delayed_rl.experiments import linefollow, plotting\n"
        "from delayed_rl.experiments.linefollow import LAM, line_env\n"
    ),
    "delayed_rl.experiments.future_work": (
        "def shared():\n    from delayed_rl.experiments import anonymous_delay as shared\n"
    ),
    "delayed_rl.experiments.real_robot": "import delayed_rl.experiments.linefollow_deconv\n",
    "delayed_rl.experiments.mmq_gridworld": "from .anonymous_delay import band_plot\n",
    "delayed_rl.experiments.thesis.linefollow": "from ..beyond import anonymous_delay\n",
    "delayed_rl.experiments.roulette": "from delayed_rl.experiments import plotting\n",
}


def test_the_experiment_check_sees_every_form_of_import():
    experiments = {
        "delayed_rl.experiments.anonymous_delay",
        "delayed_rl.experiments.linefollow",
        "delayed_rl.experiments.linefollow_deconv",
        "delayed_rl.experiments.beyond.anonymous_delay",
        *OLD_LAYOUT,
    }
    modules = experiments | {"delayed_rl.experiments", "delayed_rl.experiments.plotting"}
    graph = {
        name: _source_imports(name, False, source, modules) for name, source in OLD_LAYOUT.items()
    }
    assert experiment_imports(graph, experiments) == [
        "delayed_rl.experiments.controllers imports delayed_rl.experiments.linefollow",
        "delayed_rl.experiments.future_work imports delayed_rl.experiments.anonymous_delay",
        "delayed_rl.experiments.mmq_gridworld imports delayed_rl.experiments.anonymous_delay",
        "delayed_rl.experiments.real_robot imports delayed_rl.experiments.linefollow_deconv",
        "delayed_rl.experiments.thesis.linefollow imports "
        "delayed_rl.experiments.beyond.anonymous_delay",
    ]


HEAVY = (
    "pymunk",
    "torch",
    "matplotlib",
    "ray",
    "dask",
    "stable_baselines3",
    "pettingzoo",
    "supersuit",
)


def _modules_after(statement: str) -> set[str]:
    """The modules loaded by ``statement`` in a fresh interpreter."""
    code = f"import sys, json; {statement}; print(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(json.loads(done.stdout))


@pytest.mark.parametrize(
    "package",
    [
        "delayed_rl",
        "delayed_rl.wrappers",
        "delayed_rl.multiagent",
        "delayed_rl.agents",
        "delayed_rl.compiled",
        "delayed_rl.envs",
    ],
)
def test_importing_a_package_loads_no_heavy_dependency(package):
    loaded = {name.split(".")[0] for name in _modules_after(f"import {package}")}
    assert loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))


def test_the_e_puck_loads_pymunk_when_it_is_used():
    assert "pymunk" in _modules_after("import delayed_rl.envs.linefollow")


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycles(graph) == [["a", "b", "c"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_graph_sees_the_package():
    graph = import_graph()
    assert "delayed_rl._validation" in graph["delayed_rl.agents.common.base"]
    assert "delayed_rl.agents.common.save_util" in graph["delayed_rl.agents.common.persistence"]
    assert len(graph) > 30


def test_no_import_cycles_in_the_package():
    assert find_cycles(import_graph()) == []


def test_save_util_imports_no_agent():
    imported = import_graph()["delayed_rl.agents.common.save_util"]
    assert not {name for name in imported if name.startswith("delayed_rl.agents")}


class MyMMQ(MultipleModelQLearning):
    """A user's subclass, defined at module level."""


def test_a_user_subclass_saves_and_loads_as_itself(tmp_path):
    env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=1)
    agent = MyMMQ(env, max_delay_estimate=3, q_init=5.0, seed=1).learn(2_000)
    path = agent.save(tmp_path / "mine")
    for loaded in (
        MyMMQ.load(path),
        MultipleModelQLearning.load(path),
        load_agent(path),
        TabularAgent.load(path),
    ):
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
    from delayed_rl.agents.common import persistence

    class Gone(QLearning):
        pass

    path = Gone("delayed_rl/Roulette-v0", seed=0).save(tmp_path / "gone")

    del persistence.AGENT_CLASSES[persistence.class_key(Gone)]
    with pytest.raises(ValueError, match="unknown agent class .*Gone.*import the module"):
        load_agent(path)


def test_the_removed_names_are_gone():
    """0.x renames leave no alias behind (CHANGELOG.md lists them)."""
    import importlib

    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("delayed_rl.agents.serialization")
    agent = QLearning("delayed_rl/GridWorld-3x3-v0", seed=0).learn(50, record=True)
    assert "done" not in agent.training_log and "episode_end" in agent.training_log
    with pytest.raises(TypeError):
        FixedDelayQLearning("delayed_rl/GridWorld-3x3-v0", delay=3)
    assert not hasattr(FixedDelayQLearning("delayed_rl/GridWorld-3x3-v0", 3), "delay")


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_agent_shows_the_shared_hyperparameters_with_the_one_set_of_defaults(name):
    """Every registered class: ``@shares_hyperparameters`` on its ``__init__`` shows them.

    Each is built from its registry entry's ``example_arguments``, as the code that builds
    every agent does.
    """
    from delayed_rl.wrappers import RewardDelay

    entry = REGISTRY[name]
    cls = agent_class(name)
    grid = gym.make("delayed_rl/GridWorld-3x3-v0")
    env = RewardDelay(grid, 1, record_arrivals=True) if entry.needs_arrivals else grid
    shown = inspect.signature(cls).parameters
    for parameter, default in {**asdict(DEFAULTS), "seed": None, "verbose": 0}.items():
        assert shown[parameter].default == default, parameter
    base = inspect.signature(TabularAgent.__init__).parameters
    assert {parameter: base[parameter].default for parameter in HYPERPARAMETER_NAMES} == {
        parameter: shown[parameter].default for parameter in HYPERPARAMETER_NAMES
    }
    agent = cls(env, gamma=0.5, q_init=2.0, **entry.example_arguments)
    assert agent.gamma == 0.5 and agent.q_init == 2.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'gammma'"):
        cls(env, gammma=0.5, **entry.example_arguments)


def test_module_docstrings_are_docs_not_manuals():
    """A module docstring is at most 60 lines: a file format or a method goes in ``docs/``."""
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
        if doc and doc.count("\n") + 1 > 60:
            long.append((_module_name(path), doc.count("\n") + 1))
    assert long == []


def test_no_measured_timing_is_written_in_the_code():
    """Speed lives in benchmarks/SPEED.md, which the code may link, not in docstrings."""
    import re

    timing = re.compile(
        r"\d\s?(ns|µs)\b( a| per)|\d+\s?-\s?\d+\s?% faster|\d(\.\d+)?-\d+(\.\d+)?[x×] slower"
    )
    found = [
        f"{path.relative_to(PACKAGE)}:{number}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if timing.search(line)
    ]
    assert found == []


def _is_jitted(function: ast.FunctionDef) -> bool:
    """Decorated by numba (``@_jit``, ``@jit``, ``@numba.njit(...)``): a compiled kernel."""
    return any("jit" in ast.unparse(decorator) for decorator in function.decorator_list)


def _long_functions(source: str, limit: int = 80) -> list[tuple[str, int]]:
    tree = ast.parse(source)
    return [
        (node.name, node.end_lineno - node.lineno + 1)
        for node in ast.walk(tree)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        and node.end_lineno - node.lineno + 1 > limit
        and not _is_jitted(node)
    ]


def test_no_function_outside_the_compiled_kernels_is_over_80_lines():
    long = [
        (_module_name(path), name, lines)
        for path in sorted(PACKAGE.rglob("*.py"))
        for name, lines in _long_functions(path.read_text(encoding="utf-8"))
    ]
    assert long == []


def test_the_length_check_counts_a_long_function_and_spares_a_kernel():
    body = "\n".join(f"    x{i} = {i}" for i in range(85))
    assert _long_functions(f"def long():\n{body}\n") == [("long", 86)]
    assert _long_functions(f"@_jit\ndef kernel():\n{body}\n") == []


ALGORITHMS = [agent_class(name) for name in REGISTRY]


@pytest.mark.parametrize("cls", ALGORITHMS, ids=lambda cls: cls.__name__)
def test_algorithms_are_siblings_over_the_one_q_base(cls):
    """Every algorithm subclasses the tabular Q base, and no algorithm subclasses another."""
    from delayed_rl.agents.common.q_agent import QAgent

    assert cls.__mro__[1] is QAgent
    assert not set(cls.__mro__[1:]) & set(ALGORITHMS)


def test_mmq_is_at_most_300_lines():
    source = inspect.getsource(MultipleModelQLearning)
    assert source.count("\n") <= 300


def test_every_algorithm_has_one_public_name():
    """The long class name, and no alias of it in ``delayed_rl.agents`` or ``delayed_rl``."""
    for cls in ALGORITHMS:
        names = [name for name in agents.__all__ if getattr(agents, name) is cls]
        assert names == [cls.__name__]
    for alias in ("MMQ", "DeconvQ"):
        assert not hasattr(agents, alias) and not hasattr(delayed_rl, alias)


def test_no_two_modules_define_a_public_class_of_the_same_name():
    defined: dict[str, list[str]] = {}
    for path in sorted(Path(delayed_rl.__file__).parent.rglob("*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                defined.setdefault(node.name, []).append(path.name)
    assert {name: where for name, where in defined.items() if len(where) > 1} == {}


def test_the_sweeps_import_nothing_from_the_experiments():
    graph = with_parents(import_graph())
    sweep = {m for m in graph if m == "delayed_rl.sweep" or m.startswith("delayed_rl.sweep.")}
    assert len(sweep) >= 4
    found = [
        f"{m} imports {o}"
        for m in sorted(sweep)
        for o in sorted(graph[m])
        if o == "delayed_rl.experiments" or o.startswith("delayed_rl.experiments.")
    ]
    assert found == []

"""The agent registry is the one list of agents: what lists agents derives from it."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import inspect
import sys
from pathlib import Path

import numpy as np
import pytest

from delayed_rl import agents
from delayed_rl.agents import QLearning
from delayed_rl.agents.common.q_agent import QAgent
from delayed_rl.agents.registry import ARRIVAL_AGENTS, CLASS_NAMES, REGISTRY, agent_class
from delayed_rl.cli import TRAIN_AGENTS, build_parser

ROOT = Path(__file__).resolve().parents[2]


def _seeded_runs():
    """``benchmarks/seeded_runs.py`` as a module (it is a script, not a package module)."""
    spec = importlib.util.spec_from_file_location("seeded_runs", ROOT / "benchmarks/seeded_runs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("seeded_runs", module)
    spec.loader.exec_module(module)
    return module


def test_every_entry_is_a_public_agent_class_with_a_description():
    for name, entry in REGISTRY.items():
        cls = agent_class(name)
        assert cls.__name__ == entry.class_name == CLASS_NAMES[name]
        assert cls.__name__ in agents.__all__ and issubclass(cls, QAgent) and entry.description


def test_every_q_agent_of_the_package_is_registered():
    classes = {
        getattr(agents, name)
        for name in agents.__all__
        if isinstance(getattr(agents, name), type) and issubclass(getattr(agents, name), QAgent)
    }
    assert classes == {agent_class(name) for name in REGISTRY}


def test_the_command_line_and_the_sweeps_derive_from_it():
    assert {
        k: e.class_name for k, e in REGISTRY.items() if e.train_options is not None
    } == TRAIN_AGENTS
    assert ARRIVAL_AGENTS == ("oracle",) and REGISTRY["oracle"].needs_arrivals
    train = build_parser()._subparsers._group_actions[0].choices["train"]
    dests = {action.dest for action in train._actions}
    for entry in REGISTRY.values():
        assert set(entry.train_options or ()) <= dests  # every option exists on `train`


def test_every_registered_agent_has_a_seeded_run():
    rows = _seeded_runs().AGENT_RUNS
    assert {class_name for _, class_name, _ in rows} == set(CLASS_NAMES.values())


@pytest.fixture
def defined_classes():
    """Agent classes a test defines: out of the model-file class table after it, pass or fail."""
    from delayed_rl.agents.common import persistence

    made: list[type] = []
    yield made
    for cls in made:
        persistence.AGENT_CLASSES.pop(persistence.class_key(cls), None)


def test_a_new_rule_trains_on_the_python_path_until_it_compiles(defined_classes):
    """A ``QAgent`` subclass with its own rule inherits no compiled rule (none would be its own)."""
    from delayed_rl.compiled import NotCompilable

    class HalfRewardQ(QAgent):  # a rule of its own: Q-learning on half the reward
        def _learn_transition(self, s, a, r, s2, terminated, truncated):
            self._q_learning_update(s, a, 0.5 * r, s2, terminated)

    defined_classes.append(HalfRewardQ)
    env = "delayed_rl/GridWorld-3x3-v0"
    agent = HalfRewardQ(env, seed=0).learn(500)
    assert agent.last_learn_path == "python" and agent.compiled_tables() is None
    with pytest.raises(NotCompilable, match="HalfRewardQ has no compiled learning rule"):
        HalfRewardQ(env, seed=0).learn(10, compiled=True)
    q = QLearning(env, seed=0).learn(500, compiled=False)
    assert not np.array_equal(agent.q_table, q.q_table)  # its own rule ran, not Q-learning's
    assert _seeded_runs().paths(HalfRewardQ) == (False,)
    assert _seeded_runs().paths(QLearning) == (False, True)


def test_the_packages_top_level_agents_are_registered_classes():
    import delayed_rl

    top = [name for name in delayed_rl.__all__ if name != "__version__"]
    by_class = {class_name: key for key, class_name in CLASS_NAMES.items()}
    assert top and set(top) <= set(by_class)
    for name in top:
        assert getattr(delayed_rl, name) is agent_class(by_class[name])


def test_the_options_train_requires_are_options_it_takes():
    for key, entry in REGISTRY.items():
        assert set(entry.train_required) <= set(entry.train_options or ()), key


def test_the_docs_table_of_agents_is_the_registry():
    """The agents page includes :func:`registry_table`: a row per entry, in the registry's order."""
    from delayed_rl.agents.registry import registry_table

    rows = registry_table().splitlines()[2:]
    assert len(rows) == len(REGISTRY)
    for row, (key, entry) in zip(rows, REGISTRY.items(), strict=True):
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        assert cells[:3] == [f"`{key}`", f"`{entry.class_name}`", entry.description], row
        assert (f"`--agent {key}`" in cells[3]) == (key in TRAIN_AGENTS), row
        for option in entry.train_options or ():
            flag = f"`--{option.replace('_', '-')}`"
            required = option in entry.train_required
            assert flag + (" (required)" if required else "") in cells[3], (row, option)
    fixed = "| `fixed` | `FixedDelayQLearning` | Q-learning assuming a constant delay | `--agent fixed`, "
    assert fixed + "`--delay-estimate` (required) |" in rows  # the whole row, as the page shows it
    agents_page = (ROOT / "docs" / "agents.md").read_text(encoding="utf-8")
    assert "```{include} _generated/agent_registry.md" in agents_page


def test_a_rule_over_several_delay_estimates_acts_as_mmq_does(defined_classes):
    """``QAgent`` with several tables acts from the one holding the state's max (MMQ's choice)."""

    class FirstTableQ(QAgent):  # learns in table 0 only; table 1 keeps q_init
        def __init__(self, env, **hyperparameters):
            super().__init__(env, delay_estimates=np.array([0, 2]), **hyperparameters)

        def _learn_transition(self, s, a, r, s2, terminated, truncated):
            self._q_learning_update(s, a, r, s2, terminated)

    defined_classes.append(FirstTableQ)
    agent = FirstTableQ("delayed_rl/GridWorld-3x3-v0", q_init=1.0, seed=0)
    table, uniform = agent._table, (lambda: 0.5)
    table.write(0, 0 * table.row_size + 1 * agent.n_actions + 3, 5.0, 1.0)  # state 0: table 1
    table.write(1, 1 * table.row_size + 0 * agent.n_actions + 2, 7.0, 1.0)  # state 1: table 0
    assert agent._choose(0, 0.0, uniform) == (1, 3)
    assert agent._choose(1, 0.0, uniform) == (0, 2)
    share = agent.learn(3_000).acting_delay_share  # (it raised IndexError here)
    assert agent.last_learn_path == "python" and share[0] > 0 and share[1] > 0


def test_writing_named_fingerprints_keeps_the_others(tmp_path, monkeypatch):
    import json

    seeded = _seeded_runs()
    versions = {name: importlib.metadata.version(name) for name in seeded.PACKAGES}
    hashes = {"a/x/python": "old", "b/x/python": "b"}
    stored = {"versions": versions, "steps": seeded.STEPS, "hashes": hashes}
    monkeypatch.setattr(seeded, "RESULTS", tmp_path / "runs.json")
    seeded.RESULTS.write_text(json.dumps({**stored, "history": ["kept"]}))
    table = {"a/x/python": lambda: "new", "a/x/compiled": lambda: "c", "b/x/python": lambda: "b"}
    monkeypatch.setattr(seeded, "runs", lambda: table)
    monkeypatch.setattr(sys, "argv", ["seeded_runs.py", "--write", "a"])  # an agent: all its runs
    assert seeded.main() == 0
    written = json.loads(seeded.RESULTS.read_text())
    assert written["hashes"] == {"a/x/python": "new", "a/x/compiled": "c", "b/x/python": "b"}
    assert written["history"] == ["kept"]
    monkeypatch.setattr(sys, "argv", ["seeded_runs.py", "--write", "c"])
    with pytest.raises(SystemExit):  # no such run: refused, naming the agents
        seeded.main()
    monkeypatch.setattr(sys, "argv", ["seeded_runs.py", "--write", "a"])
    for other in ({"versions": {"numpy": "0.1"}}, {"steps": seeded.STEPS + 1}):
        seeded.RESULTS.write_text(json.dumps({**stored, **other}))
        with pytest.raises(SystemExit):  # other versions or steps: one set, written whole
            seeded.main()
        assert json.loads(seeded.RESULTS.read_text())["hashes"] == hashes


def test_the_check_reports_a_stored_run_that_no_longer_runs(tmp_path, monkeypatch, capsys):
    import json

    seeded = _seeded_runs()
    versions = {name: importlib.metadata.version(name) for name in seeded.PACKAGES}
    stored = {
        "versions": versions,
        "steps": seeded.STEPS,
        "hashes": {"a/x/python": "h", "a/x/compiled": "c"},
    }
    monkeypatch.setattr(seeded, "RESULTS", tmp_path / "runs.json")
    seeded.RESULTS.write_text(json.dumps(stored))
    monkeypatch.setattr(seeded, "runs", lambda: {"a/x/python": lambda: "h"})  # a path lost
    monkeypatch.setattr(sys, "argv", ["seeded_runs.py", "--check"])
    assert seeded.main() == 1
    assert "missing: a/x/compiled" in capsys.readouterr().out


def test_each_entry_gives_a_value_for_every_argument_its_class_needs():
    """``example_arguments`` builds the class: no argument without a default is left out."""
    variadic = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    for name, entry in REGISTRY.items():
        parameters = inspect.signature(agent_class(name)).parameters
        needed = {
            parameter
            for parameter, spec in parameters.items()
            if parameter != "env"
            and spec.default is inspect.Parameter.empty
            and spec.kind not in variadic
        }
        assert needed <= set(entry.example_arguments) <= set(parameters), name


def test_option_flag_spells_an_argument_and_refuses_what_is_not_one():
    from delayed_rl.agents.registry import option_flag

    assert option_flag("delay_estimate") == "--delay-estimate"
    with pytest.raises(TypeError, match="option must be"):
        option_flag(3)
    with pytest.raises(ValueError, match="option must be .* got 'max delay'"):
        option_flag("max delay")


def test_an_entry_refuses_example_arguments_that_are_not_a_mapping():
    from delayed_rl.agents.registry import AgentEntry

    with pytest.raises(TypeError, match="example_arguments must be a mapping"):
        AgentEntry("delayed_rl.agents.qlearning:QLearning", "Q", example_arguments=[("a", 1)])
    entry = AgentEntry("delayed_rl.agents.qlearning:QLearning", "Q", example_arguments={"a": 1})
    with pytest.raises(TypeError):
        entry.example_arguments["a"] = 2  # read-only

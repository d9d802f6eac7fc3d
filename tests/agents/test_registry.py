"""The agent registry is the one list of agents: what lists agents derives from it."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from delayed_rl import agents
from delayed_rl.agents.common.q_agent import QAgent
from delayed_rl.agents.registry import AGENTS, ARRIVAL_AGENTS, REGISTRY, agent_class
from delayed_rl.cli import AGENTS as TRAIN_AGENTS
from delayed_rl.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]


def _seeded_runs():
    """``benchmarks/seeded_runs.py`` as a module (it is a script, not a package module)."""
    spec = importlib.util.spec_from_file_location("seeded_runs", ROOT / "benchmarks/seeded_runs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("seeded_runs", module)
    spec.loader.exec_module(module)
    return module


def test_every_entry_is_a_public_agent_class_with_a_label():
    for name, entry in REGISTRY.items():
        cls = agent_class(name)
        assert cls.__name__ == entry.class_name == AGENTS[name]
        assert cls.__name__ in agents.__all__ and issubclass(cls, QAgent) and entry.label


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
    rows = _seeded_runs().AGENTS
    assert {class_name for _, class_name, _ in rows} == set(AGENTS.values())


def test_the_packages_top_level_agents_are_registered_classes():
    import delayed_rl

    top = [name for name in delayed_rl.__all__ if name != "__version__"]
    by_class = {class_name: key for key, class_name in AGENTS.items()}
    assert top and set(top) <= set(by_class)
    for name in top:
        assert getattr(delayed_rl, name) is agent_class(by_class[name])


def test_the_options_train_requires_are_options_it_takes():
    for key, entry in REGISTRY.items():
        assert set(entry.train_required) <= set(entry.train_options or ()), key

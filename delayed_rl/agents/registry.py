"""The agents by their short names: the one list of the library's tabular agents.

Everything that lists agents derives from :data:`REGISTRY`: the classes
:mod:`delayed_rl.agents` exports, ``delayed-rl train --agent`` (the agents with
``train_options``), ``delayed-rl list``, sweep files' ``agents[].name``, the sweeps' arrival
recording, the seeded runs and the tests of every agent. Adding an agent is its module and one
entry here, as Gymnasium registers an env by its entry point.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

__all__ = [
    "CLASS_NAMES",
    "ARRIVAL_AGENTS",
    "REGISTRY",
    "AgentEntry",
    "agent_class",
    "option_flag",
    "registry_table",
]


@dataclass(frozen=True)
class AgentEntry:
    """One agent of the registry.

    Attributes:
        entry_point: where its class is defined, ``"module:ClassName"``.
        description: what it is, in words, as ``delayed-rl list`` and ``train --help`` say it
            (``"Multiple Model Q-learning"``).
        needs_arrivals: its env must record which transition emitted each reward
            (``RewardDelay(..., record_arrivals=True)``: the oracle).
        train_options: the constructor arguments ``delayed-rl train`` sets from its options of
            the same name (``max_delay_estimate`` from ``--max-delay-estimate``; ``None``:
            ``train`` does not take this agent).
        train_required: those of ``train_options`` that ``train`` must be given.
        example_arguments: constructor arguments, beyond the env, for a small working instance:
            a value for each argument the class needs (``{"delay_estimate": 2}``). The code
            that builds every agent in turn (the seeded runs, the tests of every agent, the
            model-file corpus) passes them.
    """

    entry_point: str
    description: str
    needs_arrivals: bool = False
    train_options: tuple[str, ...] | None = None
    train_required: tuple[str, ...] = ()
    example_arguments: Mapping[str, Any] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.example_arguments, Mapping):
            raise TypeError(
                "example_arguments must be a mapping of constructor arguments, got "
                f"{self.example_arguments!r}"
            )
        # read-only, as the rest of the entry: the registry is shared by everything that reads it
        object.__setattr__(
            self, "example_arguments", MappingProxyType(dict(self.example_arguments))
        )

    @property
    def class_name(self) -> str:
        """Its class's name (the part of ``entry_point`` after the colon)."""
        return self.entry_point.partition(":")[2]


#: The library's agents by the names the command line and sweep files use.
REGISTRY: dict[str, AgentEntry] = {
    "q": AgentEntry("delayed_rl.agents.qlearning:QLearning", "Q-learning", train_options=()),
    "fixed": AgentEntry(
        "delayed_rl.agents.qlearning:FixedDelayQLearning",
        "Q-learning assuming a constant delay",
        train_options=("delay_estimate",),
        train_required=("delay_estimate",),
        example_arguments={"delay_estimate": 2},
    ),
    "mmq": AgentEntry(
        "delayed_rl.agents.mmq:MultipleModelQLearning",
        "Multiple Model Q-learning, over delays 0..max_delay_estimate",
        train_options=("max_delay_estimate",),
    ),
    "deconv": AgentEntry(
        "delayed_rl.agents.deconvolution:DeconvolutionQLearning",
        "deconvolution Q-learning, the delay learned on 0..max_delay_estimate",
        train_options=("max_delay_estimate",),
    ),
    "oracle": AgentEntry(
        "delayed_rl.agents.oracle:OracleQLearning",
        "Q-learning crediting each reward to its own transition (the upper bound)",
        needs_arrivals=True,
    ),
    "expected-credit": AgentEntry(
        "delayed_rl.agents.expected_credit:ExpectedCreditQLearning",
        "Q-learning crediting each reward over the past by a known delay's pmf",
        example_arguments={"delay": 2},
    ),
}
#: Each agent's class name, by its short name.
CLASS_NAMES = {name: entry.class_name for name, entry in REGISTRY.items()}
#: The agents whose env must record which transition emitted each reward.
ARRIVAL_AGENTS = tuple(name for name, entry in REGISTRY.items() if entry.needs_arrivals)


def agent_class(name: str) -> type:
    """The agent class called ``name`` (a key of :data:`REGISTRY`).

    Raises:
        KeyError: ``name`` is not a key of :data:`REGISTRY`.
    """
    module, _, class_name = REGISTRY[name].entry_point.partition(":")
    return getattr(importlib.import_module(module), class_name)


def option_flag(option: str) -> str:
    """The ``delayed-rl train`` flag that sets constructor argument ``option``.

    >>> option_flag("max_delay_estimate")
    '--max-delay-estimate'

    Raises:
        TypeError: ``option`` is not a string.
        ValueError: ``option`` is not a Python identifier (an argument's name).
    """
    if not isinstance(option, str):
        raise TypeError(f"option must be a constructor argument's name (a str), got {option!r}")
    if not option.isidentifier():
        raise ValueError(f"option must be a constructor argument's name, got {option!r}")
    return "--" + option.replace("_", "-")


def registry_table() -> str:
    """The registry as a Markdown table, as the docs' agents page shows it.

    One row per agent: its short name, its class, what it is, and what ``delayed-rl train``
    takes for it (the options it sets, or that ``train`` does not take it). The library's
    ``pprint_registry``, as Gymnasium's is for envs.

    >>> print(registry_table().splitlines()[2])
    | `q` | `QLearning` | Q-learning | `--agent q` |
    """
    rows = ["| name | class | what it is | `delayed-rl train` |", "|---|---|---|---|"]
    for name, entry in REGISTRY.items():
        if entry.train_options is None:
            train = "not taken (sweeps and Python)"
        else:
            options = [
                f"`{option_flag(option)}`"
                + (" (required)" if option in entry.train_required else "")
                for option in entry.train_options
            ]
            train = ", ".join([f"`--agent {name}`", *options])
        rows.append(f"| `{name}` | `{entry.class_name}` | {entry.description} | {train} |")
    return "\n".join(rows) + "\n"

"""The agents by their short names: the one list of the library's tabular agents.

Everything that lists agents derives from :data:`REGISTRY`: ``delayed-rl train --agent`` (the
agents with ``train_options``), ``delayed-rl list``, sweep files' ``agents[].name``, the sweeps'
arrival recording and the tests of every agent. Adding an agent is its module and one entry
here.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["AGENTS", "ARRIVAL_AGENTS", "REGISTRY", "AgentEntry", "agent_class"]


@dataclass(frozen=True)
class AgentEntry:
    """One agent of the registry.

    Attributes:
        class_name: its class, in :mod:`delayed_rl.agents`.
        label: how tables and figures name it (``"MMQ"``).
        needs_arrivals: its env must record which transition emitted each reward
            (``RewardDelay(..., record_arrivals=True)``: the oracle).
        train_options: the constructor arguments ``delayed-rl train`` sets from its options of
            the same name (``max_delay_estimate`` from ``--max-delay-estimate``; ``None``:
            ``train`` does not take this agent).
    """

    class_name: str
    label: str
    needs_arrivals: bool = False
    train_options: tuple[str, ...] | None = None


#: The library's agents by the names the command line and sweep files use.
REGISTRY: dict[str, AgentEntry] = {
    "q": AgentEntry("QLearning", "Q", train_options=()),
    "fixed": AgentEntry("FixedDelayQLearning", "fixed-delay Q", train_options=("delay_estimate",)),
    "mmq": AgentEntry("MultipleModelQLearning", "MMQ", train_options=("max_delay_estimate",)),
    "deconv": AgentEntry(
        "DeconvolutionQLearning", "DeconvQ", train_options=("max_delay_estimate",)
    ),
    "oracle": AgentEntry("OracleQLearning", "oracle Q", needs_arrivals=True),
    "expected-credit": AgentEntry("ExpectedCreditQLearning", "expected credit"),
}
#: Each agent's class name, by its short name.
AGENTS = {name: entry.class_name for name, entry in REGISTRY.items()}
#: The agents whose env must record which transition emitted each reward.
ARRIVAL_AGENTS = tuple(name for name, entry in REGISTRY.items() if entry.needs_arrivals)


def agent_class(name: str) -> type:
    """The agent class called ``name`` (a key of :data:`REGISTRY`).

    Raises:
        KeyError: ``name`` is not a key of :data:`REGISTRY`.
    """
    return getattr(importlib.import_module("delayed_rl.agents"), AGENTS[name])

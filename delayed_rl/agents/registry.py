"""The agents by their short names: what ``delayed-rl train --agent`` and sweep files take."""

from __future__ import annotations

import importlib

__all__ = ["AGENTS", "ARRIVAL_AGENTS", "agent_class"]

#: The library's agents by the names the command line and sweep files use.
AGENTS = {
    "q": "QLearning",
    "fixed": "FixedDelayQLearning",
    "mmq": "MultipleModelQLearning",
    "deconv": "DeconvolutionQLearning",
    "oracle": "OracleQLearning",
    "expected-credit": "ExpectedCreditQLearning",
}
#: The agents whose env must record which transition emitted each reward.
ARRIVAL_AGENTS = ("oracle",)


def agent_class(name: str) -> type:
    """The agent class called ``name`` (a key of :data:`AGENTS`).

    Raises:
        KeyError: ``name`` is not a key of :data:`AGENTS`.
    """
    return getattr(importlib.import_module("delayed_rl.agents"), AGENTS[name])

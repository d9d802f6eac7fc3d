"""The default hyper-parameters of the tabular agents, stated once."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DEFAULTS", "AgentDefaults"]


@dataclass(frozen=True)
class AgentDefaults:
    """The default hyper-parameters of every tabular agent, stated once (the thesis's values).

    Attributes:
        learning_rate: α = 0.1.
        gamma: γ = 0.9.
        exploration_initial_eps: ε = 0.1 at the start of ``learn()``.
        exploration_final_eps: ε = 0.1 at the end: a constant ε, as in the thesis.
        exploration_fraction: 0.1 (only used when ε moves).
        q_init: 0.0 (set it above the achievable values for optimistic exploration).
    """

    learning_rate: float = 0.1
    gamma: float = 0.9
    exploration_initial_eps: float = 0.1
    exploration_final_eps: float = 0.1
    exploration_fraction: float = 0.1
    q_init: float = 0.0


DEFAULTS = AgentDefaults()
"""The defaults the agents' constructors use."""

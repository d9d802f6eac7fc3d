"""The tabular agents' shared hyper-parameters: their defaults, stated once, and their checks."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

from delayed_rl._validation import check_fraction, check_int, check_probability, check_real
from delayed_rl.agents.schedules import Schedule, as_learning_rate_schedule

__all__ = [
    "DEFAULTS",
    "HYPERPARAMETER_NAMES",
    "AgentDefaults",
    "check_hyperparameters",
    "shares_hyperparameters",
]


@dataclass(frozen=True)
class AgentDefaults:
    """The default hyper-parameters of every tabular agent (the thesis's values).

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

_SHARED = {**asdict(DEFAULTS), "seed": None, "verbose": 0}
HYPERPARAMETER_NAMES = tuple(_SHARED)
"""The constructor arguments every tabular agent shares (and saves)."""

_Init = TypeVar("_Init", bound=Callable[..., None])


def shares_hyperparameters(init: _Init) -> _Init:
    """Mark ``__init__(self, env, ..., **hyperparameters)`` as taking the shared hyper-parameters.

    The constructor passes ``**hyperparameters`` on to
    :class:`~delayed_rl.agents.base.TabularAgent`, so their defaults live in one place
    (:data:`DEFAULTS`); its signature, as ``help()``, ``inspect`` and the documentation show it,
    lists them by name, keyword-only, with those defaults.
    """
    signature = inspect.signature(init)
    own = [p for p in signature.parameters.values() if p.kind is not p.VAR_KEYWORD]
    shared = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
              for name, default in _SHARED.items()]  # fmt: skip
    init.__signature__ = signature.replace(parameters=own + shared)
    return init


def check_hyperparameters(
    learning_rate: float | Schedule,
    gamma: float,
    exploration_initial_eps: float,
    exploration_final_eps: float,
    exploration_fraction: float,
    q_init: float,
    seed: int | None,
    verbose: int,
) -> dict[str, Any]:
    """The shared hyper-parameters, checked, plus the learning rate as a schedule.

    Returns:
        One entry per argument (``learning_rate`` as given), and ``lr_schedule``.

    Raises:
        TypeError: an argument has the wrong type.
        ValueError: an argument is out of range (the message names it and what is allowed).
    """
    return {
        "learning_rate": learning_rate,
        "lr_schedule": as_learning_rate_schedule(learning_rate),
        "gamma": check_probability("gamma", gamma),
        "exploration_initial_eps": check_probability(
            "exploration_initial_eps", exploration_initial_eps
        ),
        "exploration_final_eps": check_probability("exploration_final_eps", exploration_final_eps),
        "exploration_fraction": check_fraction("exploration_fraction", exploration_fraction),
        "q_init": check_real("q_init", q_init),
        "seed": check_int("seed", seed, 0, optional=True),
        "verbose": check_int("verbose", verbose, 0, note=" (0 silent, 1 info)"),
    }

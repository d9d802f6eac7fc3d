"""The tabular agents' shared hyper-parameters: their defaults, stated once, and their checks."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

from delayed_rl._validation import (
    Limit,
    RealLimit,
    check_fraction,
    check_int,
    check_limit,
    check_probability,
    check_real,
)
from delayed_rl.agents.common.schedules import as_learning_rate_schedule

__all__ = [
    "DEFAULTS",
    "HYPERPARAMETER_CHECKS",
    "HYPERPARAMETER_NAMES",
    "MAX_ABS_VALUE",
    "MAX_SEED_VALUE",
    "AgentDefaults",
    "check_seed",
    "check_value",
    "check_hyperparameters",
    "shares_hyperparameters",
    "with_defaults",
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

MAX_ABS_VALUE = RealLimit(2.0**200, "MAX_ABS_VALUE", __name__, "2**200")
"""The largest magnitude of a value the agents are given to learn from (about 1.6e60).

It bounds ``q_init``, every entry of a Q-table, averaged table or reward model a model file
holds, the reward of :meth:`~delayed_rl.agents.common.base.TabularAgent.update` (and an oracle's
arrivals), and DeconvQ's ``ridge``; a value above is refused (``ValueError`` naming it).

Why this bound: no update can then overflow float64 (largest value about ``2**1024``).

- A Q-learning update ``Q ← Q + α (r + γ max Q′ − Q)`` with ``α, γ`` in [0, 1] is a convex
  combination of ``Q`` and ``r + γ max Q′``, so each step raises ``max |Q|`` by at most ``|r|``:
  after ``T`` steps ``|Q| <= (T + 1) · 2**200``, below ``2**1021`` for every ``T < 2**821`` —
  any step count an int64 can hold (``2**63``) — and the TD error, at most three such values,
  stays below ``2**1023``. (With ``γ < 1`` the table even stays within ``2**200 / (1 − γ)``.)
  The reward kernel's and the delay trace's weights, expected credit's lag weights and the
  averaged table's rate are in [0, 1]: the same bound holds.
- DeconvQ's least squares multiply rewards by rewards and by counts: with rewards and mean
  rewards within ``2**200``, a sum over ``2**63`` steps is within ``2**263``, and a product of
  two such values with a count (int32, below ``2**31``), summed over ``2**27`` pairs and
  ``2**11`` lags, within ``2**(263 + 200 + 31 + 27 + 11) = 2**532``.

An env whose own rewards pass it is outside this guarantee (``learn()`` does not check each
reward it receives).
"""
MAX_SEED_VALUE = Limit(2**63 - 1, "MAX_SEED_VALUE", __name__, "2**63 - 1")
"""The largest ``seed`` value (the int64 range, which numpy arrays and the sweeps' tables hold)."""


def check_value(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is a number within ±MAX_ABS_VALUE.

    Raises:
        TypeError: ``value`` is not a real number.
        ValueError: it is NaN, infinite or of magnitude above :data:`MAX_ABS_VALUE`.
    """
    number = check_real(name, value)
    if abs(number) > MAX_ABS_VALUE:
        raise ValueError(f"{name} must be within ±{MAX_ABS_VALUE.text}, got {value!r}")
    return number


def check_seed(name: str, value: Any) -> int | None:
    """Return ``value`` (``None`` or an int in ``[0, MAX_SEED_VALUE]``) after checking it.

    Raises:
        TypeError: ``value`` is neither ``None`` nor an integer.
        ValueError: it is negative or above :data:`MAX_SEED_VALUE`.
    """
    seed = check_int(name, value, 0, optional=True)
    return check_limit(name, seed, MAX_SEED_VALUE)


_SHARED = {**asdict(DEFAULTS), "seed": None, "verbose": 0}
HYPERPARAMETER_NAMES = tuple(_SHARED)
"""The constructor arguments every tabular agent shares (and saves)."""

_Init = TypeVar("_Init", bound=Callable[..., None])


def shares_hyperparameters(init: _Init) -> _Init:
    """Mark ``__init__(self, env, ..., **hyperparameters)`` as taking the shared hyper-parameters.

    The constructor passes ``**hyperparameters`` on to
    :class:`~delayed_rl.agents.common.base.TabularAgent`, whose own constructor takes them the
    same way and fills in the missing ones (:func:`with_defaults`), so their defaults live in
    one place (:data:`DEFAULTS`); its signature, as ``help()``, ``inspect`` and the
    documentation show it, lists them by name, keyword-only, with those defaults.
    """
    signature = inspect.signature(init)
    own = [p for p in signature.parameters.values() if p.kind is not p.VAR_KEYWORD]
    shared = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
              for name, default in _SHARED.items()]  # fmt: skip
    init.__signature__ = signature.replace(parameters=own + shared)
    return init


def with_defaults(owner: str, given: dict[str, Any]) -> dict[str, Any]:
    """``given`` with the default of every shared hyper-parameter it lacks (:data:`DEFAULTS`).

    Args:
        owner: the class whose constructor was called, for the message.
        given: the shared hyper-parameters passed to it, by name.

    Raises:
        TypeError: a name in ``given`` is not a shared hyper-parameter, worded as Python words
            an unexpected keyword argument.
    """
    for name in given:
        if name not in _SHARED:
            raise TypeError(f"{owner}() got an unexpected keyword argument {name!r}")
    return {**_SHARED, **given}


def _check_learning_rate(name: str, value: Any) -> Any:
    """α as given: a number in (0, 1], or a schedule (whose values are checked as it runs)."""
    return value if callable(value) else check_fraction(name, value)


def _check_verbose(name: str, value: Any) -> int:
    return check_int(name, value, 0, note=" (0 silent, 1 info)")


HYPERPARAMETER_CHECKS: dict[str, Callable[[str, Any], Any]] = {
    "learning_rate": _check_learning_rate,
    "gamma": check_probability,
    "exploration_initial_eps": check_probability,
    "exploration_final_eps": check_probability,
    "exploration_fraction": check_fraction,
    "q_init": check_value,
    "seed": check_seed,
    "verbose": _check_verbose,
}
"""The check of each shared hyper-parameter, ``check(name, value) -> value``: what the agents
and ``delayed-rl train``'s options both refuse."""


def check_hyperparameters(**hyperparameters: Any) -> dict[str, Any]:
    """The shared hyper-parameters, each checked by :data:`HYPERPARAMETER_CHECKS`.

    ``q_init`` must lie within ±:data:`MAX_ABS_VALUE` and ``seed`` in ``[0, MAX_SEED_VALUE]``.

    Args:
        **hyperparameters: every name of :data:`HYPERPARAMETER_NAMES`, and no other.

    Returns:
        One entry per argument (``learning_rate`` as given), and ``lr_schedule``.

    Raises:
        TypeError: a name is missing or unknown, or an argument has the wrong type.
        ValueError: an argument is out of range (the message names it and what is allowed).
    """
    missing = [name for name in HYPERPARAMETER_NAMES if name not in hyperparameters]
    unknown = [name for name in hyperparameters if name not in HYPERPARAMETER_NAMES]
    if missing or unknown:
        raise TypeError(
            f"check_hyperparameters takes every shared hyper-parameter and no other: missing "
            f"{missing}, unknown {unknown}"
        )
    checked = {
        name: HYPERPARAMETER_CHECKS[name](name, value) for name, value in hyperparameters.items()
    }
    learning_rate = hyperparameters["learning_rate"]  # kept as given (a number or a schedule)
    return {
        **checked,
        "learning_rate": learning_rate,
        "lr_schedule": as_learning_rate_schedule(learning_rate),
    }

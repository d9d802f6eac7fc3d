"""Per-agent arguments and seeds of the multi-agent wrappers (no PettingZoo needed here).

- :func:`agent_seed`: the seed of agent ``i``'s delay stream for ``reset(seed=s)``;
- :func:`per_agent_delays`: a ``delay`` argument (one distribution, or a mapping from agent name
  to one) as one :class:`~delayed_rl.delays.Delay` per agent;
- :func:`per_agent_actions`: an ``initial_action`` argument likewise;
- :func:`delay_record`: a ``delay`` argument in JSON form, for the wrappers' constructor records.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from delayed_rl._validation import check_int
from delayed_rl.delays import Delay, as_delay, delay_spec

__all__ = ["agent_seed", "delay_record", "per_agent_actions", "per_agent_delays"]

AGENT_STREAM = 0xA9E475
"""The spawn key that separates the agents' seeds from every other stream of a seed."""


def agent_seed(seed: int, index: int) -> int:
    """The seed of agent ``index``'s delays when the wrapper is reset with ``seed``.

    It is the 128-bit integer that ``numpy.random.SeedSequence(seed, spawn_key=(AGENT_STREAM,
    index))`` generates: different for every agent (``index`` is the agent's position in
    ``possible_agents``) and unrelated to the env's own stream for ``seed``. The agent's delay
    generator is then ``delayed_rl.wrappers._delay_draws.delay_rng`` of it, so the agent
    draws exactly the delays of a single-agent wrapper (:class:`~delayed_rl.wrappers.RewardDelay`,
    :class:`~delayed_rl.wrappers.ObservationDelay`, :class:`~delayed_rl.wrappers.ActionDelay`)
    reset with ``seed=agent_seed(seed, index)``.

    Raises:
        TypeError: ``seed`` or ``index`` is not an integer.
        ValueError: ``seed`` or ``index`` is negative.

    Example:
        >>> agent_seed(0, 0) == agent_seed(0, 0) != agent_seed(0, 1)
        True
    """
    seed = check_int("seed", seed, 0)
    index = check_int("index", index, 0)
    words = np.random.SeedSequence(seed, spawn_key=(AGENT_STREAM, index)).generate_state(4)
    return sum(int(word) << (32 * k) for k, word in enumerate(words.tolist()))


def _is_per_agent_delay(delay: Any, agents: Sequence[Any]) -> bool:
    """Whether ``delay`` is a mapping from agent name to distribution (not one description).

    A mapping with a ``"type"`` key is a :meth:`~delayed_rl.delays.Delay.to_dict` description,
    unless an agent is named ``"type"``.
    """
    return isinstance(delay, Mapping) and ("type" not in delay or "type" in agents)


def _entries(name: str, given: Mapping[Any, Any], agents: Sequence[Any]) -> dict[Any, Any]:
    """``given``'s entry for every agent, in ``agents``' order, after checking its keys.

    Raises:
        ValueError: a key is not one of ``agents`` (the message names it), or an agent has no
            entry.
    """
    unknown = [key for key in given if key not in agents]
    if unknown:
        raise ValueError(
            f"{name} names {unknown[0]!r}, which is not an agent of the env: a mapping's keys "
            f"must be agents of possible_agents {list(agents)}"
        )
    missing = [agent for agent in agents if agent not in given]
    if missing:
        raise ValueError(
            f"{name} must give an entry for every agent of possible_agents {list(agents)}, "
            f"got none for {missing}"
        )
    return {agent: given[agent] for agent in agents}


def per_agent_delays(delay: Any, agents: Sequence[Any], name: str = "delay") -> dict[Any, Delay]:
    """Each agent's distribution from a wrapper's ``delay`` argument.

    Args:
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description or a number
            (a Poisson mean), for every agent; or a mapping from each agent of ``agents`` to one
            of those.
        agents: the env's ``possible_agents``.
        name: the argument's name, for the messages (an entry is named ``delay['agent']``).

    Raises:
        TypeError: ``delay`` (or an entry) is none of those (the message names it).
        ValueError: a number is not a valid Poisson mean, a description describes no
            distribution, or a mapping names an unknown agent or leaves one out.
    """
    if _is_per_agent_delay(delay, agents):
        given = _entries(name, delay, agents)
        return {agent: as_delay(given[agent], f"{name}[{agent!r}]") for agent in agents}
    if not isinstance(delay, Delay | numbers.Real | Mapping) or isinstance(delay, bool | np.bool_):
        raise TypeError(
            f"{name} must be a delayed_rl.delays.Delay (Poisson, Constant, Geometric, Uniform, "
            "Empirical), a number read as a Poisson mean, a Delay.to_dict() description, or a "
            f"mapping from agent name to one of these, got {delay!r} ({type(delay).__name__})"
        )
    one = as_delay(delay, name)
    return dict.fromkeys(agents, one)


def delay_record(delay: Any, agents: Sequence[Any]) -> Any:
    """``delay`` in JSON form (:func:`~delayed_rl.delays.delay_spec`, entry by entry for a mapping)."""
    if _is_per_agent_delay(delay, agents):
        return {agent: delay_spec(entry) for agent, entry in delay.items()}
    return delay_spec(delay)


def per_agent_actions(
    initial_action: Any,
    agents: Sequence[Any],
    action_space: Callable[[Any], spaces.Space],
    read: Callable[[Any, spaces.Space, Any, str], Any],
) -> dict[Any, Any]:
    """Each agent's initial action from a wrapper's ``initial_action`` argument.

    A mapping is read as one entry per agent when one of its keys is an agent, or when no agent
    has a ``Dict`` action space (whose actions are mappings themselves); otherwise it is one
    action for every agent. ``None`` (the argument or an entry) stands for the agent's default.

    Args:
        initial_action: the argument.
        agents: the env's ``possible_agents``.
        action_space: the env's ``action_space`` method.
        read: ``read(agent, space, value, name)`` checks ``value`` (``None`` included) and
            returns the agent's initial action (``name`` is ``"initial_action"`` or
            ``"initial_action['agent']"``).

    Raises:
        ValueError: a mapping of entries names an unknown agent or leaves one out; whatever
            ``read`` raises.
    """
    per_agent = isinstance(initial_action, Mapping) and (
        any(key in agents for key in initial_action)
        or not any(isinstance(action_space(agent), spaces.Dict) for agent in agents)
    )
    if per_agent:
        given = _entries("initial_action", initial_action, agents)
        return {
            agent: read(agent, action_space(agent), given[agent], f"initial_action[{agent!r}]")
            for agent in agents
        }
    return {
        agent: read(agent, action_space(agent), initial_action, "initial_action")
        for agent in agents
    }

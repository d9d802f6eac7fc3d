"""Observation delays per agent for PettingZoo's ``ParallelEnv``: :class:`ParallelObservationDelay`."""

from __future__ import annotations

from typing import Any

from pettingzoo import ParallelEnv

from delayed_rl._validation import check_choice
from delayed_rl.delays import Delay
from delayed_rl.multiagent._base import ParallelDelayWrapper
from delayed_rl.wrappers._samples import copy_sample
from delayed_rl.wrappers.observation_delay import (
    ARRIVAL_RULES,
    new_arrival_rule,
    observation_delay_settings,
)

__all__ = ["ParallelObservationDelay"]


class ParallelObservationDelay(ParallelDelayWrapper):
    """Delays every agent's observations independently, with the rule of :class:`~delayed_rl.wrappers.ObservationDelay`.

    Each agent has its own arrival rule (``arrival``), delay stream and observation space (any).
    An agent's first observation, at ``reset()`` or at the step it joins, is shown undelayed.
    Observations are copied where they come in and where they leave. ``reset(seed=s)`` seeds
    agent ``i`` with :func:`~delayed_rl.multiagent.agent_seed` ``(s, i)``: it shows the
    observations of an :class:`~delayed_rl.wrappers.ObservationDelay` reset with that seed.
    ``docs/multiagent.md`` has the rules in full.

    ``info[agent]`` holds ``observation_age`` (the age of the observation shown, 0 for the
    first) and ``arrived_observations`` (the ``(i, o_i)`` received at this step). An entry of
    the observations that names no agent of ``possible_agents`` (PettingZoo allows extra keys,
    such as a shared ``"common"`` one) is passed on undelayed, copied.

    Args:
        env: a ``pettingzoo.ParallelEnv`` with ``possible_agents``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean, for every agent; or a mapping from every agent of
            ``possible_agents`` to one of those.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        arrival: the arrival rule, ``"stale"`` or ``"network"``
            (see :class:`~delayed_rl.wrappers.ObservationDelay`).

    Raises:
        TypeError, ValueError: for an invalid argument, as :class:`~delayed_rl.wrappers.ObservationDelay`
            (the message names it).

    Attributes:
        delays: each agent's distribution.
        histories: how many observations each agent's ``"stale"`` rule keeps.
        rules: each agent's arrival rule.

    Example:
        >>> from pettingzoo.classic.rps.rps import parallel_env  # rock-paper-scissors
        >>> from delayed_rl.delays import Constant
        >>> env = ParallelObservationDelay(parallel_env(), Constant(1))
        >>> _ = env.reset(seed=0)
        >>> obs, _, _, _, infos = env.step({"player_0": 1, "player_1": 0})
        >>> int(obs["player_0"]), infos["player_0"]["observation_age"]  # still o_0 (none)
        (3, 1)
        >>> int(env.step({"player_0": 2, "player_1": 2})[0]["player_0"])  # o_1: rock
        0
    """

    def __init__(
        self,
        env: ParallelEnv,
        delay: Delay | float | dict[Any, Any],
        max_delay: int | None = None,
        arrival: str = "stale",
    ):
        super().__init__(env, delay, max_delay, {"arrival": arrival})
        self.arrival = check_choice("arrival", arrival, ARRIVAL_RULES)
        self.histories: dict[Any, int] = {
            agent: observation_delay_settings(self.delays[agent], max_delay, arrival)[3]
            for agent in self.agent_order
        }
        self.rules = {
            agent: new_arrival_rule(self.arrival, self.histories[agent])
            for agent in self.agent_order
        }
        self._samplers = self.delay_samplers("observation")
        self._live: set[Any] = set()  # the agents whose rule is in an episode

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and every agent's rule; ``seed`` also reseeds every agent's delays.

        Each agent's first observation is returned undelayed (a copy), with
        ``info[agent]["observation_age"] = 0`` and
        ``info[agent]["arrived_observations"] = ((0, o_0),)``.

        Raises:
            TypeError, ValueError: ``seed`` is neither ``None`` nor an integer ``>= 0``.
        """
        obs, infos, seeds = self.reset_env(seed, options)
        self.seed_samplers(self._samplers, seeds)
        for agent in self._live:
            self.rules[agent].reset(None)  # lets the last episode's observations go
        self._live.clear()
        shown = {}
        for agent, first in obs.items():
            if agent in self.agent_index:
                shown[agent] = self._start(agent, first, infos)
            else:  # not an agent's: shown as it is (a copy)
                shown[agent] = copy_sample(first)
        return shown, infos

    def step(self, actions: dict[Any, Any]):
        """Step the env; show each agent an older observation (see the class docstring)."""
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        infos = self.own_infos(infos)
        shown = {}
        for agent, made in obs.items():
            if agent not in self.agent_index:  # not an agent's: shown as it is (a copy)
                shown[agent] = copy_sample(made)
                continue
            if agent not in self._live:  # joins the episode: its o_0
                shown[agent] = self._start(agent, made, infos)
                continue
            age, seen, arrived = self.rules[agent].receive(
                copy_sample(made), self._samplers[agent]()
            )
            info = infos.setdefault(agent, {})
            info["observation_age"] = age
            info["arrived_observations"] = tuple((i, copy_sample(o)) for i, o in arrived)
            shown[agent] = copy_sample(seen)
        for ends in (terminated, truncated):
            for agent, ended in ends.items():
                if ended and agent in self._live:
                    self._live.discard(agent)
                    self.rules[agent].reset(None)  # lets its observations go
        return shown, rewards, terminated, truncated, infos

    def _start(self, agent: Any, first: Any, infos: dict[Any, dict[str, Any]]) -> Any:
        """Start ``agent``'s rule at ``first`` (its ``o_0``); report it and return a copy."""
        first = copy_sample(first)
        self.rules[agent].reset(first)
        self._live.add(agent)
        info = infos.setdefault(agent, {})
        info["observation_age"] = 0
        info["arrived_observations"] = ((0, copy_sample(first)),)
        return copy_sample(first)

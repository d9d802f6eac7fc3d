"""What the three multi-agent wrappers share: the env check, the agents, their delays and seeds."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils import BaseParallelWrapper

from delayed_rl._validation import check_int
from delayed_rl.delays import Delay
from delayed_rl.multiagent._agents import agent_seed, delay_record, per_agent_delays
from delayed_rl.wrappers._delay_draws import DelaySampler, check_max_delay
from delayed_rl.wrappers._spec import record_arguments

__all__ = ["ParallelDelayWrapper", "check_parallel_env"]


def check_parallel_env(env: Any) -> tuple[Any, ...]:
    """Return ``env.possible_agents`` as a tuple after checking that ``env`` can be wrapped.

    Raises:
        TypeError: ``env`` is not a ``pettingzoo.ParallelEnv`` (an AEC env included: the message
            names ``aec_to_parallel``).
        ValueError: ``env`` has no ``possible_agents``, or none.
    """
    if not isinstance(env, ParallelEnv):
        hint = (
            " (an AEC env: wrap pettingzoo.utils.conversions.aec_to_parallel(env), then "
            "parallel_to_aec gives an AEC env back)"
            if isinstance(env, AECEnv)
            else ""
        )
        raise TypeError(
            f"env must be a pettingzoo.ParallelEnv, got {env!r} ({type(env).__name__}){hint}"
        )
    agents = getattr(env, "possible_agents", None)
    if not agents:
        raise ValueError(
            "env must be a pettingzoo.ParallelEnv with a non-empty possible_agents list (each "
            f"agent's delays are its own), got {env!r} with possible_agents={agents!r}"
        )
    return tuple(agents)


class ParallelDelayWrapper(BaseParallelWrapper, gym.utils.RecordConstructorArgs):
    """The base of the multi-agent delay wrappers: a ``BaseParallelWrapper`` with per-agent delays.

    It records the wrapper's arguments as Gymnasium's wrappers do
    (``gym.utils.RecordConstructorArgs``, in ``_saved_kwargs``), in JSON form, reads ``delay``
    and ``max_delay`` as every wrapper does, and gives every agent of ``possible_agents`` its
    position, which seeds its delays (:meth:`agent_seeds`).

    Args:
        env: a ``pettingzoo.ParallelEnv`` with ``possible_agents``.
        delay: one distribution for every agent, or a mapping from agent to distribution
            (:func:`~delayed_rl.multiagent._agents.per_agent_delays`).
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        record: the wrapper's other arguments, in JSON form.

    Raises:
        TypeError, ValueError: as :func:`check_parallel_env`, or for an invalid ``delay`` or
            ``max_delay``.

    Attributes:
        agent_order: ``env.possible_agents``, as a tuple.
        agent_index: each agent's position in it.
        delays: each agent's distribution.
        max_delay: the clip on drawn delays.
    """

    def __init__(
        self,
        env: ParallelEnv,
        delay: Delay | float | dict[Any, Any],
        max_delay: int | None,
        record: dict[str, Any],
    ):
        named = getattr(env, "possible_agents", None) or ()
        agents = check_parallel_env(env)
        # first: the first call records (BaseParallelWrapper's own super().__init__() is another)
        record_arguments(self, delay=delay_record(delay, named), max_delay=max_delay, **record)
        BaseParallelWrapper.__init__(self, env)
        self.agent_order = agents
        self.agent_index = {agent: i for i, agent in enumerate(agents)}
        self.delays = per_agent_delays(delay, self.agent_order)
        self.max_delay = check_max_delay(max_delay)

    def delay_samplers(self, signal: str) -> dict[Any, DelaySampler]:
        """A ``DelaySampler`` (``delayed_rl.wrappers._delay_draws``) per agent, on ``signal``'s stream."""
        return {
            agent: DelaySampler(self.delays[agent], self.max_delay, signal)
            for agent in self.agent_order
        }

    def reset_env(
        self, seed: int | None, options: dict[str, Any] | None
    ) -> tuple[dict[Any, Any], dict[Any, dict[str, Any]], list[int] | None]:
        """Reset the env with ``seed``; return its observations, new ``infos`` and the agents' seeds.

        The seeds (:meth:`agent_seeds`) are checked before the env is reset.

        Raises:
            TypeError, ValueError: ``seed`` is neither ``None`` nor an integer ``>= 0``.
        """
        seeds = self.agent_seeds(seed)
        obs, infos = self.env.reset(seed=seed, options=options)
        return obs, self.own_infos(infos), seeds

    @staticmethod
    def seed_samplers(samplers: dict[Any, DelaySampler], seeds: list[int] | None) -> None:
        """Seed each agent's sampler with its seed of ``seeds`` (in agent order; ``None``: none)."""
        if seeds is not None:
            for sampler, seed in zip(samplers.values(), seeds, strict=True):
                sampler.seed(seed)

    def agent_seeds(self, seed: Any) -> list[int] | None:
        """Each agent's delay seed for ``reset(seed=seed)`` (:func:`agent_seed`); ``None``: none.

        Raises:
            TypeError: ``seed`` is neither ``None`` nor an integer.
            ValueError: ``seed`` is negative.
        """
        if seed is None:
            return None
        seed = check_int("seed", seed, 0)
        return [agent_seed(seed, i) for i in range(len(self.agent_order))]

    def position(self, agent: Any, where: str) -> int:
        """The position of ``agent`` in ``possible_agents``.

        Raises:
            ValueError: ``agent`` is not one of them (``where`` says what named it).
        """
        try:
            return self.agent_index[agent]
        except (KeyError, TypeError):
            raise ValueError(
                f"{where} names agent {agent!r}, which is not one of possible_agents "
                f"{list(self.agent_order)}"
            ) from None

    @staticmethod
    def own_infos(infos: dict[Any, dict[str, Any]]) -> dict[Any, dict[str, Any]]:
        """New ``infos`` (a new dict per agent), so that the wrapper's entries change no env's dict.

        An env may hand out its own dicts, or one dict shared by several agents.
        """
        return {agent: dict(info) for agent, info in infos.items()}

"""What the three multi-agent wrappers share: the env check, the agents' positions and seeds."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils import BaseParallelWrapper

from delayed_rl._validation import check_int
from delayed_rl.multiagent._agents import agent_seed

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
    """The base of the multi-agent delay wrappers: a ``BaseParallelWrapper`` that knows its agents.

    It records the wrapper's arguments as Gymnasium's wrappers do
    (``gym.utils.RecordConstructorArgs``, in ``_saved_kwargs``), in JSON form, and gives every
    agent of ``possible_agents`` its position, which seeds its delays (:meth:`agent_seeds`).

    Args:
        env: a ``pettingzoo.ParallelEnv`` with ``possible_agents``.
        record: the wrapper's arguments, in JSON form.

    Raises:
        TypeError, ValueError: as :func:`check_parallel_env`.

    Attributes:
        agent_order: ``env.possible_agents``, as a tuple.
        agent_index: each agent's position in it.
    """

    def __init__(self, env: ParallelEnv, record: dict[str, Any]):
        agents = check_parallel_env(env)
        # first: the first call records (BaseParallelWrapper's own super().__init__() is another)
        gym.utils.RecordConstructorArgs.__init__(self, **record)
        BaseParallelWrapper.__init__(self, env)
        self.agent_order = agents
        self.agent_index = {agent: i for i, agent in enumerate(agents)}

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

"""Random reward, observation and action delays for PettingZoo's ``ParallelEnv``, per agent.

:class:`ParallelRewardDelay`, :class:`ParallelObservationDelay` and :class:`ParallelActionDelay`
apply their single-agent namesakes' rules to every agent on its own; :func:`sb3_vec_env` hands
them to stable-baselines3, and :class:`CooperativeGridWorldEnv` is a small game to learn on.
PettingZoo is imported when a wrapper is first used (the ``multiagent`` extra).
``docs/multiagent.md`` has the rules.
"""

from __future__ import annotations

from delayed_rl._lazy import lazy_attributes

__all__ = [
    "CooperativeGridWorldEnv",
    "ParallelActionDelay",
    "ParallelObservationDelay",
    "ParallelRewardDelay",
    "agent_seed",
    "sb3_vec_env",
]

_HOMES = {
    "CooperativeGridWorldEnv": "gridworld",
    "ParallelActionDelay": "action_delay",
    "ParallelObservationDelay": "observation_delay",
    "ParallelRewardDelay": "reward_delay",
    "agent_seed": "_agents",
    "sb3_vec_env": "sb3",
}


__getattr__ = lazy_attributes(
    __name__,
    _HOMES,
    ("pettingzoo",),
    "PettingZoo",
    "multiagent",
    '`pip install "delayed-rl[multiagent]"`',
)


def __dir__() -> list[str]:
    return sorted(__all__)

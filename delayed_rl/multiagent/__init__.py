"""Random reward, observation and action delays for PettingZoo's ``ParallelEnv``, per agent.

:class:`ParallelRewardDelay`, :class:`ParallelObservationDelay` and :class:`ParallelActionDelay`
apply their single-agent namesakes' rules to every agent on its own; :func:`sb3_vec_env` hands
them to stable-baselines3, and :class:`CooperativeGridWorldEnv` is a small game to learn on.
PettingZoo is imported when a wrapper is first used (the ``multiagent`` extra).
``docs/multiagent.md`` has the rules.

Example:
    >>> from pettingzoo.classic.rps.rps import parallel_env  # rock-paper-scissors
    >>> from delayed_rl.delays import Constant
    >>> from delayed_rl.multiagent import ParallelRewardDelay
    >>> env = ParallelRewardDelay(parallel_env(), {"player_0": 0, "player_1": Constant(1)})
    >>> _ = env.reset(seed=0)
    >>> rewards = env.step({"player_0": 1, "player_1": 0})[1]  # paper beats rock
    >>> rewards, env.step({"player_0": 0, "player_1": 0})[1]
    ({'player_0': 1.0, 'player_1': 0.0}, {'player_0': 0.0, 'player_1': -1.0})
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

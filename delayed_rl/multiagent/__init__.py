"""Random reward, observation and action delays for PettingZoo's ``ParallelEnv``, per agent.

:class:`ParallelRewardDelay`, :class:`ParallelObservationDelay` and :class:`ParallelActionDelay`
apply their single-agent namesakes' rules (:mod:`delayed_rl.wrappers`) to every agent on its
own: ``delay`` is one distribution for all or a mapping from agent to one, and
``reset(seed=s)`` seeds agent ``i`` with :func:`agent_seed` ``(s, i)``, so that it draws exactly
its namesake's delays. They are ``BaseParallelWrapper`` objects: they stack, pass PettingZoo's
API and seed tests, and :func:`sb3_vec_env` (SuperSuit's conversion, with a ``seed()``) hands
them to stable-baselines3 with one policy for every agent. :class:`CooperativeGridWorldEnv` is
a small two-agent game to learn on. ``docs/multiagent.md`` covers agents that leave or join,
AEC envs (through PettingZoo's conversions; turn-based games are not covered) and the learners.

PettingZoo is imported when a wrapper is first used; install it with the ``multiagent`` extra.

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

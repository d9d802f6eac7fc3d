"""Random reward, observation and action delays for PettingZoo's ``ParallelEnv``, per agent.

Each wrapper applies its single-agent namesake's rule to every agent on its own, as the vector
twins (:class:`~delayed_rl.wrappers.VectorRewardDelay`, ...) do to every sub-env:

- :class:`ParallelRewardDelay`: :class:`~delayed_rl.wrappers.RewardDelay`'s rule (pending
  rewards in :class:`~delayed_rl.wrappers.pending_rewards.PendingRewards`), ``on_episode_end`` applied
  to each agent when it terminates or is truncated, whether or not the others go on;
- :class:`ParallelObservationDelay`: :class:`~delayed_rl.wrappers.ObservationDelay`'s two
  arrival rules (:class:`~delayed_rl.wrappers.observation_delay.StaleArrival`,
  :class:`~delayed_rl.wrappers.observation_delay.NetworkArrival`), one per agent, on each
  agent's own observation space;
- :class:`ParallelActionDelay`: :class:`~delayed_rl.wrappers.ActionDelay`'s rule
  (:class:`~delayed_rl.wrappers.action_delay.ActionLine`), one line per agent; the actions an
  agent still has in transit when it leaves are discarded and reported in its last ``info``.

The package also has a small env to learn on: :class:`CooperativeGridWorldEnv`, the thesis's
grid world walked by two agents who are paid +10 only together (``docs/multiagent.md`` wires
independent tabular learners to it through ``predict`` and ``update``).

``delay`` is one distribution for every agent (a :class:`~delayed_rl.delays.Delay`, its
``to_dict()`` description, or a number read as a Poisson mean) or a mapping from agent name to
one; ``initial_action`` may be per agent too. Each agent draws its delays from its own
generator: ``reset(seed=s)`` seeds agent ``i`` (its position in ``possible_agents``) with
:func:`agent_seed` ``(s, i)``, so that it draws exactly the delays of its single-agent
namesake reset with that seed. The wrappers are ``pettingzoo.utils.BaseParallelWrapper``
objects, so they stack, pass PettingZoo's ``parallel_api_test`` and ``parallel_seed_test``,
and SuperSuit's ``pettingzoo_env_to_vec_env_v1`` and ``concat_vec_envs_v1`` (for
stable-baselines3 with parameter sharing) accept them.

**AEC envs.** An AEC env whose ``metadata["is_parallelizable"]`` is true (the butterfly and
SISL envs) is covered through PettingZoo's conversions: wrap
``pettingzoo.utils.conversions.aec_to_parallel(aec_env)``, then
``parallel_to_aec(wrapper)`` gives an AEC env with the delays (it passes PettingZoo's
``api_test``). Turn-based AEC games (chess, Go, tic-tac-toe: not parallelizable) are not
covered: under ``turn_based_aec_to_parallel`` every agent but the one whose turn it is has its
action ignored, and a delayed ``action_mask`` would name moves that are no longer legal.

PettingZoo is imported when a wrapper is first used (``import delayed_rl.multiagent`` does not
import it); install it with the ``multiagent`` extra, ``pip install "delayed-rl[multiagent]"``.

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

"""Wrappers that delay rewards, observations and actions by random numbers of steps.

- :class:`RewardDelay`, :class:`PoissonRewardDelay`: one env, the library's core;
- :class:`ObservationDelay`: the same idea for observations (the thesis's stale sensor, or
  rlrd's network where every observation travels on its own: ``arrival=``), with its
  ``gymnasium.vector`` twin :class:`VectorObservationDelay`;
- :class:`ActionDelay`: for actions (the env executes an action sent steps earlier), with its
  ``gymnasium.vector`` twin :class:`VectorActionDelay`;
- :class:`DelayAwareObservation`: what the agent can know under those delays (the newest
  observation received, its age, the actions sent since), with its ``gymnasium.vector`` twin
  :class:`VectorDelayAwareObservation`, and :class:`DiscreteDelayAwareObservation`, the same as
  one ``Discrete`` index for tabular agents;
- :func:`wrap_delays`: all three (and the delay-aware view) on one env, in the order
  ``gym.make(id, ...)`` stacks them;
- :class:`DiscreteObservation`: observations of several discrete parts (``Blackjack-v1``'s
  ``Tuple``) as one ``Discrete`` index, for the tabular agents;
- :class:`VectorRewardDelay`: the twin for ``gymnasium.vector`` envs;
- :class:`delayed_rl.wrappers.sb3.VecRewardDelay`: the twin for stable-baselines3 ``VecEnv`` objects
  (imported from its own module so that stable-baselines3 and torch load only when used).
"""

from delayed_rl.wrappers.action_delay import ActionDelay
from delayed_rl.wrappers.delay_aware import DelayAwareObservation, DiscreteDelayAwareObservation
from delayed_rl.wrappers.discrete_observation import DiscreteObservation
from delayed_rl.wrappers.observation_delay import ObservationDelay
from delayed_rl.wrappers.reward_delay import (
    EPISODE_END_MODES,
    PoissonRewardDelay,
    RewardDelay,
    wrap_reward_delay,
)
from delayed_rl.wrappers.stack import wrap_delays
from delayed_rl.wrappers.vector import (
    VectorActionDelay,
    VectorDelayAwareObservation,
    VectorObservationDelay,
    VectorRewardDelay,
)

__all__ = [
    "EPISODE_END_MODES",
    "ActionDelay",
    "DelayAwareObservation",
    "DiscreteDelayAwareObservation",
    "DiscreteObservation",
    "ObservationDelay",
    "PoissonRewardDelay",
    "RewardDelay",
    "VectorActionDelay",
    "VectorDelayAwareObservation",
    "VectorObservationDelay",
    "VectorRewardDelay",
    "wrap_delays",
    "wrap_reward_delay",
]

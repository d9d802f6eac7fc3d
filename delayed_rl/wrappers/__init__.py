"""Wrappers that delay rewards, observations and actions by random numbers of steps.

One wrapper per delayed signal (:class:`RewardDelay`, :class:`ObservationDelay`,
:class:`ActionDelay`) with its ``gymnasium.vector`` twin, :func:`wrap_delays` to stack them as
``gym.make(id, ...)`` does, :class:`DelayAwareObservation` for what the agent can know under
them, and :class:`DiscreteObservation` for tabular agents. The stable-baselines3 twin,
:class:`delayed_rl.wrappers.sb3.VecRewardDelay`, is imported from its own module.
``docs/semantics.md`` states the rules.
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

"""One env wrapped for all three delays, in one documented order.

:func:`wrap_delays` is what ``gym.make(id, action_delay=..., observation_delay=...,
reward_delay=...)`` does for every ``delayed_rl/`` id, and what you call for any other env.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from delayed_rl.delays import as_delay
from delayed_rl.wrappers.action_delay import ActionDelay
from delayed_rl.wrappers.observation_delay import ObservationDelay
from delayed_rl.wrappers.reward_delay import wrap_reward_delay

__all__ = ["wrap_delays"]


def wrap_delays(
    env: gym.Env,
    *,
    action_delay: Any = None,
    observation_delay: Any = None,
    reward_delay: Any = None,
) -> gym.Env:
    """``env`` wrapped for each delay that is not ``None``, innermost first.

    1. ``action_delay``: :class:`~delayed_rl.wrappers.ActionDelay`;
    2. ``observation_delay``: :class:`~delayed_rl.wrappers.ObservationDelay`;
    3. ``reward_delay``: :class:`~delayed_rl.wrappers.PoissonRewardDelay` for a number,
       :class:`~delayed_rl.wrappers.RewardDelay` for a distribution — outermost, so that its
       ``info["undelayed_reward"]`` and its episode-end handling see the whole step.

    Each delay is a number (a Poisson mean), a :class:`~delayed_rl.delays.Delay` or its
    ``to_dict()`` description. The wrappers' other arguments take their defaults; build the
    stack by hand for others (``on_episode_end``, ``max_delay``, ``initial_action``).

    Raises:
        TypeError: a delay is neither a number, a ``Delay`` nor a dict.
        ValueError: a delay is not a valid Poisson mean, or a dict describes no distribution.

    The messages name the argument (``reward_delay``, ``observation_delay``, ``action_delay``).

    Example:
        >>> import gymnasium as gym
        >>> env = wrap_delays(gym.make("CartPole-v1"), action_delay=1, reward_delay=3)
        >>> type(env).__name__, type(env.env).__name__
        ('PoissonRewardDelay', 'ActionDelay')
    """
    if action_delay is not None:
        env = ActionDelay(env, as_delay(action_delay, "action_delay"))
    if observation_delay is not None:
        env = ObservationDelay(env, as_delay(observation_delay, "observation_delay"))
    if reward_delay is not None:
        env = wrap_reward_delay(env, reward_delay)
    return env

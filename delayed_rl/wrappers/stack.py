"""One env wrapped for all three delays (and the delay-aware view), in one documented order.

:func:`wrap_delays` is what ``gym.make(id, action_delay=..., observation_delay=...,
reward_delay=..., ...)`` does for every ``delayed_rl/`` id, and what you call for any other env.
"""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym

from delayed_rl._validation import check_bool, check_choice
from delayed_rl.delays import as_delay
from delayed_rl.wrappers.action_delay import ActionDelay
from delayed_rl.wrappers.delay_aware import DelayAwareObservation
from delayed_rl.wrappers.observation_delay import ARRIVAL_RULES, ObservationDelay
from delayed_rl.wrappers.reward_delay import wrap_reward_delay

__all__ = ["WRAP_DELAYS_KEYWORDS", "wrap_delays"]


def wrap_delays(
    env: gym.Env,
    *,
    action_delay: Any = None,
    observation_delay: Any = None,
    reward_delay: Any = None,
    observation_arrival: str = "stale",
    delay_aware: bool = False,
    action_history: int | None = None,
) -> gym.Env:
    """``env`` wrapped for each delay that is not ``None``, innermost first.

    1. ``action_delay``: :class:`~delayed_rl.wrappers.ActionDelay`;
    2. ``observation_delay``: :class:`~delayed_rl.wrappers.ObservationDelay`, with the arrival
       rule ``observation_arrival`` (``"stale"`` or ``"network"``);
    3. ``delay_aware=True``: :class:`~delayed_rl.wrappers.DelayAwareObservation` (with
       ``action_history``), outside the delays it reads (the view needs the observation delay's
       ``info``) and inside the reward delay;
    4. ``reward_delay``: :class:`~delayed_rl.wrappers.PoissonRewardDelay` for a number,
       :class:`~delayed_rl.wrappers.RewardDelay` for a distribution — outermost, so that its
       ``info["undelayed_reward"]`` and its episode-end handling see the whole step.

    Each delay is a number (a Poisson mean), a :class:`~delayed_rl.delays.Delay` or its
    ``to_dict()`` description. The wrappers' other arguments take their defaults; build the
    stack by hand for others (``on_episode_end``, ``max_delay``, ``initial_action``).
    ``observation_arrival`` applies only with an ``observation_delay``; ``action_history`` only
    with ``delay_aware=True``.

    Raises:
        TypeError: a delay is neither a number, a ``Delay`` nor a dict; ``observation_arrival``
            is not a string, ``delay_aware`` not a bool, ``action_history`` not an integer.
        ValueError: a delay is not a valid Poisson mean, or a dict describes no distribution;
            ``observation_arrival`` is not a rule; ``action_history`` is given without
            ``delay_aware=True``, or :class:`~delayed_rl.wrappers.DelayAwareObservation` refuses
            it (or needs it: an unbounded delay).

    The messages name the argument (``reward_delay``, ``observation_delay``, ``action_delay``,
    ...).

    Example:
        >>> import gymnasium as gym
        >>> env = wrap_delays(gym.make("CartPole-v1"), action_delay=1, reward_delay=3)
        >>> type(env).__name__, type(env.env).__name__
        ('PoissonRewardDelay', 'ActionDelay')
    """
    check_choice("observation_arrival", observation_arrival, ARRIVAL_RULES)
    if not check_bool("delay_aware", delay_aware) and action_history is not None:
        raise ValueError(
            f"action_history is DelayAwareObservation's argument: give it with "
            f"delay_aware=True, got action_history={action_history!r} with delay_aware=False"
        )
    if action_delay is not None:
        env = ActionDelay(env, as_delay(action_delay, "action_delay"))
    if observation_delay is not None:
        delay = as_delay(observation_delay, "observation_delay")
        env = ObservationDelay(env, delay, arrival=observation_arrival)
    if delay_aware:
        env = DelayAwareObservation(env, action_history=action_history)
    if reward_delay is not None:
        env = wrap_reward_delay(env, reward_delay)
    return env


WRAP_DELAYS_KEYWORDS = tuple(inspect.signature(wrap_delays).parameters)[1:]
""":func:`wrap_delays`' keywords: what ``gym.make`` hands it for a ``delayed_rl/`` id."""

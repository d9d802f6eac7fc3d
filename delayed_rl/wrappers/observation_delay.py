"""Observation delay: the agent sees an observation from a random number of steps ago."""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym

from delayed_rl._delay_line import delay_bound
from delayed_rl.delays import MAX_DELAY, Delay, as_delay, delay_spec
from delayed_rl.wrappers._samples import copy_sample
from delayed_rl.wrappers._spec import JsonSpecMixin, json_safe
from delayed_rl.wrappers.reward_delay import DelaySampler, check_max_delay


class ObservationDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Shows, at step ``t``, the observation of step ``t − d_t`` with ``d_t`` drawn from ``delay``.

    Observations are numbered from the reset observation ``o_0``; the observation returned by
    step ``t`` (counted from 0) is ``o_{t+1}`` undelayed and ``o_{max(0, t+1−d_t)}`` here: a delay
    reaching back past the episode's start shows the episode's first observation. The reset
    observation itself is never delayed. This is the thesis's delayed-sensing baseline
    (section 5.2.3: the P-controller fed camera readings λ = 90 steps old on average).

    Rewards, termination and ``info`` are the inner env's, plus ``info["observation_delay"]``, the
    delay actually applied (``d_t`` clipped to the episode's start and to the history kept).

    The wrapper keeps the last ``history`` observations: ``max_delay + 1`` when ``max_delay`` is
    set, otherwise enough for all but a negligible tail of the distribution (mean + 10·√mean + 20
    steps for an unbounded one). A delay reaching further back than that is applied as the oldest
    observation kept, and ``info["observation_delay"]`` says so. Seeded by ``reset(seed=...)`` from
    the same independent delay stream as :class:`~delayed_rl.wrappers.RewardDelay`.

    The same observation can be shown at several steps (a delay reaching back past the episode's
    start, or two delays pointing at one step), so array observations are handed out as copies:
    modifying one changes neither the history nor any other observation returned, as
    ``gymnasium.utils.env_checker.check_env`` requires. (Integer observations need no copy.)
    The history is kept in a ``deque`` that holds only the observations seen, so a long delay
    bound costs no memory until the steps are taken.

    Args:
        env: the env whose observations to delay.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).

    Raises:
        TypeError: ``delay`` is neither a ``Delay`` nor a number, or ``max_delay`` is not an
            integer.
        ValueError: ``delay`` is a number that is not a valid Poisson mean, or ``max_delay`` is
            negative.
    """

    def __init__(self, env: gym.Env, delay: Delay | float, max_delay: int | None = None):
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay_spec(delay), max_delay=json_safe(max_delay)
        )
        gym.Wrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        self._sampler = DelaySampler(self.delay, self.max_delay)
        self.history = min(delay_bound(self.delay, self.max_delay), MAX_DELAY - 1) + 1
        self._observations: deque = deque(maxlen=self.history)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and the history; ``seed`` also reseeds the delay generator.

        The reset observation is returned undelayed (a copy, if it is an array), with
        ``info["observation_delay"] = 0``.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        self._observations.clear()
        self._observations.append(obs)
        info["observation_delay"] = 0
        return copy_sample(obs), info

    def step(self, action):
        """Step the env; return an older observation (see the class docstring) with its reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._observations.append(obs)
        applied = min(self._sampler(), len(self._observations) - 1)
        info["observation_delay"] = applied
        return copy_sample(self._observations[-1 - applied]), reward, terminated, truncated, info

"""Observation delay: the agent sees an observation made a random number of steps ago.

:class:`ObservationDelay` is the wrapper; :class:`VectorObservationDelay` is its
``gymnasium.vector`` twin. Both follow one of two arrival rules, each stated once in its own
class: :class:`StaleArrival` (the thesis's stale sensor) and :class:`NetworkArrival` (every
observation travels on its own, as in rlrd: Bouteiller et al., ICLR 2021).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym

from delayed_rl._delay_line import delay_bound
from delayed_rl._validation import check_choice
from delayed_rl.delays import MAX_DELAY, Delay, as_delay
from delayed_rl.wrappers._delay_draws import DelaySampler, check_max_delay
from delayed_rl.wrappers._in_transit import InTransit
from delayed_rl.wrappers._samples import copy_sample
from delayed_rl.wrappers._spec import JsonSpecMixin, record_arguments

__all__ = [
    "ARRIVAL_RULES",
    "NetworkArrival",
    "ObservationDelay",
    "StaleArrival",
    "new_arrival_rule",
    "observation_delay_settings",
]

ARRIVAL_RULES = ("stale", "network")
"""The values of :class:`ObservationDelay`'s ``arrival`` argument."""

Arrivals = list[tuple[int, Any]]
"""``(index, observation)`` pairs received at one step, in the order of their indices."""


class StaleArrival:
    """The stale sensor: step ``t`` receives one observation, ``o_{t+1−d_t}``.

    Observations are numbered from the reset observation ``o_0``; step ``t`` (counted from 0)
    makes ``o_{t+1}``. The index ``t+1−d_t`` is clipped to the episode's start (``o_0``) and to the
    last ``history`` observations (the oldest of them). An observation no delay points at is never
    received; one that several delays point at is received several times, and the one received
    may be older than one received before.

    Only the observations made so far are kept (a ``deque`` of at most ``history``), so a long
    delay bound costs no memory until the steps are taken. The rule keeps the very objects it is
    given and returns them (:class:`ObservationDelay` hands out copies).

    Args:
        history: how many of the last observations to keep (at least 1).
    """

    def __init__(self, history: int):
        self._observations: deque = deque(maxlen=history)
        self.made = 0

    def reset(self, first: Any) -> None:
        """Start an episode: ``first`` is ``o_0``, received at once."""
        self._observations.clear()
        self._observations.append(first)
        self.made = 0

    def receive(self, observation: Any, delay: int) -> tuple[int, Any, Arrivals]:
        """Make ``observation`` (the next index) with ``delay``; return what this step shows.

        Returns:
            The age of the observation shown (``d_t`` clipped: the steps since it was made), the
            observation shown, and the observations received at this step (the one shown).
        """
        self._observations.append(observation)
        self.made += 1
        age = min(delay, len(self._observations) - 1)
        shown = self._observations[-1 - age]
        return age, shown, [(self.made - age, shown)]


class NetworkArrival:
    """The network: every observation ``o_i`` (``i ≥ 1``) arrives by itself at step index ``i + d_i``.

    Observations are numbered from the reset observation ``o_0``, which arrives at once; step
    ``t`` (counted from 0) makes ``o_{t+1}`` with its own delay ``d_{t+1}``, and receives every
    observation with ``i + d_i = t + 1`` (none, one or several, in the order of ``i``). What it
    shows is the newest observation (largest ``i``) arrived so far: an older observation that
    arrives after a newer one is received but does not replace it.

    Only the observations in transit are kept (a heap by arrival index), with the newest arrived,
    so memory follows what is in flight, not the delay's bound. The rule keeps the very objects it
    is given and returns them (:class:`ObservationDelay` hands out copies).
    """

    def __init__(self):
        self.reset(None)

    def reset(self, first: Any) -> None:
        """Start an episode: ``first`` is ``o_0``, received at once; nothing in transit."""
        self._in_transit = InTransit()
        self.made = 0
        self.newest, self.newest_index = first, 0

    @property
    def in_transit(self) -> int:
        """How many observations made have not arrived yet."""
        return len(self._in_transit)

    def receive(self, observation: Any, delay: int) -> tuple[int, Any, Arrivals]:
        """Make ``observation`` (the next index) with ``delay``; return what this step shows.

        Returns:
            The age of the observation shown (the steps since the newest arrived was made), the
            observation shown, and the observations received at this step, in the order of
            their indices.
        """
        self.made = made = self.made + 1
        if delay == 0 and not self._in_transit:  # the common undelayed case, no heap
            self.newest, self.newest_index = observation, made
            return 0, observation, [(made, observation)]
        self._in_transit.send(made, observation, delay)
        arrived = self._in_transit.arrived(made)
        if arrived and arrived[-1][0] > self.newest_index:
            self.newest_index, self.newest = arrived[-1]
        return made - self.newest_index, self.newest, arrived


def observation_delay_settings(
    delay: Any, max_delay: Any, arrival: Any
) -> tuple[Delay, int | None, str, int]:
    """An observation delay's ``delay``, ``max_delay`` and ``arrival``, checked, and its ``history``.

    ``history`` is how many observations the ``"stale"`` rule keeps: the delay's bound plus 1
    (:func:`~delayed_rl._delay_line.delay_bound`, capped below ``MAX_DELAY``).
    :class:`ObservationDelay` and :class:`VectorObservationDelay` read their arguments here, so
    that both refuse the same values with the same messages.

    Raises:
        TypeError, ValueError: as :class:`ObservationDelay`.
    """
    delay = as_delay(delay)
    max_delay = check_max_delay(max_delay)
    arrival = check_choice("arrival", arrival, ARRIVAL_RULES)
    return delay, max_delay, arrival, min(delay_bound(delay, max_delay), MAX_DELAY - 1) + 1


def new_arrival_rule(arrival: str, history: int) -> StaleArrival | NetworkArrival:
    """A new arrival rule of kind ``arrival`` (one of :data:`ARRIVAL_RULES`), for one env."""
    return StaleArrival(history) if arrival == "stale" else NetworkArrival()


class ObservationDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Shows, at step ``t``, an observation made ``d`` steps earlier, ``d`` drawn from ``delay``.

    Observations are numbered from the reset observation ``o_0``, which is never delayed; step
    ``t`` makes ``o_{t+1}``. The arrival rule (``arrival``) says which one step ``t`` returns:

    - ``"stale"`` (the default; :class:`StaleArrival`), the thesis's stale sensor: step ``t``
      draws ``d_t`` and returns ``o_{max(0, t+1−d_t)}``. Some observations are never seen; one
      can be seen again, or after a newer one.
    - ``"network"`` (:class:`NetworkArrival`), rlrd's rule: every ``o_i`` draws its own delay
      and arrives at step index ``i + d_i``; step ``t`` returns the newest arrived so far.

    Rewards and termination are the inner env's. Array observations are handed out as copies.
    ``reset(seed=...)`` seeds the delays, from a stream of their own. ``docs/semantics.md`` has
    the rules in full: the ages reported, the history kept, the copies.

    ``info`` adds ``observation_age``, the steps since the observation returned was made (0 at
    ``reset()``), and ``arrived_observations``, the ``(i, o_i)`` received at this step, in the
    order of ``i`` (under ``"network"`` possibly none, or several; ``((0, o_0),)`` at
    ``reset()``).

    Args:
        env: the env whose observations to delay.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        arrival: the arrival rule, ``"stale"`` or ``"network"`` (see above).

    Raises:
        TypeError: ``delay`` is neither a ``Delay`` nor a number, ``max_delay`` is not an
            integer, or ``arrival`` is not a string.
        ValueError: ``delay`` is a number that is not a valid Poisson mean, ``max_delay`` is
            negative, or ``arrival`` is not one of :data:`ARRIVAL_RULES`.

    Example:
        >>> from delayed_rl.delays import Constant
        >>> env = ObservationDelay(gym.make("CartPole-v1"), Constant(2), arrival="network")
        >>> _ = env.reset(seed=0)
        >>> [[i for i, _ in env.step(0)[-1]["arrived_observations"]] for _ in range(4)]
        [[], [], [1], [2]]
    """

    def __init__(
        self,
        env: gym.Env,
        delay: Delay | float,
        max_delay: int | None = None,
        arrival: str = "stale",
    ):
        record_arguments(self, delay=delay, max_delay=max_delay, arrival=arrival)
        gym.Wrapper.__init__(self, env)
        self.delay, self.max_delay, self.arrival, self.history = observation_delay_settings(
            delay, max_delay, arrival
        )
        self._sampler = DelaySampler(self.delay, self.max_delay, "observation")
        self._rule = new_arrival_rule(self.arrival, self.history)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and the observations kept; ``seed`` also reseeds the delay generator.

        The reset observation is returned undelayed (a copy, if it is an array), with
        ``info["observation_age"] = 0`` and ``info["arrived_observations"] = ((0, o_0),)``.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        self._rule.reset(obs)
        info["observation_age"] = 0
        info["arrived_observations"] = ((0, copy_sample(obs)),)
        return copy_sample(obs), info

    def step(self, action):
        """Step the env; return an older observation (see the class docstring) with its reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        age, shown, arrived = self._rule.receive(obs, self._sampler())
        info["observation_age"] = age
        info["arrived_observations"] = tuple((i, copy_sample(o)) for i, o in arrived)
        return copy_sample(shown), reward, terminated, truncated, info

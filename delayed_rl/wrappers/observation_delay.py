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
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import iterate

from delayed_rl._delay_line import delay_bound
from delayed_rl._validation import check_choice
from delayed_rl.delays import MAX_DELAY, Delay, as_delay, delay_spec
from delayed_rl.wrappers._in_transit import InTransit
from delayed_rl.wrappers._samples import batch_of_copies, copy_sample
from delayed_rl.wrappers._spec import JsonSpecMixin, json_safe
from delayed_rl.wrappers.reward_delay import DelaySampler, check_max_delay
from delayed_rl.wrappers.vector import autoreset_mode, reset_mask, sub_env_seeds

__all__ = [
    "ARRIVAL_RULES",
    "NetworkArrival",
    "ObservationDelay",
    "StaleArrival",
    "VectorObservationDelay",
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


def _settings(delay: Any, max_delay: Any, arrival: Any) -> tuple[Delay, int | None, str, int]:
    """An observation delay's ``delay``, ``max_delay`` and ``arrival``, checked, and its ``history``.

    ``history`` is how many observations the ``"stale"`` rule keeps (:class:`ObservationDelay`
    says how it is chosen). :class:`ObservationDelay` and :class:`VectorObservationDelay` read
    their arguments here, so that both refuse the same values with the same messages.

    Raises:
        TypeError, ValueError: as :class:`ObservationDelay`.
    """
    delay = as_delay(delay)
    max_delay = check_max_delay(max_delay)
    arrival = check_choice("arrival", arrival, ARRIVAL_RULES)
    return delay, max_delay, arrival, min(delay_bound(delay, max_delay), MAX_DELAY - 1) + 1


def _new_rule(arrival: str, history: int) -> StaleArrival | NetworkArrival:
    """A new arrival rule of kind ``arrival`` (one of :data:`ARRIVAL_RULES`), for one env."""
    return StaleArrival(history) if arrival == "stale" else NetworkArrival()


class ObservationDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Shows, at step ``t``, an observation made ``d`` steps earlier, ``d`` drawn from ``delay``.

    Observations are numbered from the reset observation ``o_0``; step ``t`` (counted from 0)
    makes ``o_{t+1}``, which it would return undelayed. The reset observation itself is never
    delayed. Two arrival rules (``arrival``) say which observation step ``t`` returns:

    - ``"stale"`` (the default; :class:`StaleArrival`): the stale sensor. Step ``t`` draws
      ``d_t`` and returns ``o_{max(0, t+1−d_t)}``: a delay reaching back past the episode's start
      shows the episode's first observation. Some observations are never seen; one can be seen
      again, or after a newer one. This is the thesis's delayed-sensing baseline (section 5.2.3:
      the P-controller fed camera readings λ = 90 steps old on average).
    - ``"network"`` (:class:`NetworkArrival`): rlrd's rule (Bouteiller et al., ICLR 2021). Every
      observation ``o_i`` (``i ≥ 1``) draws its own delay ``d_i`` when it is made and arrives at
      index ``i + d_i``: by step ``t`` if ``i + d_i ≤ t + 1``. Step ``t`` returns the newest
      observation (largest ``i``) arrived so far; an older one that arrives after a newer one
      does not replace it. A constant delay ``k`` gives the same observations under both rules.

    Both rules draw one delay a step from the same stream, so the same seed gives the same delays.

    Rewards, termination and ``info`` are the inner env's, plus:

    - ``info["observation_delay"]``: the age of the observation returned, the steps since it was
      made (``t + 1 − i`` for ``o_i``; under ``"stale"``, ``d_t`` clipped to the episode's start
      and to the history kept), 0 at ``reset()``;
    - ``info["arrived_observations"]``: a tuple of the ``(i, o_i)`` received at this step, in the
      order of ``i``: under ``"stale"`` the one returned; under ``"network"`` every one arriving
      now (possibly none), those older than the one returned included. ``((0, o_0),)`` at
      ``reset()``. Learners that use every observation received, not only the newest, read it.

    Under ``"stale"`` the wrapper keeps the last ``history`` observations: ``max_delay + 1`` when
    ``max_delay`` is set, otherwise enough for all but a negligible tail of the distribution
    (mean + 10·√mean + 20 steps for an unbounded one). A delay reaching further back than that is
    applied as the oldest observation kept, and ``info["observation_delay"]`` says so; the history
    is a ``deque`` holding only the observations made, so a long delay bound costs no memory until
    the steps are taken. Under ``"network"`` the wrapper keeps only the observations in transit
    and the newest arrived, and no delay is clipped but by ``max_delay``. Seeded by
    ``reset(seed=...)`` from the same independent delay stream as
    :class:`~delayed_rl.wrappers.RewardDelay`; observations still in transit when an episode ends
    are discarded by the next ``reset()``.

    The same observation can be handed out at several steps (returned again, or in
    ``arrived_observations``), so array observations are handed out as copies, every time and
    everywhere (:func:`~delayed_rl.wrappers._samples.copy_sample`): modifying one changes neither
    what the wrapper keeps nor any other observation returned or reported, as
    ``gymnasium.utils.env_checker.check_env`` requires. (Integer observations need no copy.)

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
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay_spec(delay), max_delay=json_safe(max_delay), arrival=arrival
        )
        gym.Wrapper.__init__(self, env)
        self.delay, self.max_delay, self.arrival, self.history = _settings(
            delay, max_delay, arrival
        )
        self._sampler = DelaySampler(self.delay, self.max_delay, "observation")
        self._rule = _new_rule(self.arrival, self.history)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and the observations kept; ``seed`` also reseeds the delay generator.

        The reset observation is returned undelayed (a copy, if it is an array), with
        ``info["observation_delay"] = 0`` and ``info["arrived_observations"] = ((0, o_0),)``.
        """
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        self._rule.reset(obs)
        info["observation_delay"] = 0
        info["arrived_observations"] = ((0, copy_sample(obs)),)
        return copy_sample(obs), info

    def step(self, action):
        """Step the env; return an older observation (see the class docstring) with its reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        age, shown, arrived = self._rule.receive(obs, self._sampler())
        info["observation_delay"] = age
        info["arrived_observations"] = tuple((i, copy_sample(o)) for i, o in arrived)
        return copy_sample(shown), reward, terminated, truncated, info


class VectorObservationDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's observations independently, with the rule of :class:`ObservationDelay`.

    Every sub-env has its own arrival rule (:class:`StaleArrival` or :class:`NetworkArrival`, as
    ``arrival`` says) and its own delay stream, seeded as
    :class:`~delayed_rl.wrappers.VectorActionDelay` seeds them: ``reset(seed=s)`` gives sub-env
    ``i`` the seed ``s + i`` (``reset(seed=[s0, s1, ...])`` its entry), so sub-env ``i`` shows
    exactly the observations of an :class:`ObservationDelay` over the same env reset with
    ``seed=s + i``, and reports the same ``info`` entries. A sub-env's rule restarts with its
    episode, and the episode's first observation ``o_0`` is shown undelayed, as at
    :class:`ObservationDelay`'s ``reset()``:

    - ``NEXT_STEP`` (the default autoreset mode): the step after an episode ends is the sub-env's
      reset step; it returns the new episode's ``o_0`` (age 0) and draws no delay;
    - ``SAME_STEP``: the ending step makes the episode's last observation, which goes through the
      rule like any other; the step returns the new episode's ``o_0``, and
      ``info["final_obs"]`` holds, for the sub-envs whose episode ended, the observation the
      delayed sub-env shows at that last step (not the undelayed one the inner env reports
      there: that would leak the state the delay hides). That step's ``observation_delay`` and
      ``arrived_observations`` are in ``info["final_info"]``, and the top-level entries are those
      of the new episode's ``o_0``, which is what a ``SyncVectorEnv`` of
      :class:`ObservationDelay` sub-envs reports;
    - ``DISABLED``: a sub-env restarts when ``reset(options={"reset_mask": ...})`` resets it; the
      sub-envs left alone keep their episodes and show again what they showed last.

    ``info`` holds, with Gymnasium's ``_key`` masks (set for the sub-envs stepped or reset):

    - ``info["observation_delay"]``: an ``int64`` array, each sub-env's age of the observation
      it shows (as :class:`ObservationDelay`'s, 0 for an ``o_0``);
    - ``info["arrived_observations"]``: an object array holding, for each sub-env, the tuple of
      the ``(i, o_i)`` it received at this step (``((0, o_0),)`` for an ``o_0``).

    Observations are batched with ``gymnasium.vector.utils`` (``iterate``, ``concatenate``,
    ``create_empty_array``) and copied as :class:`ObservationDelay` copies them: the rules keep
    copies of the inner env's observations (its batch may be reused), and the batch returned,
    the arrived observations and ``info["final_obs"]`` are new objects built from copies, so
    that modifying any of them changes nothing the wrapper keeps or returns later.

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        arrival: the arrival rule, ``"stale"`` or ``"network"`` (see :class:`ObservationDelay`).

    Raises:
        TypeError, ValueError: as :class:`ObservationDelay`; ``ValueError`` also for an env whose
            ``metadata["autoreset_mode"]`` is not a ``gymnasium.vector.AutoresetMode``.

    Example:
        >>> from delayed_rl.delays import Constant
        >>> envs = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
        >>> envs = VectorObservationDelay(envs, Constant(1), arrival="network")
        >>> _ = envs.reset(seed=0)
        >>> info = envs.step(np.array([0, 1]))[-1]
        >>> info["observation_delay"].tolist(), [len(got) for got in info["arrived_observations"]]
        ([1, 1], [0, 0])
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        max_delay: int | None = None,
        arrival: str = "stale",
    ):
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay_spec(delay), max_delay=json_safe(max_delay), arrival=arrival
        )
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay, self.max_delay, self.arrival, self.history = _settings(
            delay, max_delay, arrival
        )
        self.autoreset_mode = autoreset_mode(env)
        self.rules = [_new_rule(self.arrival, self.history) for _ in range(self.num_envs)]
        self._samplers = [
            DelaySampler(self.delay, self.max_delay, "observation") for _ in range(self.num_envs)
        ]
        self._shown: list[Any] = [None] * self.num_envs  # what each sub-env shows now
        self._resetting = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``, and their rules.

        The reset sub-envs show their ``o_0`` undelayed, with ``info["observation_delay"]`` 0 and
        ``info["arrived_observations"]`` ``((0, o_0),)`` (masked to them); each one's delay
        stream is reseeded with its own seed (see the class docstring).

        Raises:
            TypeError, ValueError: ``seed`` is not ``None``, an integer ``>= 0`` or a list of
                ``num_envs`` of them (or ``None``).
        """
        seeds = sub_env_seeds(seed, self.num_envs)
        envs = reset_mask(options, self.num_envs)
        obs, info = self.env.reset(seed=seed, options=options)
        rows = list(iterate(self.env.observation_space, obs))
        arrived = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(envs).tolist():
            if seeds[i] is not None:
                self._samplers[i].seed(seeds[i])
            arrived[i] = self._start(i, rows[i])
        self._resetting[envs] = False
        delays = np.zeros(self.num_envs, dtype=np.int64)
        self._report(info, delays, arrived, envs)
        return batch_of_copies(self.single_observation_space, self._shown), info

    def step(self, actions):
        """Step every sub-env; each shows an older observation (see the class docstring)."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        rows = list(iterate(self.env.observation_space, obs))
        ended = np.asarray(terminated) | np.asarray(truncated)
        same_step = self.autoreset_mode == AutoresetMode.SAME_STEP
        delays = np.zeros(self.num_envs, dtype=np.int64)
        arrived = np.full(self.num_envs, None, dtype=object)
        final_delays, final_arrived = delays.copy(), arrived.copy()
        final_obs = info["final_obs"].copy() if same_step and ended.any() else None
        for i in range(self.num_envs):
            if self._resetting[i]:  # NEXT_STEP's reset step: the new episode's o_0
                arrived[i] = self._start(i, rows[i])
                continue
            last = same_step and ended[i]  # then rows[i] is the next episode's o_0
            made = info["final_obs"][i] if last else rows[i]
            age, shown, got = self.rules[i].receive(copy_sample(made), self._samplers[i]())
            self._shown[i] = shown
            report = (age, tuple((index, copy_sample(o)) for index, o in got))
            if last:
                final_obs[i] = copy_sample(shown)
                final_delays[i], final_arrived[i] = report
                arrived[i] = self._start(i, rows[i])
            else:
                delays[i], arrived[i] = report
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._resetting = ended & ~self._resetting
        if final_obs is not None:
            info["final_obs"] = final_obs
            final_info = info.setdefault("final_info", {})
            self._report(final_info, final_delays, final_arrived, ended)
            info["_final_info"] = np.asarray(info.get("_final_info", ended)) | ended
        self._report(info, delays, arrived, np.ones(self.num_envs, dtype=bool))
        return (
            batch_of_copies(self.single_observation_space, self._shown),
            rewards,
            terminated,
            truncated,
            info,
        )

    def _start(self, i: int, first: Any) -> tuple[tuple[int, Any]]:
        """Start sub-env ``i``'s episode at ``first`` (``o_0``); return ``((0, o_0),)``, a copy."""
        first = copy_sample(first)  # the inner env's batch may be reused
        self.rules[i].reset(first)
        self._shown[i] = first
        return ((0, copy_sample(first)),)

    @staticmethod
    def _report(
        info: dict[str, Any], delays: np.ndarray, arrived: np.ndarray, mask: np.ndarray
    ) -> None:
        """Store ``observation_delay`` and ``arrived_observations`` in ``info``, masked."""
        for key, values in (("observation_delay", delays), ("arrived_observations", arrived)):
            info[key], info["_" + key] = values, mask.copy()

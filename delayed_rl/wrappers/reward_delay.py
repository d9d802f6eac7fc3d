"""Reward-delay wrappers: every reward arrives its own random number of steps late."""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._delay_line import exact_sum
from delayed_rl._validation import check_bool, check_choice, check_reward
from delayed_rl.delays import Delay, Poisson, as_delay
from delayed_rl.wrappers._delay_draws import DelaySampler, check_max_delay
from delayed_rl.wrappers._spec import JsonSpecMixin, record_arguments

__all__ = [
    "EPISODE_END_MODES",
    "FLUSH_WATCH_EPISODES",
    "FLUSH_WATCH_STEPS",
    "FlushWatch",
    "find_reward_delay",
    "flush_watch",
    "PoissonRewardDelay",
    "RewardDelay",
    "check_episode_end",
    "wrap_reward_delay",
]

#: The values of ``on_episode_end``: what happens to pending rewards when an episode ends.
EPISODE_END_MODES = ("flush", "drop", "carry")


def check_episode_end(on_episode_end: Any) -> str:
    """Return ``on_episode_end`` after checking that it is one of :data:`EPISODE_END_MODES`.

    Raises:
        TypeError: ``on_episode_end`` is not a string.
        ValueError: ``on_episode_end`` is a string but not one of the modes.
    """
    return check_choice("on_episode_end", on_episode_end, EPISODE_END_MODES)


FLUSH_WATCH_EPISODES = 10
"""How many episodes with a nonzero reward the flush-trap watch waits for (:class:`FlushWatch`).

Episodes without any reward do not count: under a random policy most FrozenLake episodes end in
a hole with no reward, and ten of those say nothing about where the env puts its rewards."""

FLUSH_WATCH_STEPS = 100_000
"""The most steps the flush-trap watch lasts, all sub-envs' together (:class:`FlushWatch`).

It bounds what the watch costs when rewarded episodes are rare or never come (an env that never
rewards, a policy that never reaches the goal): from then on the wrapper does nothing for it."""


class FlushWatch:
    """The flush-trap watch of one wrapper: does the env reward only at episodes' final steps?

    One watch serves a whole wrapper (:class:`RewardDelay`, or a vector twin and all its sub-envs
    together, so it warns once, not once per sub-env). The rule:

    - a nonzero reward emitted at a step that ends no episode ends the watch, without a warning
      (the env rewards along the way, which the delay does delay);
    - otherwise the watch counts the episodes that end, and those of them with a nonzero reward
      (necessarily at their final step). Once :data:`FLUSH_WATCH_EPISODES` episodes with a reward
      have ended, or once :data:`FLUSH_WATCH_STEPS` steps have been taken, the watch ends, and it
      warns if any episode had a reward: every reward came at a final step, where ``"flush"``
      delivers it at once.

    The step cap is checked whenever :meth:`see` is called: :class:`RewardDelay` calls it only at
    an episode's end or a reward before it (other steps cost the watch nothing), the vector twins
    at every step (through :meth:`see_envs`).

    Args:
        stacklevel: how many calls lead from the line that calls the wrapper's ``step`` down to
            :meth:`see` (2 for a ``step`` that calls :meth:`see` itself), so that the warning
            names that line.

    Attributes:
        episodes: how many episodes ended so far.
        rewarded: how many of them had a nonzero reward.
    """

    def __init__(self, stacklevel: int):
        self.stacklevel = stacklevel
        self.episodes = self.rewarded = 0

    def see(self, steps: int, early: bool, finals: Iterable[float]) -> bool:
        """Take in what happened since the last call; ``True`` once the watch is over.

        The call that ends the watch warns (a ``UserWarning``) if the env was caught in the trap.

        Args:
            steps: the steps taken so far (since the wrapper's construction, all sub-envs').
            early: whether a nonzero reward was emitted at a step that ended no episode.
            finals: the reward emitted at the final step of each episode that ended.
        """
        if early:
            return True
        for reward in finals:
            self.episodes += 1
            self.rewarded += reward != 0.0
        if self.rewarded < FLUSH_WATCH_EPISODES and steps < FLUSH_WATCH_STEPS:
            return False
        if self.rewarded:
            warnings.warn(
                f"the env emitted every reward of its first {self.episodes} episodes "
                f"({self.rewarded} of them with a reward) at an episode's final step, where "
                "on_episode_end='flush' delivers it at once: the delay had no effect. Use "
                "on_episode_end='carry' to delay such rewards into the next episode",
                stacklevel=self.stacklevel + 1,
            )
        return True

    def see_envs(self, steps: int, rewards: np.ndarray, ended: np.ndarray) -> bool:
        """:meth:`see` for one step of several sub-envs; ``True`` once the watch is over.

        Args:
            steps: the steps taken so far, all sub-envs' together.
            rewards: each sub-env's reward emitted at this step (0 for a sub-env that did not
                step).
            ended: whether each sub-env's episode ended at this step.
        """
        ended = np.asarray(ended, dtype=bool)
        early = bool(np.any((rewards != 0.0) & ~ended))
        return self.see(steps, early, rewards[ended].tolist())


def flush_watch(
    on_episode_end: str, delay: Delay, max_delay: int | None, stacklevel: int
) -> FlushWatch | None:
    """The flush-trap watch of a wrapper with these arguments, or ``None`` if it needs none.

    Only ``"flush"`` has the trap, and only a delay that can be nonzero can be lost to it.

    Args:
        on_episode_end: the wrapper's ``on_episode_end``.
        delay: its delay distribution.
        max_delay: its clip (``None``: none).
        stacklevel: the :class:`FlushWatch`'s.
    """
    if on_episode_end != "flush" or delay.support_max == 0 or max_delay == 0:
        return None
    return FlushWatch(stacklevel)


class RewardDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Delays every reward by its own random number of steps, drawn from ``delay``.

    At step ``t`` of an episode the inner env emits ``r_t``; the wrapper draws ``d_t`` (clipped
    to ``max_delay``) and returns the sum of every ``r_j`` with ``j + d_j = t``: rewards overlap
    and arrive out of order, and a step with nothing due returns ``0.0``. When an episode ends,
    the rewards still pending follow ``on_episode_end``: added to the last reward (``"flush"``,
    so the return is the undelayed return), discarded (``"drop"``) or kept for the next episode
    (``"carry"``). Under ``"flush"`` it warns once if the env rewards only at episodes' ends
    (then the delay has no effect). ``reset(seed=...)`` seeds the delays, from a stream of their
    own. ``docs/semantics.md`` has the rules in full: episode ends and resets, the flush trap's
    watch, the rewards accepted, the checked sums, the cost and the JSON spec.

    ``info`` adds, on every step, ``undelayed_reward`` (``r_t``), ``drawn_reward_delay``
    (``d_t``) and ``pending_reward`` (emitted, not yet delivered); at an episode's end
    ``flushed_reward`` or ``dropped_reward``; with ``record_arrivals=True``,
    ``reward_arrivals``, the ``(emission_step, value)`` pairs delivered now.

    Args:
        env: the env whose rewards to delay; its rewards must be real scalars.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"``, ``"drop"`` or ``"carry"`` (see above).
        record_arrivals: add ``info["reward_arrivals"]`` on every step.

    Raises:
        TypeError, ValueError: at construction, for an invalid argument (the message names it).
        TypeError: at a step where the inner env returns a reward that is not a real scalar.
        ValueError: at a step where the inner env returns a NaN or infinite reward, or where
            the rewards due at one step or all those pending sum beyond float64's range.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.wrappers import RewardDelay
        >>> from delayed_rl.delays import Constant
        >>> env = RewardDelay(gym.make("CliffWalking-v1"), Constant(2))
        >>> _ = env.reset(seed=0)
        >>> [env.step(0)[1] for _ in range(3)]
        [0.0, 0.0, -1.0]
    """

    def __init__(
        self,
        env: gym.Env,
        delay: Delay | float,
        max_delay: int | None = None,
        on_episode_end: str = "flush",
        record_arrivals: bool = False,
    ):
        record_arguments(
            self,
            delay=delay,
            max_delay=max_delay,
            on_episode_end=on_episode_end,
            record_arrivals=record_arrivals,
        )
        gym.Wrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        self.on_episode_end = check_episode_end(on_episode_end)
        # None once the watch is over (called as step -> _watch_see -> FlushWatch.see)
        self._watch = flush_watch(self.on_episode_end, self.delay, self.max_delay, stacklevel=3)
        self._watched_elsewhere = 0  # steps the compiled path showed the watch
        self.record_arrivals = check_bool("record_arrivals", record_arrivals)
        self._sampler = DelaySampler(self.delay, self.max_delay)
        self._delays = self._sampler.block  # the sampler refills this very list
        self._due: dict[int, float] = {}  # clock step -> sum of the rewards due then
        self._arrivals: dict[int, list[tuple[int, float]]] = {}
        self._clock = 0  # steps since construction: the keys of _due are on this clock
        self._episode_start = 0  # the clock at this episode's first step
        self._pending = 0.0
        self._episode_ended = True  # from an episode's end (or construction) to the next reset

    @property
    def pending_reward(self) -> float:
        """The sum of rewards emitted but not yet delivered."""
        return self._pending

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env; ``seed`` also reseeds the delay generator.

        A reset in the middle of an episode discards the pending rewards (except under
        ``"carry"``), reports them as ``info["dropped_reward"]`` and warns if they were not zero.
        ``info["pending_reward"]`` is what is still pending (nonzero only under ``"carry"``).
        """
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        if not self._episode_ended and self.on_episode_end != "carry":
            lost = self._clear_pending()
            info["dropped_reward"] = lost
            self._arrivals.clear()
            if lost != 0.0:
                warnings.warn(
                    f"reset() in the middle of an episode discarded {lost} of pending reward "
                    f"(on_episode_end={self.on_episode_end!r}); end episodes inside the "
                    "RewardDelay wrapper to have them flushed",
                    stacklevel=2,
                )
        self._episode_start = self._clock
        self._episode_ended = False
        info["pending_reward"] = self._pending
        return obs, info

    def step(self, action):
        """Step the env; return the rewards due now (see the class docstring)."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        if type(reward) is not float:
            reward = self._checked_reward(reward)
        try:
            delay = self._delays.pop()
        except IndexError:  # once every block of delays
            delay = self._sampler.refill().pop()
        clock = self._clock
        self._clock = clock + 1
        due = self._due
        before = self._pending  # (with ``previous`` and ``popped``: what a refusal puts back)
        previous = popped = None
        if reward:  # a zero reward changes no sum (and is finite): nothing to schedule
            if reward - reward:  # inf or NaN (x - x is 0 for every finite float)
                self._refuse(reward, delay)
            if self._watch is not None and not (terminated or truncated):
                self._watch_see(True, ())  # a reward before an episode's end: no flush trap
            when = clock + delay
            previous = due.get(when)
            slot = (previous or 0.0) + reward
            pending = before + reward
            if slot - slot or pending - pending:  # NaN (true) once a sum passed float64's range
                try:
                    pending = self._checked_pending(when, slot)
                except ValueError:
                    self._undo_step(delay, before)
                    raise
            due[when] = slot
            self._pending = pending
        if clock in due:
            delivered = popped = due.pop(clock)
            pending = self._pending - delivered if due else 0.0  # exact 0 once all is in
            if pending - pending:  # a float sum passed float64's range: the exact one
                try:
                    pending = exact_sum(due.values())
                except ValueError:  # what stays pending is beyond float64: the step did not happen
                    self._take_back(delay, reward, previous, popped, before)
                    raise
            self._pending = pending
        else:
            delivered = 0.0
        if terminated or truncated:
            try:
                delivered = self._settle_episode_end(delivered, info)
            except ValueError:  # the flush passed float64's range: the step did not happen
                self._take_back(delay, reward, previous, popped, before)
                raise
            if self._watch is not None:
                self._watch_see(False, (reward,))
        info["undelayed_reward"] = reward
        info["drawn_reward_delay"] = delay
        info["pending_reward"] = self._pending
        if self.record_arrivals:
            info["reward_arrivals"] = self._arrivals_now(
                clock, delay, reward, terminated or truncated
            )
        return obs, delivered, terminated, truncated, info

    def _watch_see(self, early: bool, finals: tuple[float, ...]) -> None:
        """Show this step to the flush-trap watch (:meth:`FlushWatch.see`); end it once over."""
        if self._watch.see(self._clock + self._watched_elsewhere, early, finals):
            self._watch = None

    def watch_steps_taken_elsewhere(
        self, rewards: np.ndarray, episode_ends: np.ndarray, stacklevel: int
    ) -> None:
        """Show the flush-trap watch steps of this stack that did not go through :meth:`step`.

        The compiled training path (:mod:`delayed_rl.compiled`) steps the env's tables or robot
        itself, not this wrapper; it passes each chunk's emitted rewards and episode ends here,
        so an agent trained either way is warned alike. The steps count towards
        :data:`FLUSH_WATCH_STEPS` after those taken through :meth:`step`.

        Args:
            rewards: the reward emitted at each step, in order.
            episode_ends: whether each step ended an episode.
            stacklevel: how many calls lead from the line to name in a warning to this one.
        """
        if self._watch is None:
            return
        base = self._clock + self._watched_elsewhere
        self._watched_elsewhere += len(rewards)
        watch, level = self._watch, self._watch.stacklevel
        watch.stacklevel = stacklevel
        try:
            for i in np.flatnonzero((rewards != 0.0) | episode_ends).tolist():
                ended = bool(episode_ends[i])
                finals = (float(rewards[i]),) if ended else ()
                if watch.see(base + i + 1, not ended, finals):
                    self._watch = None
                    return
            if watch.see(self._clock + self._watched_elsewhere, False, ()):  # the step cap
                self._watch = None
        finally:
            watch.stacklevel = level

    def _settle_episode_end(self, delivered: float, info: dict[str, Any]) -> float:
        """The episode ended at this step: settle what is pending (``on_episode_end``).

        Returns:
            What the step delivers: ``delivered`` plus, under ``"flush"``, the rest pending
            (``info["flushed_reward"]``); ``"drop"`` reports it as ``info["dropped_reward"]``.

        Raises:
            ValueError: the flushed sum is beyond float64's range.
        """
        if self.on_episode_end == "flush":
            flushed = exact_sum(self._due.values())
            total = delivered + flushed
            if total - total:  # NaN: the sum passed float64's range
                raise ValueError(
                    "the rewards delivered at the episode's last step (due then, plus the "
                    "flushed rest) sum to more than float64 can hold; rescale the env's rewards"
                )
            self._empty()
            info["flushed_reward"] = flushed
            delivered = total
        elif self.on_episode_end == "drop":
            info["dropped_reward"] = self._clear_pending()
        self._episode_ended = True
        return delivered

    def _refuse(self, reward: float, delay: int) -> None:
        """Undo the step begun for a non-finite ``reward`` (its delay, the clock), then refuse it.

        Raises:
            ValueError: always (see :meth:`_checked_reward`).
        """
        self._undo_step(delay, self._pending)
        self._checked_reward(reward)

    def _take_back(
        self,
        delay: int,
        reward: float,
        previous: float | None,
        popped: float | None,
        pending: float,
    ) -> None:
        """Take back a step refused after it scheduled ``reward`` and delivered ``popped``.

        ``previous`` is what was due when ``reward`` is (``None``: nothing), ``pending`` the
        pending sum before the step.
        """
        clock = self._clock - 1
        if popped is not None:
            self._due[clock] = popped
        if reward:
            if previous is None:
                self._due.pop(clock + delay)
            else:
                self._due[clock + delay] = previous
        self._undo_step(delay, pending)

    def _undo_step(self, delay: int, pending: float) -> None:
        """Take back a step begun but refused: its delay, the clock, the pending sum."""
        self._delays.append(delay)
        self._clock -= 1
        self._pending = pending

    def _checked_reward(self, reward: Any) -> float:
        """``reward`` as a Python float, checked (:func:`~delayed_rl._validation.check_reward`).

        Numpy-typed rewards (e.g. float32) are thereby summed in double precision.

        Raises:
            TypeError: ``reward`` is not a real scalar (``None``, a bool, a complex number, a
                list, an array of one or more dimensions...).
            ValueError: ``reward`` is NaN, infinite or an integer beyond float64's range.
        """
        try:
            reward = check_reward("reward", reward)
        except (TypeError, ValueError) as error:
            raise type(error)(
                f"{error}; the inner env returned it at episode step "
                f"{self._clock - self._episode_start}, and RewardDelay refuses to delay it"
            ) from None
        if not math.isfinite(reward):
            raise ValueError(
                f"the inner env returned a non-finite reward ({reward!r}) at episode step "
                f"{self._clock - self._episode_start}; RewardDelay refuses to delay it"
            )
        return reward

    def _checked_pending(self, when: int, slot: float) -> float:
        """The exact pending sum once ``slot`` is due at ``when``, after a float sum overflowed.

        Raises:
            ValueError: the rewards due at ``when`` (``slot`` overflowed), or all those pending,
                sum to more than float64 can hold.
        """
        if slot - slot:  # NaN: this slot's sum passed float64's range
            raise ValueError(
                f"the rewards due at episode step {when - self._episode_start} sum to more than "
                "float64 can hold; rescale the env's rewards"
            )
        others = (value for key, value in self._due.items() if key != when)
        return exact_sum([*others, slot])

    def _arrivals_now(
        self, clock: int, delay: int, reward: float, episode_ended: bool
    ) -> list[tuple[int, float]]:
        """Book-keep the oracle view: who emitted what, and what is delivered at ``clock``."""
        book = self._arrivals
        book.setdefault(clock + delay, []).append((clock, reward))
        start = self._episode_start
        arrivals = [(emitted - start, r) for emitted, r in book.pop(clock, [])]
        if episode_ended and self.on_episode_end == "flush":
            arrivals += [(t - start, r) for due in sorted(book) for t, r in book[due]]
        if episode_ended and self.on_episode_end != "carry":
            book.clear()
        return arrivals

    def _clear_pending(self) -> float:
        """Empty the pending rewards and return their exact sum (rounded once).

        Raises:
            ValueError: the sum is beyond float64's range.
        """
        total = exact_sum(self._due.values())
        self._empty()
        return total

    def _empty(self) -> None:
        """Empty the pending rewards (their sum already taken, or not wanted)."""
        self._due.clear()
        self._pending = 0.0


class PoissonRewardDelay(RewardDelay):
    """:class:`RewardDelay` with Poisson(λ) delays, the thesis's variably-delayed MDP.

    Args:
        env: the env whose rewards to delay.
        lam: the mean delay λ ≥ 0 (any finite real; need not be an integer).
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"`` (default), ``"drop"`` or ``"carry"``.
        record_arrivals: add ``info["reward_arrivals"]`` on every step.

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.wrappers import PoissonRewardDelay
        >>> env = PoissonRewardDelay(gym.make("Taxi-v4"), lam=5)
    """

    def __init__(
        self,
        env: gym.Env,
        lam: float,
        max_delay: int | None = None,
        on_episode_end: str = "flush",
        record_arrivals: bool = False,
    ):
        options = dict(
            max_delay=max_delay, on_episode_end=on_episode_end, record_arrivals=record_arrivals
        )
        record_arguments(self, lam=lam, **options)
        super().__init__(env, Poisson(lam), **options)
        self.lam = self.delay.lam


def wrap_reward_delay(env: gym.Env, reward_delay: Delay | float | Mapping[str, Any]) -> RewardDelay:
    """Wrap ``env`` for ``gym.make(id, reward_delay=...)``: a number means Poisson(λ).

    Args:
        env: the env to wrap.
        reward_delay: a :class:`~delayed_rl.delays.Delay` or its
            :meth:`~delayed_rl.delays.Delay.to_dict` description (gives a :class:`RewardDelay`),
            or a number λ (gives a :class:`PoissonRewardDelay`, whose ``lam`` is recorded as a
            Python number).

    Raises:
        TypeError: ``reward_delay`` is neither a number, a ``Delay`` nor a dict.
        ValueError: ``reward_delay`` is a number that is not a valid λ (negative, NaN, infinite),
            or a dict that describes no distribution. The messages name ``reward_delay``.
    """
    delay = as_delay(reward_delay, "reward_delay")
    if isinstance(reward_delay, numbers.Real):
        return PoissonRewardDelay(env, lam=reward_delay)
    return RewardDelay(env, delay)


def find_reward_delay(env: gym.Env) -> Any:
    """The outermost :class:`RewardDelay` in ``env``'s wrapper stack, or ``None``.

    The stack is walked from ``env`` down its ``.env`` chain (Gymnasium wrappers).
    """
    layer = env
    while isinstance(layer, gym.Env):
        if isinstance(layer, RewardDelay):
            return layer
        layer = getattr(layer, "env", None)
    return None

"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.RewardDelay`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers._delay_draws import check_max_delay
from delayed_rl.wrappers._spec import record_arguments
from delayed_rl.wrappers.pending_rewards import PendingRewards
from delayed_rl.wrappers.reward_delay import check_episode_end, flush_watch
from delayed_rl.wrappers.vector._sub_envs import (
    autoreset_mode,
    checked_rewards,
    reset_inner,
)


def _with_mask(info: dict[str, Any], key: str, values: np.ndarray, mask: np.ndarray) -> None:
    """Store ``values`` under ``key`` with Gymnasium's ``_key`` mask convention."""
    info[key] = values
    info["_" + key] = mask


class VectorRewardDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's rewards independently, with the semantics of :class:`~delayed_rl.wrappers.RewardDelay`.

    Every sub-env has its own pending rewards, clock and delay stream; ``on_episode_end``
    applies to a sub-env when its episode ends, under each autoreset mode of
    ``gymnasium.vector`` (under ``NEXT_STEP`` the reset step emits and delivers nothing).
    ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (``reset(seed=[s0, s1, ...])`` with its
    entry), so that it draws exactly the delays of a :class:`~delayed_rl.wrappers.RewardDelay`
    reset with that seed. The flush-trap warning watches all sub-envs together, and comes at
    most once. ``docs/semantics.md`` (vector envs) has the rules in full: the autoreset modes,
    seeding, the rewards accepted and the memory used.

    ``info`` holds arrays with Gymnasium's ``_key`` masks: ``undelayed_reward``,
    ``drawn_reward_delay`` and ``pending_reward`` on every step; ``flushed_reward`` or
    ``dropped_reward`` for the sub-envs whose episode ended at this step.

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"`` (default), ``"drop"`` or ``"carry"``.

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.RewardDelay`, at construction or
            at a step (one real scalar reward per sub-env); ``ValueError`` also for an env whose
            ``metadata["autoreset_mode"]`` is not a ``gymnasium.vector.AutoresetMode``.

    Example:
        >>> import gymnasium as gym
        >>> import numpy as np
        >>> import delayed_rl
        >>> from delayed_rl.delays import Constant
        >>> envs = gym.make_vec("delayed_rl/GridWorld-3x3-v0", num_envs=2, vectorization_mode="sync")
        >>> envs = VectorRewardDelay(envs, Constant(2))  # every reward arrives 2 steps late
        >>> _ = envs.reset(seed=0)
        >>> for _ in range(3):
        ...     _, rewards, _, _, info = envs.step(np.array([1, 1]))
        ...     print(rewards, info["undelayed_reward"], info["drawn_reward_delay"])
        [0. 0.] [-1. -1.] [2 2]
        [0. 0.] [-1. -1.] [2 2]
        [-1. -1.] [-1. -1.] [2 2]
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        max_delay: int | None = None,
        on_episode_end: str = "flush",
    ):
        record_arguments(self, delay=delay, max_delay=max_delay, on_episode_end=on_episode_end)
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        self.on_episode_end = check_episode_end(on_episode_end)
        self.autoreset_mode = autoreset_mode(env)
        self.pending_rewards = PendingRewards(self.num_envs, self.delay, self.max_delay)
        # (called as step -> FlushWatch.see_envs -> see)
        self._watch = flush_watch(self.on_episode_end, self.delay, self.max_delay, stacklevel=3)
        self._resetting = np.zeros(self.num_envs, dtype=bool)
        # per sub-env: from its episode's end (or construction) to its next reset
        self._episode_ended = np.ones(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``; ``seed`` reseeds the delays.

        Each reset sub-env's delay stream is reseeded with its own seed (see the class
        docstring: an int ``s`` gives sub-env ``i`` the seed ``s + i``). A reset sub-env whose
        episode had not ended loses its pending rewards (except under ``"carry"``), reported as
        ``info["dropped_reward"]``.

        Raises:
            TypeError, ValueError: ``seed`` is not ``None``, an integer ``>= 0`` or a list of
                ``num_envs`` of them (or ``None``).
        """
        seeds, envs, obs, info = reset_inner(self.env, seed, options)
        self.pending_rewards.seed(
            [s if reset else None for s, reset in zip(seeds, envs, strict=True)]
        )
        cut_short = envs & ~self._episode_ended
        if self.on_episode_end != "carry" and cut_short.any():
            _with_mask(info, "dropped_reward", self.pending_rewards.clear(cut_short), cut_short)
        self._episode_ended[envs] = False
        self._resetting[envs] = False
        return obs, info

    def step(self, actions):
        """Step every sub-env; return the rewards due now (see the class docstring)."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        rewards = checked_rewards(rewards, self.num_envs, type(self).__name__)
        active = ~self._resetting
        ended = (np.asarray(terminated) | np.asarray(truncated)) & active
        delivered, delays, settled = self.pending_rewards.step(
            rewards, active, ended, self.on_episode_end
        )
        if settled is not None:
            key = "flushed_reward" if self.on_episode_end == "flush" else "dropped_reward"
            _with_mask(info, key, settled, ended)
        emitted = np.where(active, rewards, 0.0)
        if self._watch is not None and self._watch.see_envs(
            int(self.pending_rewards.clock.sum()), emitted, ended
        ):
            self._watch = None
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._episode_ended = ended.copy()  # until the reset step starts a new episode
            self._resetting = ended.copy()
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            self._episode_ended[:] = False
        else:
            self._episode_ended |= ended
        _with_mask(info, "undelayed_reward", emitted, active)
        _with_mask(info, "drawn_reward_delay", delays, active)
        _with_mask(
            info, "pending_reward", self.pending_rewards.pending, np.ones(self.num_envs, bool)
        )
        return obs, delivered, terminated, truncated, info

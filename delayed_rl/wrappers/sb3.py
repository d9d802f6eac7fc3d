"""The stable-baselines3 ``VecEnvWrapper`` twin of :class:`~delayed_rl.wrappers.RewardDelay`.

This module imports stable-baselines3 (and so torch) when it is imported; nothing else in
``delayed_rl.wrappers`` does. Install the ``sb3`` extra to use it.
"""

from __future__ import annotations

import warnings

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from delayed_rl._validation import check_int
from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers._delay_draws import check_max_delay
from delayed_rl.wrappers.pending_rewards import PendingRewards
from delayed_rl.wrappers.reward_delay import check_episode_end, flush_watch
from delayed_rl.wrappers.vector._sub_envs import checked_rewards


class VecRewardDelay(VecEnvWrapper):
    """Delays each sub-env's rewards independently, with the semantics of :class:`~delayed_rl.wrappers.RewardDelay`.

    SB3 vector envs reset a sub-env in the step that ends its episode (``dones[i]`` true, the
    observation already the next episode's): the pending rewards follow ``on_episode_end`` at
    that step. A ``reset()`` after the first discards them (except under ``"carry"``), warning
    when they are not zero. ``seed=s``, or ``venv.seed(s)`` then ``reset()``, gives sub-env
    ``i`` the delays of a :class:`~delayed_rl.wrappers.RewardDelay` reset with ``seed=s + i``.
    Rewards come back in the inner ``VecEnv``'s floating dtype (at least float32).
    ``docs/semantics.md`` (stable-baselines3) has the rules in full.

    Each ``infos[i]`` gets ``undelayed_reward``, ``drawn_reward_delay``, ``pending_reward``, and
    at an episode end ``flushed_reward`` or ``dropped_reward``; ``reset_infos[i]`` gets
    ``pending_reward``, and ``dropped_reward`` at a ``reset()`` after the first (not under
    ``"carry"``).

    Args:
        venv: the SB3 ``VecEnv`` to wrap.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"`` (default), ``"drop"`` or ``"carry"``.
        seed: seed of the delay generators, an integer ``>= 0`` (``None``: fresh entropy).

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.RewardDelay`, at construction (a
            ``seed`` that is not an integer ``>= 0`` included) or at a step (one real scalar
            reward per sub-env).

    Example:
        >>> import gymnasium as gym
        >>> import numpy as np
        >>> import delayed_rl
        >>> from stable_baselines3.common.vec_env import DummyVecEnv
        >>> from delayed_rl.delays import Constant
        >>> grids = DummyVecEnv([lambda: gym.make("delayed_rl/GridWorld-3x3-v0")] * 2)
        >>> venv = VecRewardDelay(grids, Constant(2), seed=0)
        >>> _ = venv.reset()
        >>> for _ in range(3):
        ...     _, rewards, _, infos = venv.step(np.array([1, 1]))
        ...     print(rewards, [info["undelayed_reward"] for info in infos])
        [0. 0.] [-1.0, -1.0]
        [0. 0.] [-1.0, -1.0]
        [-1. -1.] [-1.0, -1.0]
    """

    def __init__(
        self,
        venv: VecEnv,
        delay: Delay | float,
        max_delay: int | None = None,
        on_episode_end: str = "flush",
        seed: int | None = None,
    ):
        super().__init__(venv)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        self.on_episode_end = check_episode_end(on_episode_end)
        self.pending_rewards = PendingRewards(self.num_envs, self.delay, self.max_delay)
        # (called as VecEnv.step -> step_wait -> FlushWatch.see_envs -> see)
        self._watch = flush_watch(self.on_episode_end, self.delay, self.max_delay, stacklevel=4)
        seed = check_int("seed", seed, 0, optional=True)
        if seed is not None:
            self.pending_rewards.seed(self._seeds_from(seed))
        self._pending_seeds: list[int] | None = None
        self._started = False  # True from the first reset: the sub-envs are in episodes
        self._all = np.ones(self.num_envs, dtype=bool)

    def _seeds_from(self, seed: int) -> list[int]:
        """Each sub-env's delay seed for ``seed``: ``seed + i``, as ``VecEnv.seed`` does."""
        return [seed + i for i in range(self.num_envs)]

    def seed(self, seed: int | None = None):
        """Seed the envs and, at the next reset (as SB3 does), sub-env ``i``'s delays with ``seed + i``.

        Raises:
            TypeError: ``seed`` is neither ``None`` nor an integer.
            ValueError: ``seed`` is negative.
        """
        seed = check_int("seed", seed, 0, optional=True)
        if seed is not None:
            self._pending_seeds = self._seeds_from(seed)
        return self.venv.seed(seed)

    def reset(self):
        """Reset the envs; a seed set by :meth:`seed` reseeds the delays too.

        Pending rewards are discarded, except under ``"carry"``; ``reset_infos`` reports them as
        ``dropped_reward`` (see the class docstring), with a warning if they are not zero.
        """
        obs = self.venv.reset()
        if self._pending_seeds is not None:
            self.pending_rewards.seed(self._pending_seeds)
            self._pending_seeds = None
        infos = [dict(info) for info in self.venv.reset_infos]
        if self.on_episode_end != "carry":
            dropped = self.pending_rewards.clear(self._all)
            if self._started:
                for info, lost in zip(infos, dropped, strict=True):
                    info["dropped_reward"] = float(lost)
                lost_envs = np.flatnonzero(dropped != 0.0).tolist()
                if lost_envs:
                    warnings.warn(
                        f"reset() in the middle of the episodes discarded "
                        f"{dropped[lost_envs].tolist()} of pending reward in sub-envs {lost_envs} "
                        f"(on_episode_end={self.on_episode_end!r}, reported in "
                        "reset_infos[i]['dropped_reward']); let episodes end in the sub-envs to "
                        "have them flushed",
                        stacklevel=2,
                    )
        for info, pending in zip(infos, self.pending_rewards.pending, strict=True):
            info["pending_reward"] = float(pending)
        self.reset_infos = infos
        self._started = True
        return obs

    def step_wait(self):
        """Finish the step; return the rewards due now (see the class docstring)."""
        obs, raw, dones, infos = self.venv.step_wait()
        rewards = checked_rewards(raw, self.num_envs, type(self).__name__)
        ended = np.asarray(dones, dtype=bool)
        delivered, delays, amounts = self.pending_rewards.step(
            rewards, self._all, ended, self.on_episode_end
        )
        if self._watch is not None and self._watch.see_envs(
            int(self.pending_rewards.clock.sum()), rewards, ended
        ):
            self._watch = None
        pending = self.pending_rewards.pending
        key = "flushed_reward" if self.on_episode_end == "flush" else "dropped_reward"
        for i, info in enumerate(infos):
            info["undelayed_reward"] = float(rewards[i])
            info["drawn_reward_delay"] = int(delays[i])
            info["pending_reward"] = float(pending[i])
            if amounts is not None and ended[i]:
                info[key] = float(amounts[i])
        for i in np.flatnonzero(ended).tolist():  # the autoreset's info, as the inner VecEnv's
            self.reset_infos[i] = {**self.venv.reset_infos[i], "pending_reward": float(pending[i])}
        kind = raw.dtype if isinstance(raw, np.ndarray) and raw.dtype.kind == "f" else np.float32
        return obs, delivered.astype(np.promote_types(kind, np.float32)), dones, infos

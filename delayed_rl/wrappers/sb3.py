"""The stable-baselines3 ``VecEnvWrapper`` twin of :class:`~delayed_rl.wrappers.RewardDelay`.

This module imports stable-baselines3 (and so torch) when it is imported; nothing else in
``delayed_rl.wrappers`` does. Install the ``sb3`` extra to use it.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from delayed_rl._validation import check_int
from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers.buffers import RewardBuffers
from delayed_rl.wrappers.reward_delay import check_episode_end, check_max_delay


class VecRewardDelay(VecEnvWrapper):
    """Delays each sub-env's rewards independently, with the semantics of :class:`RewardDelay`.

    SB3 vector envs reset a sub-env in the step that ends its episode (``dones[i]`` is True and the
    returned observation is already the next episode's); pending rewards follow ``on_episode_end``
    at that step. Each ``infos[i]`` gets ``undelayed_reward``, ``reward_delay``,
    ``pending_reward``, and at an episode end ``flushed_reward`` or ``dropped_reward``.

    Delays come from the wrapper's own generator: seed it with ``seed`` here or ``venv.seed(s)``
    followed by ``reset()`` (both reseed the delays as well as the envs).

    Args:
        venv: the SB3 ``VecEnv`` to wrap.
        delay: a :class:`~delayed_rl.delays.Delay`, or a number read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"`` (default), ``"drop"`` or ``"carry"``.
        seed: seed of the delay generator, an integer ``>= 0`` (``None``: fresh entropy).

    Raises:
        TypeError: ``delay`` is neither a ``Delay`` nor a number, ``max_delay`` or ``seed`` is
            not an integer, or ``on_episode_end`` is not a string.
        ValueError: ``delay`` is a number that is not a valid Poisson mean, ``max_delay`` or
            ``seed`` is negative, or ``on_episode_end`` is not one of the modes.
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
        self.buffers = RewardBuffers(self.num_envs, self.delay, self.max_delay)
        self.buffers.seed(check_int("seed", seed, 0, optional=True))
        self._pending_seed: int | None = None
        self._all = np.ones(self.num_envs, dtype=bool)

    def seed(self, seed: int | None = None):
        """Seed the envs (at the next reset, as SB3 does) and the delay generator."""
        self._pending_seed = seed
        return self.venv.seed(seed)

    def reset(self):
        """Reset the envs; a seed set by :meth:`seed` reseeds the delays too.

        Pending rewards are discarded, except under ``"carry"``.
        """
        obs = self.venv.reset()
        if self._pending_seed is not None:
            self.buffers.seed(self._pending_seed)
            self._pending_seed = None
        if self.on_episode_end != "carry":
            self.buffers.clear(self._all)
        return obs

    def step_wait(self):
        """Finish the step; return the rewards due now, as ``float32`` (see the class docstring)."""
        obs, rewards, dones, infos = self.venv.step_wait()
        delivered, delays = self.buffers.push(rewards, self._all)
        ended = np.asarray(dones, dtype=bool)
        amounts = None
        if ended.any() and self.on_episode_end != "carry":
            amounts = self.buffers.clear(ended)
            if self.on_episode_end == "flush":
                delivered = delivered + amounts
        pending = self.buffers.pending
        key = "flushed_reward" if self.on_episode_end == "flush" else "dropped_reward"
        for i, info in enumerate(infos):
            info["undelayed_reward"] = float(rewards[i])
            info["reward_delay"] = int(delays[i])
            info["pending_reward"] = float(pending[i])
            if amounts is not None and ended[i]:
                info[key] = float(amounts[i])
        return obs, delivered.astype(np.float32), dones, infos

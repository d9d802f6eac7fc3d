"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.RewardDelay`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers.buffers import RewardBuffers
from delayed_rl.wrappers.reward_delay import check_episode_end, check_max_delay


def _with_mask(info: dict[str, Any], key: str, values: np.ndarray, mask: np.ndarray) -> None:
    """Store ``values`` under ``key`` with Gymnasium's ``_key`` mask convention."""
    info[key] = values
    info["_" + key] = mask


class VectorRewardDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's rewards independently, with the semantics of :class:`RewardDelay`.

    Every sub-env has its own buffer and clock; ``on_episode_end`` applies per sub-env when its
    episode ends. All three autoreset modes of ``gymnasium.vector`` are supported:

    - ``NEXT_STEP`` (the default): the step after an episode ends is the sub-env's reset step; it
      is not a step of any episode, so it emits and delivers nothing (reward 0, delay 0) and the
      sub-env's clock does not advance;
    - ``SAME_STEP``: the ending step is both the last step of one episode and the reset; the
      pending rewards follow ``on_episode_end`` at that step;
    - ``DISABLED``: sub-envs are reset by ``reset(options={"reset_mask": mask})``; a masked sub-env
      whose episode had not ended loses its pending rewards under ``"flush"``/``"drop"`` (reported
      as ``info["dropped_reward"]``), as in :class:`RewardDelay`.

    ``info`` holds arrays (with Gymnasium's ``_key`` masks): ``undelayed_reward``, ``reward_delay``,
    ``pending_reward`` on every step; ``flushed_reward`` or ``dropped_reward`` for the sub-envs
    whose episode ended at this step.

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, or a number read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"`` (default), ``"drop"`` or ``"carry"``.

    Raises:
        TypeError: ``delay`` is neither a ``Delay`` nor a number, ``max_delay`` is not an integer
            or ``on_episode_end`` is not a string.
        ValueError: ``delay`` is a number that is not a valid Poisson mean, ``max_delay`` is
            negative, ``on_episode_end`` is not one of the modes, or the env's
            ``metadata["autoreset_mode"]`` is not a ``gymnasium.vector.AutoresetMode``.
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        max_delay: int | None = None,
        on_episode_end: str = "flush",
    ):
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay, max_delay=max_delay, on_episode_end=on_episode_end
        )
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        self.on_episode_end = check_episode_end(on_episode_end)
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if isinstance(mode, str):
            mode = AutoresetMode(mode)
        if mode not in tuple(AutoresetMode):
            raise ValueError(
                f"unsupported autoreset_mode {mode!r}; supported: {list(AutoresetMode)}"
            )
        self.autoreset_mode = mode
        self.buffers = RewardBuffers(self.num_envs, self.delay, self.max_delay)
        self._resetting = np.zeros(self.num_envs, dtype=bool)
        # per sub-env: from its episode's end (or construction) to its next reset
        self._episode_ended = np.ones(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``; ``seed`` reseeds the delays.

        The delay generator is seeded with ``seed`` (its first entry if it is a list). A reset
        sub-env whose episode had not ended loses its pending rewards (except under
        ``"carry"``), reported as ``info["dropped_reward"]``.
        """
        envs = np.ones(self.num_envs, dtype=bool)
        if options and "reset_mask" in options:  # read first: SyncVectorEnv.reset pops it
            envs = np.array(options["reset_mask"], dtype=bool)
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self.buffers.seed(seed if isinstance(seed, int) else int(seed[0]))
        cut_short = envs & ~self._episode_ended
        if self.on_episode_end != "carry" and cut_short.any():
            _with_mask(info, "dropped_reward", self.buffers.clear(cut_short), cut_short)
        self._episode_ended[envs] = False
        self._resetting[envs] = False
        return obs, info

    def step(self, actions):
        """Step every sub-env; return the rewards due now (see the class docstring)."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        active = ~self._resetting
        delivered, delays = self.buffers.push(rewards, active)
        ended = (np.asarray(terminated) | np.asarray(truncated)) & active
        if ended.any():
            if self.on_episode_end == "flush":
                flushed = self.buffers.clear(ended)
                delivered = delivered + flushed
                _with_mask(info, "flushed_reward", flushed, ended)
            elif self.on_episode_end == "drop":
                _with_mask(info, "dropped_reward", self.buffers.clear(ended), ended)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._episode_ended = ended.copy()  # until the reset step starts a new episode
            self._resetting = ended.copy()
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            self._episode_ended[:] = False
        else:
            self._episode_ended |= ended
        _with_mask(info, "undelayed_reward", np.where(active, rewards, 0.0), active)
        _with_mask(info, "reward_delay", delays, active)
        _with_mask(info, "pending_reward", self.buffers.pending, np.ones(self.num_envs, bool))
        return obs, delivered, terminated, truncated, info

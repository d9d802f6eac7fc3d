"""Per-env pending-reward buffers shared by the vector twins of :class:`RewardDelay`."""

from __future__ import annotations

import math

import numpy as np

from delayed_rl.delays import Delay
from delayed_rl.wrappers.reward_delay import _BLOCK, delay_rng


def _ring_size(n: int) -> int:
    """The smallest power of two ``>= n`` (so slots are found with a bit mask)."""
    return 1 << max(0, int(n - 1).bit_length())


class RewardBuffers:
    """``num_envs`` independent reward-delay buffers, advanced together with numpy.

    Each env has its own clock (it advances only on the steps that env really takes) and its own
    ring buffer of pending rewards; delays are drawn in blocks of shape ``(1024, num_envs)``.

    Args:
        num_envs: how many envs.
        delay: the delay distribution.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
    """

    def __init__(self, num_envs: int, delay: Delay, max_delay: int | None):
        self.num_envs = num_envs
        self.delay = delay
        self.max_delay = max_delay
        bound = delay.support_max if max_delay is None else max_delay
        if bound is None:
            bound = int(delay.mean + 6.0 * math.sqrt(delay.mean) + 8.0)
        self.buffer = np.zeros((num_envs, _ring_size(bound + 1)))
        self.clock = np.zeros(num_envs, dtype=np.int64)
        self.rows = np.arange(num_envs)
        self.seed(None)

    def seed(self, seed: int | None) -> None:
        """Restart the delay stream from ``seed``."""
        self.rng = delay_rng(seed)
        self._block = np.zeros((0, self.num_envs), dtype=np.int64)
        self._next = 0

    @property
    def pending(self) -> np.ndarray:
        """Each env's sum of rewards emitted but not yet delivered."""
        return self.buffer.sum(axis=1)

    def _draw(self) -> np.ndarray:
        if self._next == len(self._block):
            block = self.delay.sample(self.rng, (_BLOCK, self.num_envs))
            if self.max_delay is not None:
                block = np.minimum(block, self.max_delay)
            self._block, self._next = block, 0
        delays = self._block[self._next]
        self._next += 1
        return delays

    def push(self, rewards: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Schedule this step's ``rewards`` and return ``(delivered, delays)``.

        Envs with ``active`` False (an autoreset step) emit nothing, deliver nothing and keep their
        clocks; their delay is reported as 0.
        """
        rewards = np.asarray(rewards, dtype=np.float64)
        if not np.all(np.isfinite(rewards)):
            bad = np.flatnonzero(~np.isfinite(rewards)).tolist()
            raise ValueError(
                f"sub-envs {bad} returned non-finite rewards {rewards[bad].tolist()}; "
                "the reward-delay buffer refuses to store them"
            )
        delays = np.where(active, self._draw(), 0)
        if delays.max(initial=0) >= self.buffer.shape[1]:
            self._grow(int(delays.max()))
        mask = self.buffer.shape[1] - 1
        rows = self.rows[active]
        self.buffer[rows, (self.clock[active] + delays[active]) & mask] += rewards[active]
        slots = self.clock & mask
        delivered = np.where(active, self.buffer[self.rows, slots], 0.0)
        self.buffer[rows, slots[active]] = 0.0
        self.clock += active
        return delivered, delays

    def clear(self, envs: np.ndarray) -> np.ndarray:
        """Empty the buffers of the envs selected by the boolean mask ``envs``; return their sums."""
        amounts = np.where(envs, self.pending, 0.0)
        self.buffer[envs] = 0.0
        return amounts

    def _grow(self, delay: int) -> None:
        old = self.buffer
        old_size, size = old.shape[1], _ring_size(delay + 1)
        new = np.zeros((self.num_envs, size))
        offsets = np.arange(old_size)
        for env in range(self.num_envs):
            when = self.clock[env] + offsets
            new[env, when & (size - 1)] = old[env, when & (old_size - 1)]
        self.buffer = new

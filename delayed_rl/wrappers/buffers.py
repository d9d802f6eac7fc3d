"""Per-env pending-reward buffers shared by the vector twins of :class:`RewardDelay`."""

from __future__ import annotations

import math

import numpy as np

from delayed_rl._delay_line import delay_bound, draw_delays, regrow_ring, ring_size
from delayed_rl.delays import Delay
from delayed_rl.wrappers.reward_delay import _BLOCK, delay_rng


class RewardBuffers:
    """``num_envs`` independent reward-delay buffers, advanced together with numpy.

    Each env has its own clock (it advances only on the steps that env really takes) and its own
    ring buffer of pending rewards; delays are drawn in blocks of shape ``(1024, num_envs)``. The
    rings start long enough for all but a negligible tail of the delays and grow (keeping what is
    pending in place) when a longer delay comes.

    Args:
        num_envs: how many envs.
        delay: the delay distribution.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
    """

    def __init__(self, num_envs: int, delay: Delay, max_delay: int | None):
        self.num_envs = num_envs
        self.delay = delay
        self.max_delay = max_delay
        if max_delay is None and delay.support_max is None:
            # Not delay_bound's longer reach: the rings' length is part of a seeded run's result.
            # ``pending`` sums whole rings and numpy's pairwise sum groups the entries by slot, so
            # another length can change the last bits of the pending, flushed and dropped sums.
            bound = int(delay.mean + 6.0 * math.sqrt(delay.mean) + 8.0)
        else:
            bound = delay_bound(delay, max_delay)
        self.buffer = np.zeros((num_envs, ring_size(bound + 1)))
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
        """This step's delays, one per env (the next row of the current block)."""
        if self._next == len(self._block):
            self._block = draw_delays(self.delay, self.rng, (_BLOCK, self.num_envs), self.max_delay)
            self._next = 0
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
        """Lengthen the rings to hold ``delay``, every pending reward kept at its due step."""
        self.buffer = regrow_ring(self.buffer, self.clock, ring_size(delay + 1))

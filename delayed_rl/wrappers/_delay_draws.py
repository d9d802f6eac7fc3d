"""The delays every delay wrapper draws: one seeded stream per signal, drawn a block at a time.

:func:`delay_rng` gives each delayed signal (reward, observation, action) its own stream for a
seed (:data:`DELAY_STREAMS`); :class:`DelaySampler` hands its delays out one at a time from
blocks drawn in one generator call, clipped to ``max_delay`` (:func:`check_max_delay`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl._delay_line import draw_delays
from delayed_rl._validation import check_int
from delayed_rl.delays import MAX_DELAY, Delay

__all__ = ["BLOCK", "DELAY_STREAMS", "DelaySampler", "check_max_delay", "delay_rng"]

BLOCK = 1024  # delays drawn per call to the generator
DELAY_STREAMS = {"reward": 0x5DE1A7, "observation": 0x0B5DE1, "action": 0xAC7DE1}
"""The spawn key of each delayed signal's stream: apart from the env's own generator and from
each other, so that a stack reset with one seed draws its reward, observation and action delays
independently."""


def delay_rng(seed: int | None, signal: str = "reward") -> np.random.Generator:
    """The generator of ``signal``'s delays for ``seed``.

    Independent of the env's ``np_random`` for that seed and of the other signals' streams
    (:data:`DELAY_STREAMS`).

    Raises:
        TypeError: ``seed`` is neither ``None`` nor an integer.
        ValueError: ``seed`` is negative.
    """
    seed = check_int("seed", seed, 0, optional=True)
    key = DELAY_STREAMS[signal]
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(key,)))


def check_max_delay(max_delay: Any) -> int | None:
    """Return ``max_delay`` (``None`` or an integer in ``[0, MAX_DELAY]``) as an ``int`` or ``None``.

    Raises:
        TypeError: ``max_delay`` is not an integer (``3.0``, ``"3"`` and ``True`` included).
        ValueError: ``max_delay`` is negative or above :data:`~delayed_rl.delays.MAX_DELAY`.
    """
    return check_int(
        "max_delay", max_delay, 0, MAX_DELAY, optional=True, note=" (delays must fit int64)"
    )


class DelaySampler:
    """Hands out delays one at a time from blocks drawn in one generator call.

    ``block`` holds the delays still to be used, in reverse order, so that ``block.pop()`` (the
    cheapest list operation) yields them in the order drawn; :meth:`refill` draws the next block.

    Args:
        delay: the distribution.
        max_delay: clip every delay to at most this many steps (``None``: no clipping).
        signal: what it delays, ``"reward"``, ``"observation"`` or ``"action"``: its stream
            (:func:`delay_rng`).
    """

    def __init__(self, delay: Delay, max_delay: int | None, signal: str = "reward"):
        self.delay = delay
        self.max_delay = max_delay
        self.signal = signal
        self.block: list[int] = []
        self.seed(None)

    def seed(self, seed: int | None) -> None:
        """Restart the delay stream from ``seed`` and discard delays drawn ahead.

        ``None``: fresh entropy, taken when the first delay is drawn (as Gymnasium makes an
        env's ``np_random`` at its first use), so that copies of an unseeded wrapper made before
        it drew (SuperSuit's vector conversion pickles one env into every sub-env) draw
        different delays.
        """
        self.rng = None if seed is None else delay_rng(seed, self.signal)
        self.block.clear()

    def refill(self) -> list[int]:
        """Draw the next block of delays into ``block`` (the same list, reversed for ``pop()``)."""
        if self.rng is None:
            self.rng = delay_rng(None, self.signal)
        self.block[:] = draw_delays(self.delay, self.rng, BLOCK, self.max_delay)[::-1].tolist()
        return self.block

    def __call__(self) -> int:
        """The next delay."""
        return (self.block or self.refill()).pop()

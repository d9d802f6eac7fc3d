"""The agents' random streams: uniform numbers handed out one at a time from blocks.

An agent has two streams from its ``seed``: one for training (``learn``, ``update``) and one for
``predict`` (spawned apart with :data:`PREDICT_STREAM`), so that calling ``predict`` between
training calls does not change what training draws.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PREDICT_STREAM", "UniformStream"]

PREDICT_STREAM = 0x9E3D
"""The spawn key that separates ``predict()``'s randomness from training's."""


class UniformStream:
    """Uniform [0, 1) numbers handed out one at a time from blocks of one generator call.

    Call the stream, or its bound :meth:`next` (cheaper to call in a loop), for the next number.

    Args:
        rng: the generator.
        block_size: how many numbers to draw per call.
    """

    __slots__ = ("rng", "block", "_numbers", "block_size")
    BLOCK_SIZE = 1024
    """The default ``block_size``: the most numbers a stream holds drawn but not handed out."""

    def __init__(self, rng: np.random.Generator, block_size: int = BLOCK_SIZE):
        self.rng = rng
        self.block_size = block_size
        self._hand_out([])

    @classmethod
    def from_seed(cls, seed: int | None, spawn_key: tuple[int, ...] = ()) -> UniformStream:
        """A stream whose generator is seeded from ``SeedSequence(seed, spawn_key=spawn_key)``."""
        if not spawn_key:
            return cls(np.random.default_rng(seed))
        return cls(np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn_key)))

    def _hand_out(self, block: list[float]) -> None:
        """Hand out ``block`` next (an iterator over it: the cheapest way to step through it)."""
        self.block = block
        self._numbers = iter(block)

    def next(self) -> float:
        """The next number (the next block is drawn when this one is used up)."""
        try:
            return next(self._numbers)
        except StopIteration:
            self._hand_out(self.rng.random(self.block_size).tolist())
            return next(self._numbers)

    __call__ = next

    def get_state(self) -> tuple[dict[str, Any], np.ndarray]:
        """The generator's state and the numbers drawn but not yet handed out."""
        remaining = self._numbers.__length_hint__()
        block = self.block[len(self.block) - remaining :]
        return self.rng.bit_generator.state, np.asarray(block, dtype=np.float64)

    def set_state(self, state: dict[str, Any], remaining: np.ndarray) -> None:
        """Restore what :meth:`get_state` returned."""
        self.rng.bit_generator.state = state
        self._hand_out([float(x) for x in remaining])

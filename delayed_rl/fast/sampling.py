"""Delay draws for the compiled path from a table: Walker's alias method.

numpy draws Poisson variates by transformed rejection at about 40 ns each, which was a tenth of a
compiled MMQ step; a draw from an alias table costs one uniform, two look-ups and a comparison
(about 7 ns, batched). The compiled path draws its delays from its own stream already, so only the
distribution has to match, not the sequence (DESIGN.md: "the same results in distribution").
The other built-in delays are drawn by numpy about as fast as a table would, and a user's
:class:`~delayed_rl.delays.Delay` subclass is drawn with its own ``sample``.
"""

from __future__ import annotations

import math

import numpy as np

from delayed_rl.delays import Delay, Poisson

TAIL = 1e-20
"""The Poisson mass left out of a table (its far tail), far below a uniform's 2⁻⁵³ resolution."""

MAX_TABLE = 1 << 16
"""The largest table built; beyond it (λ in the tens of thousands) delays come from ``sample``."""


class AliasTable:
    """Draws from a distribution on ``0, 1, …, len(pmf) − 1`` in O(1) per draw.

    Vose's construction of Walker's alias table: each of the ``n`` columns holds a probability
    ``keep[i]`` of its own value and an ``alias[i]`` for the rest, so a draw picks a column with
    the integer part of ``n·u`` and decides with its fractional part.

    Args:
        pmf: non-negative probabilities; they are normalised to sum to one.

    Raises:
        ValueError: if ``pmf`` is empty, has a negative or non-finite entry, or sums to zero.
    """

    def __init__(self, pmf: np.ndarray):
        pmf = np.asarray(pmf, dtype=float)
        if pmf.ndim != 1 or pmf.size == 0 or not np.all(np.isfinite(pmf)) or np.any(pmf < 0):
            raise ValueError(f"pmf must be a non-empty 1-d array of finite values >= 0, got {pmf}")
        total = pmf.sum()
        if total <= 0:
            raise ValueError(f"pmf must have positive mass, got {pmf}")
        n = pmf.size
        scaled = pmf * (n / total)
        self.keep = np.ones(n)
        self.alias = np.arange(n)
        small = [i for i in range(n) if scaled[i] < 1.0]
        large = [i for i in range(n) if scaled[i] >= 1.0]
        while small and large:
            low, high = small.pop(), large[-1]
            self.keep[low] = scaled[low]
            self.alias[low] = high
            scaled[high] -= 1.0 - scaled[low]
            if scaled[high] < 1.0:
                small.append(large.pop())
        # what is left holds probability one up to rounding: it keeps its own value

    def sample(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """``size`` independent draws as an ``int64`` array."""
        u = rng.random(size) * self.keep.size
        column = u.astype(np.int64)
        return np.where(u - column < self.keep[column], column, self.alias[column])


def poisson_table(lam: float, max_delay: int | None) -> AliasTable | None:
    """The alias table of Poisson(λ) delays capped at ``max_delay``, or ``None`` if too large.

    Without a cap the table stops where the remaining tail weighs less than :data:`TAIL`. With
    one, the whole tail from ``max_delay`` on is drawn as ``max_delay``, as the wrapper's cap does.
    """
    poisson = Poisson(lam)
    end = math.ceil(2 * lam) + 1  # past 2λ each term is less than half the one before it
    while end <= MAX_TABLE and poisson.pmf(end) * 2 >= TAIL:
        end = 2 * end
    if end > MAX_TABLE:
        return None
    pmf = poisson.pmf(np.arange(end))
    if max_delay is not None and max_delay < end:
        pmf = np.append(pmf[:max_delay], pmf[max_delay:].sum())
    return AliasTable(pmf)


def delay_table(delay: Delay, max_delay: int | None) -> AliasTable | None:
    """A table to draw ``delay`` from on the compiled path, or ``None`` to use ``delay.sample``."""
    if type(delay) is Poisson:  # a subclass may draw differently from its pmf
        return poisson_table(delay.lam, max_delay)
    return None

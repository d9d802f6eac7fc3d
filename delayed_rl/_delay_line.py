"""The delay line, written once: drawing clipped delays and the rings that hold what is due.

The wrappers, the vector twins' pending rewards, the agents' histories and the compiled path all use
:func:`draw_delays` (a block of clipped delays), :func:`delay_bound` (how far back a delay can
practically reach), :func:`ring_size` and :func:`regrow_ring` (power-of-two rings of what is
pending) and :func:`exact_sum` (a sum of rewards rounded once, or a clear error).

Example:
    >>> import numpy as np
    >>> from delayed_rl.delays import Poisson
    >>> draw_delays(Poisson(5.0), np.random.default_rng(0), 4, max_delay=3).tolist()
    [3, 2, 1, 2]
    >>> ring_size(5), ring_size(8)
    (8, 8)
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from decimal import Decimal
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from delayed_rl.delays import Delay

__all__ = ["delay_bound", "draw_delays", "exact_sum", "regrow_ring", "ring_size"]


def draw_delays(
    delay: Delay, rng: np.random.Generator, size: int | tuple[int, ...], max_delay: int | None
) -> np.ndarray:
    """Draw ``size`` delays from ``delay`` with ``rng``, each clipped to at most ``max_delay``.

    Args:
        delay: the distribution.
        rng: the generator (its stream advances by one ``delay.sample`` call).
        size: the shape of the block.
        max_delay: the clip (``None``: none).

    Returns:
        An ``int64`` array of shape ``size``.
    """
    delays = np.asarray(delay.sample(rng, size), dtype=np.int64)
    if max_delay is not None:
        delays = np.minimum(delays, max_delay)
    return delays


def delay_bound(delay: Delay, max_delay: int | None) -> int:
    """The longest delay worth keeping history for: what ``delay`` (clipped) can reach.

    ``max_delay`` when it is set, else the distribution's largest value, else (an unbounded
    distribution such as Poisson) ``mean + 10·√mean + 20``: for Poisson(λ) that leaves out a tail
    of probability below 1e-20 for every λ.
    """
    if max_delay is not None:
        return max_delay
    if delay.support_max is not None:
        return delay.support_max
    return int(delay.mean + 10.0 * math.sqrt(delay.mean) + 20.0)


def ring_size(n: int) -> int:
    """The smallest power of two ``>= n`` (at least 1), so a slot is ``index & (size - 1)``."""
    return 1 << max(0, int(n) - 1).bit_length()


def regrow_ring(ring: np.ndarray, clock: int | np.ndarray, size: int) -> np.ndarray:
    """A copy of ``ring`` of length ``size`` along its last axis, each entry at its due step.

    A ring of length ``L`` (a power of two) holds what is due at step ``c + i`` in slot
    ``(c + i) & (L − 1)`` for ``i`` in ``0..L−1``, ``c`` its row's clock. The new ring holds the same
    entries in slots ``(c + i) & (size − 1)``.

    Args:
        ring: shape ``(L,)`` or ``(rows, L)``.
        clock: the current step, one per row (a scalar for a 1-D ring).
        size: the new length, a power of two ``>= L``.
    """
    rows = np.atleast_2d(ring)
    old = rows.shape[-1]
    due = np.asarray(clock, dtype=np.int64).reshape(-1, 1) + np.arange(old)
    grown = np.zeros((rows.shape[0], size), dtype=ring.dtype)
    np.put_along_axis(grown, due & (size - 1), np.take_along_axis(rows, due & (old - 1), 1), 1)
    return grown.reshape(ring.shape[:-1] + (size,))


def exact_sum(values: Iterable[float], what: str = "the pending rewards") -> float:
    """The exact sum of finite floats ``values``, rounded once to float64.

    ``math.fsum`` gives it, except that it gives up ("intermediate overflow") when partial sums
    pass float64's range even if the total does not (``1e308 + 1e308 − 1e308``); the sum is then
    taken in exact rationals.

    Args:
        values: finite floats.
        what: what they are, for the message (``"the pending rewards"``).

    Raises:
        ValueError: the sum itself is beyond float64's range (about ±1.8e308): the message says
            ``"<what> sum to more than float64 can hold"`` and about how much.
    """
    values = list(values)
    try:
        return math.fsum(values)
    except OverflowError:
        total = sum(map(Fraction, values), Fraction(0))
    try:
        return float(total)
    except OverflowError:
        size = Decimal(total.numerator) / Decimal(total.denominator)
        raise ValueError(
            f"{what} sum to more than float64 can hold (about {size:.3e}; the largest float is "
            f"about 1.798e+308): rescale the env's rewards"
        ) from None

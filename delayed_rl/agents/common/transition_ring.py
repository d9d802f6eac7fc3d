"""The episode's last transitions, for the rules that credit a reward to a step ``k`` back.

Fixed-delay Q-learning, MMQ and expected-credit Q-learning credit the reward received at episode
step ``t`` to the transition of step ``t − k``: a :class:`TransitionRing` keeps the transitions
of the last steps (a power-of-two ring longer than the longest ``k``), as ``(s, s′, cell)`` with
``cell = s·row + a`` the transition's entry in the Q-table's flat layout.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl._delay_line import ring_size

__all__ = ["TransitionRing"]


class TransitionRing:
    """The last ``longest_lag + 1`` (or more) transitions of the episode.

    Args:
        longest_lag: the furthest step back a rule credits.

    Attributes:
        rows: the ring, ``int64`` of shape ``(3, size)``: rows ``s``, ``s′`` and ``cell``
            (compiled updates read it whole).
        mask: ``size − 1`` (``size`` a power of two): step ``t`` sits at ``t & mask``.
        s, s2, cell: memoryviews of the rows, which read and write single entries as Python
            integers (rebuilt after a copy).
    """

    _VIEWS = ("s", "s2", "cell")

    def __init__(self, longest_lag: int):
        size = ring_size(longest_lag + 1)
        self.mask = size - 1
        self.rows = np.zeros((3, size), dtype=np.int64)
        self._make_views()

    def _make_views(self) -> None:
        self.s, self.s2, self.cell = (memoryview(row) for row in self.rows)

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in vars(self).items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, Any]) -> None:
        vars(self).update(state)
        self._make_views()

    def record(self, t: int, s: int, s2: int, cell: int) -> None:
        """Store episode step ``t``'s transition."""
        j = t & self.mask
        self.s[j] = s
        self.s2[j] = s2
        self.cell[j] = cell

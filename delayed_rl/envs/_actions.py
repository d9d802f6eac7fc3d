"""The per-step action check of the tabular envs, at a fraction of a step's cost."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["ActionCheck"]


class ActionCheck:
    """Gymnasium's ``Discrete.contains`` with a fast path for the actions agents pass.

    ``Discrete.contains`` costs more than a grid-world step. An exact ``int``, or a numpy integer
    scalar whose type casts to the space's dtype, is answered by one range comparison; anything
    else (``bool``, ``int`` subclasses, 0-d arrays, floats, strings, ...) is handed to
    ``space.contains``. The fast path only answers where ``contains`` would accept, so what is
    accepted and what is rejected is exactly Gymnasium's. With ``integers_only``, what is not an
    integer at all (a ``bool`` or ``np.bool_``, which ``Discrete.contains`` may take for 1 and
    0, a float, a string, ``None``, an array that is not a 0-d integer array) raises
    ``TypeError`` rather than ``ValueError``, as the library's checks do everywhere; an integer
    outside the space raises ``ValueError``.

    Args:
        space: the env's action space (fixed for the env's lifetime).
        allowed: what is allowed, for the message (``"0 (bet even) or 1 (bet 13)"``).
        integers_only: refuse what is not an integer with a ``TypeError``.
    """

    __slots__ = ("space", "allowed", "integers_only", "_types", "_start", "_stop")

    def __init__(self, space: spaces.Discrete, allowed: str, *, integers_only: bool = False):
        self.space = space
        self.allowed = allowed
        self.integers_only = integers_only
        self._types = frozenset(
            {int}
            | {
                kind
                for kind in np.sctypeDict.values()
                if issubclass(kind, np.integer) and np.can_cast(kind, space.dtype)
            }
        )
        self._start = int(space.start)
        self._stop = self._start + int(space.n)

    def check(self, action: Any) -> None:
        """Return if ``action`` is in the space, else raise (a method: cheaper than ``__call__``).

        Raises:
            TypeError: ``action`` is not an integer and ``integers_only`` is set.
            ValueError: ``action`` is not in the space (whatever its type); the message names
                the argument, says what is allowed and shows the value.
        """
        if type(action) in self._types and self._start <= action < self._stop:
            return
        if self.integers_only and not _is_integer(action):
            raise TypeError(
                f"action must be an integer {self.allowed} (an int, a numpy integer or a 0-d "
                f"integer array; not a bool), got {action!r} ({type(action).__name__})"
            )
        if not self.space.contains(action):
            raise ValueError(f"action must be {self.allowed}, got {action!r}")


def _is_integer(value: object) -> bool:
    """Whether ``value`` is an integer: an ``int``, a numpy integer or a 0-d integer array."""
    if isinstance(value, np.ndarray):
        return value.shape == () and value.dtype.kind in "iu"
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))

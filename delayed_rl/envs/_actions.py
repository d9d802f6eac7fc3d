"""The per-step action check of the tabular envs, at a fraction of a step's cost."""

from __future__ import annotations

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
    accepted and what is rejected is exactly Gymnasium's, except that with ``refuse_bool`` a
    Python ``bool`` (which ``Discrete.contains`` takes for an ``int``: ``True`` is 1) raises
    ``TypeError``, as the library refuses a bool for a number everywhere. (A numpy ``np.bool_``
    is not in a ``Discrete`` space for Gymnasium: it raises ``ValueError`` like any other value
    outside the space.)

    Args:
        space: the env's action space (fixed for the env's lifetime).
        allowed: what is allowed, for the message (``"0 (bet even) or 1 (bet 13)"``).
        refuse_bool: refuse ``True`` and ``False`` with a ``TypeError``.
    """

    __slots__ = ("space", "allowed", "refuse_bool", "_types", "_start", "_stop")

    def __init__(self, space: spaces.Discrete, allowed: str, *, refuse_bool: bool = False):
        self.space = space
        self.allowed = allowed
        self.refuse_bool = refuse_bool
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
            TypeError: ``action`` is a ``bool`` and ``refuse_bool`` is set.
            ValueError: ``action`` is not in the space (whatever its type); the message names
                the argument, says what is allowed and shows the value.
        """
        if type(action) in self._types and self._start <= action < self._stop:
            return
        if self.refuse_bool and isinstance(action, bool):
            raise TypeError(
                f"action must be an integer {self.allowed}, not a bool, got {action!r} "
                f"({type(action).__name__})"
            )
        if not self.space.contains(action):
            raise ValueError(f"action must be {self.allowed}, got {action!r}")

"""Argument checks shared by the agents, envs and experiments."""

from __future__ import annotations

import numbers
from typing import Any


def check_int(name: str, value: Any, low: int, *, optional: bool = False, note: str = "") -> Any:
    """Return ``value`` as an ``int`` (or ``None`` when ``optional``) after checking it.

    Args:
        name: the argument's name, for the message.
        value: what was passed; ``bool`` is refused although it is an ``int``.
        low: the smallest value allowed.
        optional: ``None`` is allowed (and returned).
        note: appended to the description of what is allowed, e.g. ``" (0 silent, 1 info)"``.

    Raises:
        ValueError: naming the argument, the value and what is allowed.
    """
    if optional and value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        allowed = f"{'None or ' if optional else ''}an integer >= {low}{note}"
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return int(value)

"""Argument checks shared by the whole library: one policy for bad input.

Every public argument is checked where it enters (a constructor, ``learn``, a CLI option), with
the policy of Gymnasium's wrappers:

- ``TypeError`` for a value of the wrong type (``"5"`` for an integer, ``True`` for a number:
  ``bool`` is refused although Python counts it as an ``int``);
- ``ValueError`` for a value of the right type outside what is allowed (a negative count, NaN,
  an unknown mode).

Messages name the argument, say what is allowed and show the value:
``"gamma must be a number in [0, 1], got 1.5"``.

Example:
    >>> check_int("seed", 3, low=0)
    3
    >>> check_probability("gamma", "0.5")
    Traceback (most recent call last):
        ...
    TypeError: gamma must be a number in [0, 1], got '0.5' (str)
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection
from typing import Any

import numpy as np

__all__ = [
    "check_bool",
    "check_choice",
    "check_fraction",
    "check_int",
    "check_probability",
    "check_real",
]


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    """``" in [low, high)"``, ``" >= low"``, ``" < high"``..., or ``""`` with no bound."""
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f" {'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f" {'<' if high_open else '<='} {high:g}"
    return ""


def _got(value: Any, wrong_type: bool) -> str:
    """``"got <repr>"``, with the type's name when the type is what is wrong."""
    return f"got {value!r} ({type(value).__name__})" if wrong_type else f"got {value!r}"


def check_int(
    name: str,
    value: Any,
    low: int | None = None,
    high: int | None = None,
    *,
    optional: bool = False,
    note: str = "",
) -> Any:
    """Return ``value`` as an ``int`` (or ``None`` when ``optional``) after checking it.

    Args:
        name: the argument's name, for the message.
        value: what was passed (any ``numbers.Integral`` but ``bool``, e.g. ``np.int64``).
        low: the smallest value allowed (``None``: no lower bound).
        high: the largest value allowed (``None``: no upper bound).
        optional: ``None`` is allowed (and returned).
        note: appended to the description of what is allowed, e.g. ``" (0 silent, 1 info)"``.

    Raises:
        TypeError: ``value`` is not an integer.
        ValueError: ``value`` is outside ``[low, high]``.
    """
    if optional and value is None:
        return None
    allowed = f"{'None or ' if optional else ''}an integer{_interval(low, high, False, False)}"
    wrong_type = isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral)
    if wrong_type or (low is not None and value < low) or (high is not None and value > high):
        error = TypeError if wrong_type else ValueError
        raise error(f"{name} must be {allowed}{note}, {_got(value, wrong_type)}")
    return int(value)


def check_real(
    name: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    optional: bool = False,
    note: str = "",
) -> Any:
    """Return ``value`` as a finite ``float`` (or ``None`` when ``optional``) after checking it.

    Args:
        name: the argument's name, for the message.
        value: what was passed (any ``numbers.Real`` but ``bool``, e.g. ``np.float32``).
        low: the lower bound (``None``: none).
        high: the upper bound (``None``: none).
        low_open: ``low`` itself is not allowed.
        high_open: ``high`` itself is not allowed.
        optional: ``None`` is allowed (and returned).
        note: appended to the description of what is allowed.

    Raises:
        TypeError: ``value`` is not a real number.
        ValueError: ``value`` is NaN, infinite or outside the bounds.
    """
    if optional and value is None:
        return None
    interval = _interval(low, high, low_open, high_open)
    allowed = f"{'None or ' if optional else ''}{'a number' if interval else 'a finite number'}"
    allowed += interval + note
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be {allowed}, {_got(value, True)}")
    number = float(value)
    if (
        not math.isfinite(number)
        or (low is not None and (number < low or (low_open and number == low)))
        or (high is not None and (number > high or (high_open and number == high)))
    ):
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return number


def check_probability(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is a number in [0, 1]."""
    return check_real(name, value, 0.0, 1.0)


def check_fraction(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is a number in (0, 1]."""
    return check_real(name, value, 0.0, 1.0, low_open=True)


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` as a ``bool`` after checking that it is one (``np.bool_`` included).

    Raises:
        TypeError: ``value`` is not a bool (``0`` and ``1`` are refused: say ``False``/``True``).
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, {_got(value, True)}")
    return bool(value)


def check_choice(name: str, value: Any, choices: Collection[Any]) -> Any:
    """Return ``value`` after checking that it is one of ``choices``.

    Raises:
        TypeError: ``value`` is not of the choices' type (e.g. a number for a string option).
        ValueError: ``value`` is of the right type but not one of ``choices``.
    """
    kinds = {type(choice) for choice in choices}
    if not any(isinstance(value, kind) for kind in kinds):
        raise TypeError(f"{name} must be one of {tuple(choices)}, {_got(value, True)}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value

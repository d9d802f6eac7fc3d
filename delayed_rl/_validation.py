"""Argument checks shared by the whole library: one policy for bad input.

Every public argument is checked where it enters (a constructor, ``learn``, a CLI option), as
Gymnasium's wrappers do: ``TypeError`` for the wrong type (``bool`` is refused where a number is
wanted, although Python counts it as an ``int``), ``ValueError`` for a value outside what is
allowed. Messages name the argument, say what is allowed and show the value.

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
    "Limit",
    "RealLimit",
    "check_bool",
    "check_choice",
    "check_fraction",
    "check_int",
    "check_limit",
    "check_probability",
    "check_real",
    "check_real_vector",
    "check_reward",
    "check_rewards",
]

_SHOWN = 200  # characters of a value's repr that a message shows


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    """``" in [low, high)"``, ``" >= low"``, ``" < high"``..., or ``""`` with no bound."""
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f" {'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f" {'<' if high_open else '<='} {high:g}"
    return ""


def _shown(value: Any) -> str:
    """``repr(value)``, cut to :data:`_SHOWN` characters (an int too long to print: its size)."""
    try:
        text = repr(value)
    except ValueError:  # an int beyond Python's digit limit for str()
        return f"<an int of {value.bit_length()} bits>"
    return text if len(text) <= _SHOWN else f"{text[: _SHOWN - 5]}...{text[-2:]}"


def _got(value: Any, wrong_type: bool) -> str:
    """``"got <repr>"``, with the type's name when the type is what is wrong."""
    return f"got {_shown(value)} ({type(value).__name__})" if wrong_type else f"got {_shown(value)}"


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
    try:
        number = float(value)
    except OverflowError:  # an int (or Fraction) beyond float64's range
        raise ValueError(f"{name} must be {allowed}, {_got(value, False)}") from None
    if (
        not math.isfinite(number)
        or (low is not None and (number < low or (low_open and number == low)))
        or (high is not None and (number > high or (high_open and number == high)))
    ):
        raise ValueError(f"{name} must be {allowed}, {_got(value, False)}")
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


def check_real_vector(name: str, value: Any, length: int, *, note: str = "") -> tuple[float, ...]:
    """Return ``value``, a sequence of ``length`` finite real numbers, as a tuple of floats.

    A list, a tuple or a 1-D numpy array is accepted; each entry is checked as
    :func:`check_real` checks a number (named ``name[i]``).

    Args:
        name: the argument's name, for the message.
        value: what was passed.
        length: how many numbers it must hold.
        note: appended to the description of what is allowed, e.g. ``" (x, y, heading)"``.

    Raises:
        TypeError: ``value`` is not a sequence (a string is not), or an entry is not a number.
        ValueError: ``value`` does not hold ``length`` numbers (or is a multi-dimensional
            array), or an entry is NaN or infinite.
    """
    allowed = f"a sequence of {length} finite numbers{note}"
    if isinstance(value, np.ndarray):
        if value.ndim != 1:
            raise ValueError(f"{name} must be {allowed}, got an array of shape {value.shape}")
    elif isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)):
        raise TypeError(f"{name} must be {allowed}, {_got(value, True)}")
    if len(value) != length:
        raise ValueError(f"{name} must be {allowed}, got {len(value)} of them: {_shown(value)}")
    return tuple(check_real(f"{name}[{i}]", entry) for i, entry in enumerate(value))


_REWARD = (
    "a real scalar (a Python or numpy int or float, or a 0-d numpy array of one; not a bool, "
    "a complex number or a sequence)"
)
_SCALAR_TYPES = frozenset(
    {int, float}
    | {kind for kind in np.sctypeDict.values() if issubclass(kind, np.integer | np.floating)}
)


def check_reward(name: str, value: Any) -> float:
    """Return a reward as a Python ``float`` after checking that it is a real scalar.

    Accepted: ``int``, ``float``, numpy integer and floating scalars, any other
    ``numbers.Real`` (``fractions.Fraction``), and 0-d numpy arrays of an integer or floating
    dtype (what numpy itself treats as a scalar). Refused: ``bool`` and ``np.bool_`` (as
    everywhere in this library, and by Gymnasium's env checker), complex numbers, ``None``,
    strings, and sequences or arrays of one or more dimensions (a 1-element array included:
    numpy deprecates reading it as a scalar, and it is more likely one objective of a vector
    reward than a scalar). Infinite and NaN values are returned: the caller refuses them with
    its own message.

    The common case (an ``int``, a ``float`` or a numpy number) costs one set look-up and the
    conversion; the careful checks run only for the other types.

    Args:
        name: what the value is, for the message (``"reward"``, ``"rewards[2]"``).
        value: the reward.

    Raises:
        TypeError: ``value`` is not a real scalar.
        ValueError: ``value`` is an integer beyond float64's range (``10**400``).
    """
    if type(value) in _SCALAR_TYPES:
        try:
            return float(value)
        except OverflowError:
            pass  # an int beyond float64: said below
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        return float(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        kind = type(value).__name__
        if isinstance(value, np.ndarray):
            kind += f" of shape {value.shape}"
        raise TypeError(f"{name} must be {_REWARD}, got {_shown(value)} ({kind})")
    try:
        return float(value)
    except OverflowError:
        raise ValueError(
            f"{name} must be a real number within float64's range (of magnitude below about "
            f"1.8e308), {_got(value, False)}"
        ) from None


def check_rewards(name: str, values: Any, count: int) -> np.ndarray:
    """Return a batch of ``count`` rewards as a float64 array after checking it.

    The common case, a 1-D numpy array of ``count`` integers or floats, is converted at once
    (no copy for float64); anything else is checked entry by entry as :func:`check_reward`
    checks one reward (the message names ``name[i]``). Infinite and NaN entries are returned:
    the caller refuses them with its own message.

    Args:
        name: what the batch is, for the message (``"rewards"``).
        values: the batch (an array, a list or a tuple).
        count: how many rewards it must hold (one per sub-env).

    Raises:
        TypeError: ``values`` is not a sequence, or an entry is not a real scalar.
        ValueError: ``values`` does not hold ``count`` rewards (or has more than one
            dimension), or an entry is beyond float64's range.
    """
    if type(values) is np.ndarray and values.dtype.kind in "iuf" and values.shape == (count,):
        return np.asarray(values, dtype=np.float64)
    allowed = f"a 1-D array of {count} real numbers (one reward per sub-env)"
    if isinstance(values, np.ndarray):
        if values.ndim != 1 or len(values) != count:
            raise ValueError(f"{name} must be {allowed}, got an array of shape {values.shape}")
    elif isinstance(values, (str, bytes)) or not isinstance(values, (list, tuple)):
        raise TypeError(f"{name} must be {allowed}, {_got(values, True)}")
    elif len(values) != count:
        raise ValueError(f"{name} must be {allowed}, got {len(values)}: {_shown(values)}")
    return np.array([check_reward(f"{name}[{i}]", v) for i, v in enumerate(values)])


class _NamedBound:
    """What :class:`Limit` and :class:`RealLimit` share: a number that knows its constant's name.

    A subclass also derives from ``int`` or ``float``; it is built by :meth:`_named`.
    """

    name: str
    home: str
    shown: str | None
    text: str

    def _named(self, name: str, home: str, shown: str | None, default: str) -> Any:
        self.name, self.home, self.shown = name, home, shown
        self.text = f"{name} = {default if shown is None else shown} ({home})"
        return self

    def __reduce__(self) -> tuple:
        number = int(self) if isinstance(self, int) else float(self)
        return (type(self), (number, self.name, self.home, self.shown))


class Limit(_NamedBound, int):
    """An integer bound the library states as a named constant; messages name it by its ``text``.

    ``Limit(2**40, "MAX_TIMESTEPS", "delayed_rl.agents.common.python_loop", "2**40")`` is the
    integer ``2**40``, whose ``text`` is ``"MAX_TIMESTEPS = 2**40
    (delayed_rl.agents.common.python_loop)"``: :func:`check_limit` puts that in its message.

    Args:
        value: the bound.
        name: the constant's name.
        home: the module that defines it.
        shown: how the message writes the value (``None``: with thousands separators).

    Attributes:
        name, home, shown: the arguments.
        text: ``"NAME = value (home)"``.
    """

    def __new__(cls, value: int, name: str, home: str, shown: str | None = None) -> Limit:
        """A new bound (see the class docstring)."""
        return super().__new__(cls, value)._named(name, home, shown, f"{value:,}")


class RealLimit(_NamedBound, float):
    """A real bound the library states as a named constant: :class:`Limit`'s twin for floats.

    ``RealLimit(2.0**200, "MAX_ABS_VALUE", "delayed_rl.agents.common.hyperparameters",
    "2**200")`` is the float ``2.0**200``, whose ``text`` is ``"MAX_ABS_VALUE = 2**200
    (delayed_rl.agents.common.hyperparameters)"``.

    Args and attributes: :class:`Limit`'s (``shown`` ``None``: the float as Python writes it).
    """

    def __new__(cls, value: float, name: str, home: str, shown: str | None = None) -> RealLimit:
        """A new bound (see the class docstring)."""
        return super().__new__(cls, value)._named(name, home, shown, repr(float(value)))


def check_limit(name: str, value: Any, limit: int | float, limit_name: str | None = None) -> Any:
    """Return ``value`` after checking that it is at most ``limit`` (a checked number, or None).

    The bounds the library states as module constants are checked after the argument's own
    check (its type and lower bound), so that the message names the constant.

    Args:
        name: the argument's name, for the message.
        value: its value (``None`` passes).
        limit: the largest value allowed: a :class:`Limit` or :class:`RealLimit`, or a number
            named by ``limit_name``.
        limit_name: how the message names ``limit`` (``None``: the limit's ``text``).

    Raises:
        ValueError: ``value`` is above ``limit``.
    """
    if value is not None and value > limit:
        shown = limit.text if limit_name is None else limit_name
        raise ValueError(f"{name} must be at most {shown}, got {value!r}")
    return value

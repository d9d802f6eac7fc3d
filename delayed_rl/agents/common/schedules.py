"""Schedules of the training progress, with stable-baselines3's conventions.

A schedule is a callable of ``progress_remaining``, which falls from 1 at the start of a
:meth:`~delayed_rl.agents.common.base.TabularAgent.learn` call to 0 at its end, and returns a value
(a learning rate, an exploration rate). Any callable with that signature works, SB3's
``LinearSchedule`` included; the two classes here also describe themselves to
:func:`schedule_to_json`, so a saved model restores them exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from delayed_rl._validation import check_fraction

__all__ = [
    "ConstantSchedule",
    "LinearSchedule",
    "Schedule",
    "as_learning_rate_schedule",
    "check_schedule_value",
    "schedule_from_json",
    "schedule_to_json",
]

Schedule = Callable[[float], float]


class ConstantSchedule:
    """The same value at every point of training.

    Args:
        value: the value.
    """

    def __init__(self, value: float):
        self.value = float(value)

    def __call__(self, progress_remaining: float) -> float:
        """The value, whatever the progress."""
        return self.value

    def __repr__(self) -> str:
        return f"ConstantSchedule({self.value!r})"


class LinearSchedule:
    """Linear from ``start`` (progress remaining 1) to ``end``, reached after ``end_fraction``.

    The same function as SB3's ``LinearSchedule`` (used by DQN for its exploration rate): after a
    fraction ``end_fraction`` of the training, the value stays at ``end``.

    Args:
        start: the value at the start of training.
        end: the value from ``end_fraction`` of the training on.
        end_fraction: the fraction of the training over which the value moves, in (0, 1].
    """

    def __init__(self, start: float, end: float, end_fraction: float):
        self.start = float(start)
        self.end = float(end)
        self.end_fraction = check_fraction("end_fraction", end_fraction)

    def __call__(self, progress_remaining: float) -> float:
        """The value at ``progress_remaining`` (1 at the start of training, 0 at its end)."""
        progress = 1.0 - progress_remaining
        if progress > self.end_fraction:
            return self.end
        return self.start + progress * (self.end - self.start) / self.end_fraction

    def __repr__(self) -> str:
        return f"LinearSchedule({self.start!r}, {self.end!r}, {self.end_fraction!r})"


def as_learning_rate_schedule(learning_rate: Any) -> Schedule:
    """Validate ``learning_rate`` (a number in (0, 1] or a schedule) and return a schedule."""
    if callable(learning_rate):
        return learning_rate
    return ConstantSchedule(check_fraction("learning_rate", learning_rate))


def check_schedule_value(
    name: str, value: Any, progress_remaining: float, allow_zero: bool = True
) -> float:
    """Check a value a schedule returned: a number in [0, 1] (in (0, 1] without ``allow_zero``)."""
    allowed = "[0, 1]" if allow_zero else "(0, 1]"
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not (0.0 <= number <= 1.0) or (number == 0.0 and not allow_zero):
        raise ValueError(
            f"the {name} schedule must return a number in {allowed}, got {value!r} at "
            f"progress_remaining={progress_remaining}"
        )
    return number


def schedule_to_json(schedule: Schedule, current_value: float) -> dict[str, Any]:
    """Describe ``schedule`` as JSON: exactly for the classes here, else by ``current_value``."""
    if isinstance(schedule, ConstantSchedule):
        return {"type": "constant", "value": schedule.value}
    if isinstance(schedule, LinearSchedule):
        return {
            "type": "linear",
            "start": schedule.start,
            "end": schedule.end,
            "end_fraction": schedule.end_fraction,
        }
    return {
        "type": "callable",
        "repr": repr(schedule),
        "value": float(current_value),
    }


def schedule_from_json(data: dict[str, Any]) -> Schedule | float:
    """Rebuild what :func:`schedule_to_json` described.

    A constant (or a callable schedule, which cannot be stored) comes back as its value.
    """
    kind = data["type"]
    if kind == "linear":
        return LinearSchedule(data["start"], data["end"], data["end_fraction"])
    if kind in ("constant", "callable"):
        return float(data["value"])
    raise ValueError(f"unknown schedule type {kind!r}")

"""The shared argument checks: what they accept, the exception type and the message otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl._validation import (
    check_bool,
    check_choice,
    check_fraction,
    check_int,
    check_probability,
    check_real,
)


def test_check_int_accepts_integers_in_range_and_optional_none():
    assert check_int("n", 3, 3) == 3
    assert type(check_int("n", np.int64(7), 0)) is int
    assert check_int("n", None, 1, optional=True) is None
    assert check_int("n", 5, 0, 5) == 5


@pytest.mark.parametrize("value", [True, np.bool_(True), 2.0, "3", None, [3]])
def test_check_int_refuses_wrong_types_with_type_error(value):
    with pytest.raises(TypeError) as raised:
        check_int("n", value, 3, note=" (note)")
    expected = f"n must be an integer >= 3 (note), got {value!r} ({type(value).__name__})"
    assert str(raised.value) == expected


@pytest.mark.parametrize(("value", "low", "high"), [(2, 3, None), (7, 0, 5), (-1, 0, 5)])
def test_check_int_refuses_out_of_range_with_value_error(value, low, high):
    with pytest.raises(ValueError, match=rf"^n must be an integer .*, got {value}$"):
        check_int("n", value, low, high)


def test_optional_message_mentions_none():
    with pytest.raises(ValueError, match="max_steps must be None or an integer >= 1, got 0"):
        check_int("max_steps", 0, 1, optional=True)
    with pytest.raises(ValueError, match=r"^k must be an integer in \[1, 4\], got 5$"):
        check_int("k", 5, 1, 4)


def test_check_real_bounds_open_and_closed():
    assert check_real("x", np.float32(0.5), 0, 1) == 0.5
    assert check_real("x", 3) == 3.0 and type(check_real("x", 3)) is float
    assert check_fraction("lr", 1) == 1.0
    assert check_probability("p", 0) == 0.0
    with pytest.raises(ValueError, match=r"^lr must be a number in \(0, 1\], got 0$"):
        check_fraction("lr", 0)
    with pytest.raises(ValueError, match=r"^x must be a number < 2, got 2$"):
        check_real("x", 2, high=2, high_open=True)
    with pytest.raises(ValueError, match=r"^x must be a number > 0 steps, got -1.5$"):
        check_real("x", -1.5, 0, low_open=True, note=" steps")


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_check_real_refuses_non_finite_values(value):
    with pytest.raises(ValueError, match="q must be a finite number"):
        check_real("q", value)
    with pytest.raises(ValueError, match=r"p must be a number in \[0, 1\]"):
        check_probability("p", value)


@pytest.mark.parametrize("value", ["0.5", True, None, [0.5], 1j])
def test_check_real_refuses_wrong_types_with_type_error(value):
    with pytest.raises(
        TypeError, match=rf"gamma must be a number in \[0, 1\], got .*\({type(value).__name__}\)"
    ):
        check_probability("gamma", value)
    assert check_real("x", None, optional=True) is None


def test_check_bool_and_check_choice():
    assert check_bool("flag", np.bool_(False)) is False
    for value in (0, 1, "True", None):
        with pytest.raises(TypeError, match=r"^flag must be a bool, got "):
            check_bool("flag", value)
    assert check_choice("mode", "drop", ("flush", "drop")) == "drop"
    with pytest.raises(ValueError, match=r"^mode must be one of \('flush', 'drop'\), got 'keep'$"):
        check_choice("mode", "keep", ("flush", "drop"))
    with pytest.raises(TypeError, match=r"^mode must be one of .*, got 3 \(int\)$"):
        check_choice("mode", 3, ("flush", "drop"))

"""The shared argument checks: what they accept, the exception type and the message otherwise.

Also ``Limit``: a bound that is an integer and names itself in messages, and ``check_limit``.
"""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from delayed_rl._validation import (
    Limit,
    check_bool,
    check_choice,
    check_fraction,
    check_int,
    check_limit,
    check_probability,
    check_real,
)
from delayed_rl.agents.common.hyperparameters import MAX_SEED_VALUE
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.parallel.pools import MAX_SEED_COUNT, MAX_WORKERS


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


# Limit: a bound that is an integer and names itself in messages.


def test_a_limit_is_its_integer_and_its_text_names_the_constant_and_its_module():
    limit = Limit(2**40, "MAX_STEPS", "some.module", "2**40")
    assert limit == 2**40 and isinstance(limit, int) and limit + 1 == 2**40 + 1
    assert limit.text == "MAX_STEPS = 2**40 (some.module)"
    assert Limit(10_000, "MAX_N", "m").text == "MAX_N = 10,000 (m)"
    assert json.dumps({"n": limit}) == '{"n": 1099511627776}'


def test_a_limit_survives_pickling_with_its_text():
    again = pickle.loads(pickle.dumps(MAX_SEED_COUNT))
    assert again == MAX_SEED_COUNT and again.text == MAX_SEED_COUNT.text


def test_check_limit_names_the_constant_or_the_given_name():
    assert (
        check_limit("steps", 5, MAX_TIMESTEPS) == 5 and check_limit("x", None, MAX_WORKERS) is None
    )
    with pytest.raises(
        ValueError,
        match=r"^seed must be at most MAX_SEED_VALUE = 2\*\*63 - 1 "
        r"\(delayed_rl\.agents\.common\.hyperparameters\), got 9223372036854775808$",
    ):
        check_limit("seed", 2**63, MAX_SEED_VALUE)
    with pytest.raises(ValueError, match=r"^x must be at most TEN, got 11$"):
        check_limit("x", 11, 10, "TEN")


def test_the_seed_value_and_the_seed_count_have_names_that_say_which():
    assert MAX_SEED_VALUE == 2**63 - 1 and MAX_SEED_VALUE.name == "MAX_SEED_VALUE"
    assert MAX_SEED_COUNT == 10_000 and MAX_SEED_COUNT.name == "MAX_SEED_COUNT"

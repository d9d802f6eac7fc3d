"""``delayed_rl._validation.Limit``: a bound that is an integer and names itself in messages."""

from __future__ import annotations

import json
import pickle

import pytest

from delayed_rl._validation import Limit, check_limit
from delayed_rl.agents.common.hyperparameters import MAX_SEED_VALUE
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.parallel.pools import MAX_SEED_COUNT, MAX_WORKERS


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

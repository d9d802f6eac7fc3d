"""The shared integer check: what it accepts, and the message it gives otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl._validation import check_int


def test_accepts_integers_at_or_above_low_and_optional_none():
    assert check_int("n", 3, 3) == 3
    assert type(check_int("n", np.int64(7), 0)) is int
    assert check_int("n", None, 1, optional=True) is None


@pytest.mark.parametrize("value", [2, True, 2.0, "3", None])
def test_refuses_with_a_message_naming_argument_value_and_range(value):
    with pytest.raises(ValueError, match=rf"^n must be an integer >= 3 \(note\), got {value!r}$"):
        check_int("n", value, 3, note=" (note)")


def test_optional_message_mentions_none():
    with pytest.raises(ValueError, match="max_steps must be None or an integer >= 1, got 0"):
        check_int("max_steps", 0, 1, optional=True)

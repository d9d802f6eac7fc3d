"""The tabular envs' action check: Gymnasium's ``Discrete.contains``, answered fast for integers.

What the envs accept and refuse must stay exactly what ``Discrete.contains`` says (the fast
path only shortcuts the common, valid case), with the envs' own ``ValueError`` messages.
"""

from __future__ import annotations

import copy
import pickle
import re

import numpy as np
import pytest
from gymnasium import spaces

from delayed_rl.envs._actions import ActionCheck, _is_integer
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.envs.roulette import RouletteEnv


class IntSubclass(int):
    """An ``int`` subclass: not on the fast path, still an integer to ``Discrete``."""


NUMPY_INTEGERS = (
    np.int8,
    np.int16,
    np.int32,
    np.int64,
    np.longlong,
    np.uint8,
    np.uint16,
    np.uint32,
    np.uint64,
    np.ulonglong,
)
CANDIDATES = [
    *range(-2, 6),
    True,
    False,
    np.True_,
    1.0,
    np.float32(1.0),
    np.float64(2.0),
    *(kind(value) for kind in NUMPY_INTEGERS for value in (0, 1, 3, 4)),
    np.int16(-1),
    np.array(1),
    np.array(1, dtype=np.uint64),
    np.array([1]),
    np.array(1.0),
    IntSubclass(1),
    IntSubclass(9),
    2**63,
    -(2**63) - 1,
    "1",
    None,
    [1],
    1 + 0j,
]


@pytest.mark.parametrize("n", [1, 2, 4])
@pytest.mark.parametrize("action", CANDIDATES, ids=repr)
def test_check_accepts_exactly_what_discrete_contains(n: int, action: object) -> None:
    space = spaces.Discrete(n)
    check = ActionCheck(space, "allowed").check
    if space.contains(action):
        check(action)
    else:
        with pytest.raises(ValueError, match=r"^action must be allowed, got "):
            check(action)


def test_check_follows_the_space_start_and_dtype() -> None:
    check = ActionCheck(spaces.Discrete(3, start=5, dtype=np.int32), "5, 6 or 7").check
    for action in (5, 6, 7, np.int16(7)):
        check(action)
    for action in (4, 8, np.int64(6)):  # np.int64 does not cast to int32: contains says no
        with pytest.raises(ValueError, match=re.escape(f"got {action!r}")):
            check(action)


@pytest.mark.parametrize(
    ("make", "allowed"),
    [
        (lambda: GridWorldEnv(size=3), "in Discrete(4) (0 up, 1 right, 2 down, 3 left)"),
        (RouletteEnv, "0 (bet even) or 1 (bet 13)"),
    ],
)
def test_envs_refuse_what_their_space_does_not_contain(make, allowed) -> None:
    env = make()
    env.reset(seed=0)
    for action in CANDIDATES:
        if env.action_space.contains(action) and not isinstance(action, bool):
            continue
        if _is_integer(action):
            with pytest.raises(ValueError) as error:
                env.step(action)
            assert str(error.value) == f"action must be {allowed}, got {action!r}"
        else:  # not an integer at all: a TypeError, whatever Discrete.contains says
            with pytest.raises(TypeError, match=r"^action must be an integer .*not a bool\), got"):
                env.step(action)


@pytest.mark.parametrize("action", [2, np.int64(2), np.int32(2), np.uint8(2), np.array(2)])
def test_integer_actions_of_every_kind_step_alike(action) -> None:
    env = GridWorldEnv(size=3)
    env.reset(options={"state": 4})
    assert env.step(action)[:2] == (7, 0.0)


def test_copies_check_their_own_space() -> None:
    env = GridWorldEnv(size=3)
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        assert twin._check_action.__self__.space is twin.action_space
        twin.reset()
        with pytest.raises(ValueError, match="got 4"):
            twin.step(4)


@pytest.mark.parametrize("make", [lambda: GridWorldEnv(size=3), RouletteEnv])
@pytest.mark.parametrize("action", [True, False])
def test_envs_refuse_a_bool_for_an_action_with_a_type_error(make, action) -> None:
    """A bool is not an action (``np.True_`` neither: the candidates' test)."""
    env = make()
    env.reset(seed=0)
    with pytest.raises(
        TypeError, match=rf"^action must be an integer .*not a bool\), got {action}"
    ):
        env.step(action)


def test_the_bool_refusal_is_the_envs_choice_not_the_checks_default() -> None:
    ActionCheck(spaces.Discrete(2), "0 or 1").check(True)  # Discrete.contains(True) holds
    with pytest.raises(TypeError, match="not a bool"):
        ActionCheck(spaces.Discrete(2), "0 or 1", integers_only=True).check(True)

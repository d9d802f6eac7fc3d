"""ActionDelay: which action the env executes, step by step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from support import Echo, ScriptedDelay

from delayed_rl.delays import Constant, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import ActionDelay
from delayed_rl.wrappers.action_delay import ActionLine, neutral_action


def reference(actions, delays, initial):
    """What the docstring says, by brute force: the latest-sent action that has arrived."""
    executed = []
    for t in range(len(actions)):
        arrived = [i for i in range(t + 1) if i + delays[i] <= t]
        executed.append(actions[max(arrived)] if arrived else initial)
    return executed


@pytest.mark.parametrize("k", [0, 1, 4])
def test_a_constant_delay_is_the_classic_constant_delay_mdp(k):
    env = ActionDelay(Echo(), Constant(k), initial_action=7)
    env.reset(seed=0)
    sent = list(range(10, 30))
    infos = [env.step(a)[-1] for a in sent]
    assert env.unwrapped.executed == [7] * k + sent[: len(sent) - k]
    assert [i["executed_action_step"] for i in infos] == [-1] * k + list(range(len(sent) - k))
    assert {i["drawn_action_delay"] for i in infos} == {k}
    env.reset()  # a new episode: the initial action again until the first arrives
    env.step(40)
    assert env.unwrapped.executed[-1] == (40 if k == 0 else 7)


@pytest.mark.parametrize(
    "delay", [Poisson(3.0), Geometric(0.3), Uniform(0, 9), Empirical([0.3, 0, 0.1, 0.6])]
)
def test_random_delays_execute_the_latest_sent_action_that_has_arrived(delay):
    rng = np.random.default_rng(0)
    delays = delay.sample(rng, 400).tolist()
    actions = rng.integers(0, 50, 400).tolist()
    env = ActionDelay(Echo(), ScriptedDelay(delays), initial_action=3)
    env.reset(seed=0)
    infos = [env.step(a)[-1] for a in actions]
    expected = reference(actions, delays, 3)
    assert env.unwrapped.executed == expected == [i["executed_action"] for i in infos]
    assert [i["drawn_action_delay"] for i in infos] == delays
    stale = sum(  # actions overtaken in transit by a later-sent one: never executed
        any(j > i and j + delays[j] <= i + delays[i] for j in range(i + 1, min(400, i + 12)))
        for i in range(390)
    )
    if delay.support_max != 0 and not isinstance(delay, Empirical):
        assert stale > 20  # the out-of-order case happened, often


def test_out_of_order_arrivals_by_hand():
    env = ActionDelay(Echo(), ScriptedDelay([3, 0, 5, 0, 0, 0]), initial_action=9)
    env.reset()
    steps = [env.step(a)[-1] for a in (0, 1, 2, 3, 4, 5)]
    # a0 (due at 3) is overtaken by a1 (at once); a2 (due at 7) by a3, a4, a5
    assert env.unwrapped.executed == [9, 1, 1, 3, 4, 5]
    assert [s["executed_action_step"] for s in steps] == [-1, 1, 1, 3, 4, 5]


def test_seeded_resets_draw_the_same_delays_and_max_delay_clips():
    env = ActionDelay(Echo(), Poisson(5.0), max_delay=6)
    runs = []
    for _ in range(2):
        env.reset(seed=11)
        runs.append([env.step(a % 50)[-1]["drawn_action_delay"] for a in range(100)])
    assert runs[0] == runs[1] and max(runs[0]) == 6
    env.reset(seed=12)
    assert [env.step(a % 50)[-1]["drawn_action_delay"] for a in range(100)] != runs[0]


def test_memory_follows_what_is_in_transit():
    line = ActionLine(0)
    rng = np.random.default_rng(1)
    most = 0
    for t in range(20_000):
        line.send(t, int(rng.integers(0, 1000)))
        most = max(most, line.in_transit)
    assert most <= 1000  # never more than one per step of the longest transit


def test_defaults_and_bad_input():
    assert neutral_action(gym.spaces.Discrete(4, start=2)) == 2
    np.testing.assert_array_equal(neutral_action(gym.spaces.Box(1.0, 2.0, (2,))), [1.0, 1.0])
    np.testing.assert_array_equal(neutral_action(gym.spaces.Box(-1.0, 1.0, (3,))), [0, 0, 0])
    np.testing.assert_array_equal(neutral_action(gym.spaces.MultiDiscrete([3, 4])), [0, 0])
    env = ActionDelay(Echo(), 2.0)
    assert env.initial_action == 0 and env.delay == Poisson(2.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be an action of Discrete\(50\), got 50"):
        env.step(50)
    with pytest.raises(ValueError, match=r"initial_action must be an action of Discrete\(50\)"):
        ActionDelay(Echo(), 2.0, initial_action=-1)
    nested = gym.spaces.Dict({"a": gym.spaces.Tuple((gym.spaces.Discrete(2, start=1),))})
    assert neutral_action(nested) == {"a": (1,)}
    text_env = gym.make("Blackjack-v1")
    text_env.action_space = gym.spaces.Tuple((gym.spaces.Text(3),))
    with pytest.raises(
        ValueError, match="initial_action must be given for an action space of type Text"
    ):
        ActionDelay(text_env, 2.0)
    with pytest.raises(TypeError, match="max_delay"):
        ActionDelay(Echo(), 2.0, max_delay=2.5)
    with pytest.raises(ValueError, match="delay"):
        ActionDelay(Echo(), -1.0)


def test_box_actions_are_copied_when_sent():
    env = ActionDelay(gym.make("Pendulum-v1"), Constant(1))
    env.reset(seed=0)
    action = np.array([1.5], dtype=np.float32)
    first = env.step(action)[-1]
    action[0] = -2.0  # the caller reuses its array: the action in transit must not change
    second = env.step(action)[-1]
    np.testing.assert_array_equal(first["executed_action"], [0.0])
    np.testing.assert_array_equal(second["executed_action"], [1.5])

"""ActionDelay and VectorActionDelay share no object with their callers or their inner env.

An action in transit, ``initial_action`` and ``info["executed_action"]`` must not change when the
caller reuses its action object, writes into what ``info`` reports, or when the inner env edits
the action it is given in place: for every space, ``Dict`` and ``Tuple`` (nested) included.
"""

from __future__ import annotations

import copy
import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from support import same, scribble

from delayed_rl.delays import Constant, Poisson
from delayed_rl.wrappers import ActionDelay, VectorActionDelay

SPACES = {
    "discrete": spaces.Discrete(5),
    "box": spaces.Box(-1.0, 1.0, (2,), dtype=np.float32),
    "multi-discrete": spaces.MultiDiscrete([3, 4]),
    "multi-binary": spaces.MultiBinary(3),
    "dict": spaces.Dict(
        {"a": spaces.Discrete(3), "b": spaces.Box(0.0, 1.0, (2,), dtype=np.float64)}
    ),
    "tuple": spaces.Tuple((spaces.Box(-2.0, 2.0, (3,)), spaces.Discrete(2))),
    "nested": spaces.Dict(
        {
            "arm": spaces.Tuple((spaces.Box(0.0, 1.0, (2,)), spaces.MultiBinary(2))),
            "grip": spaces.Dict({"force": spaces.Box(0.0, 5.0, (1,))}),
        }
    ),
}


class Editor(gym.Env):
    """Records a deep copy of each action it executes, then scribbles over the action."""

    def __init__(self, action_space: gym.Space):
        self.action_space = action_space
        self.observation_space = spaces.Discrete(1)
        self.executed: list = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        self.executed.append(copy.deepcopy(action))
        scribble(action)
        return 0, 0.0, False, False, {}


@pytest.mark.parametrize("name", list(SPACES))
@pytest.mark.parametrize("delay", [Constant(0), Constant(2), Poisson(1.5)], ids=str)
def test_what_is_sent_executes_as_it_was_sent(name: str, delay) -> None:
    space = SPACES[name]
    space.seed(1)
    initial = space.sample()
    env = ActionDelay(Editor(space), delay, initial_action=copy.deepcopy(initial))
    env.reset(seed=0)
    sent, reported = [], []
    for _ in range(12):
        action = space.sample()
        sent.append(copy.deepcopy(action))
        info = env.step(action)[-1]
        reported.append((copy.deepcopy(info["executed_action"]), info["executed_action_step"]))
        scribble(action)  # the caller reuses its action object
        scribble(info["executed_action"])  # and writes into what info reports
    executed = env.unwrapped.executed
    for (report, step), ran in zip(reported, executed, strict=True):
        expected = initial if step == -1 else sent[step]
        assert same(ran, expected) and same(report, expected)
    assert same(env.initial_action, initial)
    env.reset()
    info = env.step(space.sample())[-1]
    if info["executed_action_step"] == -1:  # the next episode starts on the same initial action
        assert same(env.unwrapped.executed[-1], initial)


def test_the_initial_action_survives_an_env_that_edits_it_and_a_caller_that_writes_info() -> None:
    space = spaces.Box(0.0, 1.0, (2,), dtype=np.float32)
    env = ActionDelay(Editor(space), Constant(3), initial_action=np.full(2, 0.5, np.float32))
    for episode in range(3):
        env.reset(seed=episode)
        info = env.step(np.zeros(2, np.float32))[-1]
        info["executed_action"] += 0.25
        assert env.unwrapped.executed[-1].tolist() == [0.5, 0.5]
    assert env.initial_action.tolist() == [0.5, 0.5]


def test_a_dict_action_changed_after_step_does_not_change_what_executes_later() -> None:
    space = SPACES["dict"]
    env = ActionDelay(Editor(space), Constant(2), initial_action={"a": 0, "b": np.zeros(2)})
    env.reset(seed=0)
    action = {"a": 1, "b": np.array([0.1, 0.2])}
    env.step(action)
    action["b"][:] = 0.9
    action["a"] = 2
    env.step({"a": 0, "b": np.zeros(2)})
    info = env.step({"a": 0, "b": np.zeros(2)})[-1]
    assert info["executed_action"]["a"] == 1
    assert info["executed_action"]["b"].tolist() == [0.1, 0.2]


@pytest.mark.parametrize("name", ["box", "dict", "tuple", "nested", "multi-binary"])
@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.NEXT_STEP, "same-step"])
def test_the_vector_wrapper_copies_as_the_single_one_does(name: str, mode) -> None:
    space = SPACES[name]
    mode = gym.vector.AutoresetMode.SAME_STEP if mode == "same-step" else mode
    inner = gym.vector.SyncVectorEnv([lambda: Editor(space)] * 3, autoreset_mode=mode, copy=True)
    space.seed(2)
    initial = space.sample()
    env = VectorActionDelay(inner, Constant(1), initial_action=copy.deepcopy(initial))
    env.reset(seed=0)
    batches, reports = [], []
    for _ in range(6):
        actions = env.action_space.sample()
        batches.append(copy.deepcopy(actions))
        info = env.step(actions)[-1]
        reports.append(copy.deepcopy(info["executed_action"]))
        scribble(actions)
        scribble(info["executed_action"])
    single = inner.single_action_space
    for t, report in enumerate(reports):
        rows = list(gym.vector.utils.iterate(env.action_space, report))
        for i, row in enumerate(rows):
            expected = (
                initial
                if t == 0
                else list(gym.vector.utils.iterate(env.action_space, batches[t - 1]))[i]
            )
            assert single.contains(row)
            assert same(row, expected)
            assert same(inner.envs[i].executed[t], expected)
    assert same(env.initial_action, initial)


def test_vector_dict_actions_of_the_right_form_are_accepted_and_others_named() -> None:
    space = SPACES["dict"]
    env = VectorActionDelay(gym.vector.SyncVectorEnv([lambda: Editor(space)] * 2), Constant(0))
    env.reset(seed=0)
    env.step({"a": np.array([0, 2]), "b": np.zeros((2, 2))})
    assert [e.executed[-1]["a"] for e in env.env.envs] == [0, 2]
    with pytest.raises(ValueError, match=r"actions\[1\] must be an action of Dict"):
        env.step({"a": np.array([0, 7]), "b": np.zeros((2, 2))})
    with pytest.raises((TypeError, ValueError), match=r"^actions must be a batch of 2 actions"):
        env.step({"a": np.array([0, 1])})


@pytest.mark.parametrize(
    "initial", [np.array([0.5], np.float32), [0.5], (np.float64(0.5),)], ids=repr
)
def test_a_numpy_initial_action_and_numpy_delays_give_a_json_spec(initial) -> None:
    env = ActionDelay(
        gym.make("Pendulum-v1"), np.float32(2.0), initial_action=initial, max_delay=np.int64(4)
    )
    text = env.spec.to_json()
    rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(text))
    assert rebuilt.spec.to_json() == text
    rebuilt.reset(seed=0)
    info = rebuilt.step(np.zeros(1, np.float32))[-1]
    assert info["executed_action_step"] == -1  # Poisson(2) clipped at 4: seed 0 draws a delay
    assert info["executed_action"].tolist() == [0.5]


@pytest.mark.parametrize("kwarg", ["reward_delay", "observation_delay", "action_delay"])
@pytest.mark.parametrize("value", [np.float32(2.0), np.int64(3), np.float64(0.5)], ids=repr)
def test_numpy_delays_given_to_make_give_a_json_spec(kwarg: str, value) -> None:
    env = gym.make("delayed_rl/GridWorld-3x3-v0", **{kwarg: value})
    text = env.spec.to_json()
    assert json.loads(text)["kwargs"][kwarg] == float(value)
    rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(text))
    assert rebuilt.spec.to_json() == text


@pytest.mark.parametrize(
    "space",
    [
        spaces.Graph(spaces.Box(0.0, 1.0, (2,)), spaces.Discrete(3)),
        spaces.Sequence(spaces.Box(0.0, 1.0, (2,))),
        spaces.OneOf((spaces.Discrete(2), spaces.Box(0.0, 1.0, (2,)))),
        spaces.Text(5),
    ],
    ids=lambda space: type(space).__name__,
)
def test_other_spaces_pass_through_as_copies_of_their_own_kind(space) -> None:
    space.seed(0)
    initial, action = space.sample(), space.sample()
    env = ActionDelay(Editor(space), Constant(1), initial_action=initial)
    env.reset(seed=0)
    first = env.step(action)[-1]["executed_action"]
    second = env.step(space.sample())[-1]["executed_action"]
    assert type(first) is type(initial) and space.contains(first)
    assert space.contains(second)
    assert str(second) == str(action)  # every space here prints its sample's values


@pytest.mark.parametrize(
    ("wrapper", "delay"),
    [
        ("RewardDelay", {"type": "Constant", "k": np.int64(2)}),
        ("ObservationDelay", {"type": "Geometric", "p": np.float32(0.5)}),
        ("ActionDelay", {"type": "Empirical", "pmf": np.array([0.25, 0.75])}),
    ],
)
def test_a_description_holding_numpy_values_gives_a_json_spec(wrapper, delay) -> None:
    from delayed_rl import wrappers

    env = getattr(wrappers, wrapper)(gym.make("CartPole-v1"), delay)
    text = env.spec.to_json()
    rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(text))
    assert rebuilt.spec.to_json() == text

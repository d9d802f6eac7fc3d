"""DiscreteObservation: discrete parts numbered as one Discrete index (Blackjack for the agents)."""

from __future__ import annotations

import itertools
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from delayed_rl.agents import MultipleModelQLearning, QLearning
from delayed_rl.compiled import NotCompilable
from delayed_rl.wrappers import DiscreteObservation, wrap_delays


class _Parts(gym.Env):
    """An env that observes whatever it is told to, in a given space."""

    def __init__(self, space, observations=()):
        self.observation_space = space
        self.action_space = spaces.Discrete(2)
        self.observations = list(observations)

    def reset(self, *, seed=None, options=None):
        return self.observations[0] if self.observations else self.observation_space.sample(), {}

    def step(self, action):
        return self.observations.pop(0), 0.0, False, False, {}


@pytest.mark.parametrize(
    "space",
    [
        spaces.Tuple((spaces.Discrete(32), spaces.Discrete(11), spaces.Discrete(2))),  # Blackjack
        spaces.Tuple(
            (spaces.Discrete(3, start=-1), spaces.Discrete(1), spaces.Discrete(4, start=5))
        ),
        spaces.MultiDiscrete([2, 5, 3]),
        spaces.MultiDiscrete([4, 3], start=[-2, 10]),
        spaces.Tuple((spaces.Discrete(7),)),
    ],  # fmt: skip
)
def test_every_combination_gets_its_own_index_in_c_order_and_decodes_back(space):
    env = DiscreteObservation(_Parts(space))
    sizes = [p.n for p in space.spaces] if isinstance(space, spaces.Tuple) else space.nvec
    starts = [p.start for p in space.spaces] if isinstance(space, spaces.Tuple) else space.start
    assert env.observation_space == spaces.Discrete(int(np.prod(sizes)))
    ranges = [range(int(s), int(s) + int(n)) for n, s in zip(sizes, starts, strict=True)]
    indices = []
    for combination in itertools.product(*ranges):
        index = env.observation(combination)
        expected = np.ravel_multi_index(np.subtract(combination, starts), sizes)
        assert index == expected and env.decode(index) == combination
        indices.append(index)
    assert sorted(indices) == list(range(env.observation_space.n))


def test_numpy_parts_and_arrays_are_numbered_like_ints():
    env = DiscreteObservation(_Parts(spaces.MultiDiscrete([2, 5, 3])))
    assert env.observation(np.array([1, 4, 2])) == env.observation((1, 4, 2)) == 29
    assert env.observation((np.int64(1), np.int32(4), 2)) == 29


@pytest.mark.parametrize(
    "space",
    [
        spaces.Box(0, 1, (2,)),
        spaces.Discrete(4),
        spaces.Tuple(()),
        spaces.Tuple((spaces.Discrete(2), spaces.Box(0, 1, (1,)))),
        spaces.MultiDiscrete([[2, 3], [4, 5]]),
    ],  # fmt: skip
)
def test_other_spaces_are_refused_naming_what_is_allowed(space):
    with pytest.raises(
        TypeError, match="Tuple of Discrete spaces or a one-dimensional MultiDiscrete"
    ):
        DiscreteObservation(_Parts(space))


@pytest.mark.parametrize(
    "bad", [(1, 2), (1, 2, 3, 4), 5, (0, 11, 0), (32, 0, 0), (1.0, 2, 0), (1, True, 0), "abc"]
)
def test_an_observation_outside_the_space_is_refused_not_renumbered(bad):
    space = spaces.Tuple((spaces.Discrete(32), spaces.Discrete(11), spaces.Discrete(2)))
    env = DiscreteObservation(_Parts(space))
    with pytest.raises(ValueError, match="observation"):
        env.observation(bad)


def test_decode_refuses_what_is_not_an_index():
    env = DiscreteObservation(_Parts(spaces.MultiDiscrete([2, 3])))
    with pytest.raises(TypeError, match="index must be an integer"):
        env.decode(1.0)
    for bad in (-1, 6):
        with pytest.raises(ValueError, match=r"index must be in 0\.\.5"):
            env.decode(bad)


@pytest.mark.statistical
def test_blackjack_learns_under_delayed_rewards_on_the_python_path():
    """Blackjack's Tuple observation, numbered, under Poisson(2) delays: every reward arrives."""
    env = DiscreteObservation(wrap_delays(gym.make("Blackjack-v1"), reward_delay=2))
    agent = QLearning(env, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Blackjack rewards only at an episode's end: the trap
        agent.learn(20_000, log_interval=None, record=True)
    log = agent.training_log
    assert agent.last_learn_path == "python"
    assert log["obs"].min() >= 0 and log["obs"].max() < 704
    # "flush": each episode's rewards arrive by its end, so the streams sum alike
    assert log["reward"].sum() == pytest.approx(log["undelayed_reward"].sum())
    assert np.abs(log["undelayed_reward"]).sum() > 1_000  # hands were won and lost
    assert len(np.unique(log["obs"])) > 100  # many (sum, dealer card, ace) states were seen
    with pytest.raises(NotCompilable, match="DiscreteObservation"):
        MultipleModelQLearning(env, max_delay_estimate=4, seed=0).learn(10, compiled=True)

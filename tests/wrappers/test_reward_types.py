"""What the reward-delay wrappers accept as an inner env's reward, and how they refuse the rest.

A reward is a real scalar. Anything else is refused at the step that returns it, with a message
that names the reward, shows its value and says what is allowed: never a bare ``float()`` or
numpy error.
"""

from __future__ import annotations

from fractions import Fraction

import gymnasium as gym
import numpy as np
import pytest
from support import NeverEndingEnv

from delayed_rl.delays import Constant
from delayed_rl.wrappers import PoissonRewardDelay, RewardDelay, VectorRewardDelay

ACCEPTED = [1, 1.5, -2, np.float32(0.5), np.int64(2), np.uint8(3), np.array(2.0), Fraction(1, 2)]
WRONG_TYPE = [
    None,
    1 + 0j,
    np.complex128(1.0),
    [1.0],
    (1.0,),
    np.array([1.0]),
    np.array([1.0, 2.0]),
    np.array([[1.0]]),
    "1",
    True,
    np.bool_(False),
    object(),
]


@pytest.mark.parametrize("reward", ACCEPTED, ids=repr)
def test_real_scalars_are_summed_as_float64(reward) -> None:
    env = RewardDelay(NeverEndingEnv(reward), Constant(1))
    env.reset(seed=0)
    assert env.step(0)[1] == 0.0
    delivered = env.step(0)[1]
    assert type(delivered) is float and delivered == float(reward)


@pytest.mark.parametrize("reward", WRONG_TYPE, ids=repr)
@pytest.mark.parametrize("wrapper", [RewardDelay, PoissonRewardDelay])
def test_a_reward_that_is_not_a_real_scalar_is_a_type_error_naming_it(wrapper, reward) -> None:
    env = wrapper(NeverEndingEnv(1.0), Constant(1) if wrapper is RewardDelay else 1.0)
    env.reset(seed=0)
    first = env.step(0)[1]
    env.unwrapped.reward = reward
    with pytest.raises(TypeError, match=r"^reward must be a real scalar .*got .*episode step 1"):
        env.step(0)
    env.unwrapped.reward = 2.0  # nothing was scheduled for the refused step, no clock step taken
    _, second, _, _, info = env.step(0)
    assert first + second + info["pending_reward"] == 3.0


@pytest.mark.parametrize("reward", [10**400, -(10**309)], ids=["1e400", "-1e309"])
def test_an_int_beyond_float64_is_a_value_error_naming_it(reward) -> None:
    env = RewardDelay(NeverEndingEnv(reward), Constant(0))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^reward must be a real number within float64's range"):
        env.step(0)


def test_a_reward_too_long_to_print_is_shown_cut() -> None:
    env = RewardDelay(NeverEndingEnv(list(range(10_000))), Constant(0))
    env.reset(seed=0)
    with pytest.raises(TypeError) as caught:
        env.step(0)
    assert len(str(caught.value)) < 600


def _vector(rewards, n=2):
    class Scripted(gym.vector.VectorEnv):
        def __init__(self):
            self.num_envs = n
            self.single_action_space = gym.spaces.Discrete(1)
            self.single_observation_space = gym.spaces.Discrete(1)
            self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
            self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
            self.metadata = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}
            self.rewards = rewards

        def reset(self, *, seed=None, options=None):
            return np.zeros(n, dtype=np.int64), {}

        def step(self, actions):
            done = np.zeros(n, dtype=bool)
            return np.zeros(n, dtype=np.int64), self.rewards, done, done, {}

    return VectorRewardDelay(Scripted(), Constant(0))


@pytest.mark.parametrize(
    "rewards",
    [np.array([1, 2]), np.array([0.5, 1.5], np.float32), [1, 2.5], (np.float64(1), 2)],
    ids=repr,
)
def test_vector_rewards_in_any_sequence_form_are_accepted(rewards) -> None:
    env = _vector(rewards)
    env.reset(seed=0)
    np.testing.assert_array_equal(env.step(np.zeros(2))[1], np.asarray(rewards, dtype=float))


@pytest.mark.parametrize(
    ("rewards", "exc", "match"),
    [
        (None, TypeError, r"^rewards must be a 1-D array of 2 real numbers .*NoneType"),
        ([None, 1.0], TypeError, r"^rewards\[0\] must be a real scalar"),
        ([1.0, 1 + 0j], TypeError, r"^rewards\[1\] must be a real scalar"),
        (np.array([1 + 0j, 1]), TypeError, r"^rewards\[0\] must be a real scalar"),
        (np.array([True, False]), TypeError, r"^rewards\[0\] must be a real scalar"),
        ([[1.0], [2.0]], TypeError, r"^rewards\[0\] must be a real scalar"),
        (np.ones((2, 1)), ValueError, r"^rewards must be .*got an array of shape \(2, 1\)"),
        (np.ones(3), ValueError, r"^rewards must be .*got an array of shape \(3,\)"),
        ([1.0], ValueError, r"^rewards must be .*got 1"),
        ([10**400, 1], ValueError, r"^rewards\[0\] must be a real number within float64"),
        (2.0, TypeError, r"^rewards must be a 1-D array"),
    ],
    ids=repr,
)
def test_vector_rewards_of_the_wrong_form_are_refused_naming_the_entry(rewards, exc, match) -> None:
    env = _vector(rewards)
    env.reset(seed=0)
    with pytest.raises(exc, match=match):
        env.step(np.zeros(2))

"""ObservationDelay: at step t the agent sees o_{max(0, t+1-d_t)} of the current episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from support import ScriptedDelay

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.wrappers import ObservationDelay
from delayed_rl.wrappers._delay_draws import delay_rng

EPISODE_STRIDE = 100_000


class CounterEnv(gym.Env):
    """Observation ``o_t = episode * 100000 + t`` (t = steps taken this episode); reward = t."""

    observation_space = gym.spaces.Discrete(10 * EPISODE_STRIDE)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, episode_length: int | None = None):
        self.episode_length = episode_length
        self.episode, self.t = -1, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode += 1
        self.t = 0
        return self.episode * EPISODE_STRIDE, {"t": 0}

    def step(self, action):
        self.t += 1
        end = self.episode_length is not None and self.t >= self.episode_length
        return self.episode * EPISODE_STRIDE + self.t, float(self.t), end, False, {"t": self.t}


@pytest.mark.parametrize("lam", [0.5, 3, 13.7])
def test_observation_is_the_delayed_one(lam: float) -> None:
    seed = 17
    raw = Poisson(lam).sample(delay_rng(seed, "observation"), 1024)  # the wrapper's stream
    env = ObservationDelay(CounterEnv(episode_length=400), lam)
    obs, info = env.reset(seed=seed)
    assert obs == 0 and info["observation_age"] == 0
    for t in range(400):
        obs, reward, terminated, truncated, info = env.step(0)
        d = int(raw[t])
        assert obs == max(0, t + 1 - d), t
        assert info["observation_age"] == min(d, t + 1)
        assert reward == float(t + 1) and info["t"] == t + 1  # rewards and info untouched
        assert terminated == (t == 399) and truncated is False
    assert raw[:400].max() > 0  # the test exercised real delays


def test_constant_delay_and_clipping_to_first_observation() -> None:
    env = ObservationDelay(CounterEnv(), Constant(3))
    env.reset(seed=0)
    got = [env.step(0) for _ in range(8)]
    assert [g[0] for g in got] == [0, 0, 0, 1, 2, 3, 4, 5]
    assert [g[4]["observation_age"] for g in got] == [1, 2, 3, 3, 3, 3, 3, 3]


def test_new_episode_clips_to_its_own_first_observation() -> None:
    env = ObservationDelay(CounterEnv(episode_length=10), Constant(4))
    env.reset(seed=0)
    for _ in range(10):
        env.step(0)
    obs, info = env.reset()
    assert obs == EPISODE_STRIDE and info["observation_age"] == 0  # reset obs never delayed
    got = [env.step(0)[0] for _ in range(6)]
    assert got == [EPISODE_STRIDE] * 4 + [EPISODE_STRIDE + 1, EPISODE_STRIDE + 2]


def test_zero_delay_is_the_identity() -> None:
    env = ObservationDelay(CounterEnv(), 0)
    env.reset(seed=0)
    assert [env.step(0)[0] for _ in range(50)] == list(range(1, 51))


def test_scripted_out_of_order_views() -> None:
    """Observations may go back in time: delays 0, 2, 0, 3, 1 show o1, o0, o3, o1, o4."""
    env = ObservationDelay(CounterEnv(), ScriptedDelay([0, 2, 0, 3, 1]))
    env.reset(seed=0)
    assert [env.step(0)[0] for _ in range(5)] == [1, 0, 3, 1, 4]


def test_max_delay_clips_delays() -> None:
    env = ObservationDelay(CounterEnv(), Uniform(0, 50), max_delay=2)
    env.reset(seed=1)
    for t in range(300):
        obs, *_, info = env.step(0)
        assert info["observation_age"] <= 2
        assert obs == t + 1 - info["observation_age"]


def test_delay_beyond_history_uses_oldest_kept_observation() -> None:
    delay = ScriptedDelay([0] * 200 + [10_000], mean=1.0)
    env = ObservationDelay(CounterEnv(), delay)
    history = env.history
    assert history == int(1.0 + 10.0 + 20.0) + 1
    env.reset(seed=0)
    for _ in range(200):
        env.step(0)
    obs, *_, info = env.step(0)  # step t = 200 sees o_201 undelayed
    assert info["observation_age"] == history - 1
    assert obs == 201 - (history - 1)


def test_seeded_determinism() -> None:
    def run(seed):
        env = ObservationDelay(CounterEnv(), 4)
        env.reset(seed=seed)
        return [env.step(0)[4]["observation_age"] for _ in range(200)]

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_box_observations_match_an_undelayed_twin() -> None:
    inner, twin = gym.make("Pendulum-v1"), gym.make("Pendulum-v1")
    env = ObservationDelay(inner, 2, max_delay=5)
    assert env.observation_space == inner.observation_space
    obs, _ = env.reset(seed=0)
    raw = [twin.reset(seed=0)[0]]
    np.testing.assert_array_equal(obs, raw[0])
    env.action_space.seed(0)
    for t in range(60):
        action = env.action_space.sample()
        obs, reward, *_, info = env.step(action)
        raw_obs, raw_reward, *_ = twin.step(action)
        raw.append(raw_obs)
        assert reward == raw_reward
        np.testing.assert_array_equal(obs, raw[t + 1 - info["observation_age"]])


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"delay": -1}, ValueError, "^delay must be a number in \\[0, "),
        ({"delay": float("nan")}, ValueError, "^delay must be a number in \\[0, "),
        ({"delay": "3"}, TypeError, "delay"),
        ({"delay": 2, "max_delay": -1}, ValueError, "max_delay"),
        ({"delay": 2, "max_delay": 1.5}, TypeError, "max_delay"),
        ({"delay": 2, "max_delay": "3"}, TypeError, "max_delay"),
        ({"delay": True}, TypeError, "delay"),
        ({"delay": Constant(1), "max_delay": -2}, ValueError, "max_delay"),
    ],
)
def test_invalid_arguments(kwargs, exc, name) -> None:
    with pytest.raises(exc, match=name):
        ObservationDelay(CounterEnv(), **kwargs)


def test_history_reaches_the_delay_bound() -> None:
    """``max_delay + 1`` observations, else the support's end, else mean + 10·√mean + 20."""
    assert ObservationDelay(CounterEnv(), Poisson(9.0), max_delay=4).history == 5
    assert ObservationDelay(CounterEnv(), Uniform(1, 6)).history == 7
    assert ObservationDelay(CounterEnv(), Poisson(9.0)).history == 9 + 30 + 20 + 1


def test_observations_are_fresh_objects_check_env_passes() -> None:
    from gymnasium.utils.env_checker import check_env

    check_env(ObservationDelay(gym.make("CartPole-v1"), Constant(3)), skip_render_check=True)


def test_mutating_a_returned_observation_changes_no_other() -> None:
    env = ObservationDelay(gym.make("CartPole-v1"), Constant(3))
    o1, _ = env.reset(seed=0)
    o2 = env.step(0)[0]  # the reset observation again (the delay reaches back past it)
    kept = o2.copy()
    o1 *= 0
    np.testing.assert_array_equal(o2, kept)
    o3 = env.step(0)[0]
    np.testing.assert_array_equal(o3, kept)
    o3 += 1
    np.testing.assert_array_equal(env.step(0)[0], kept)

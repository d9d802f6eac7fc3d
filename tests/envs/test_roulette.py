"""RouletteEnv: payout values and frequencies (binomial tolerances), seeding, pickling.

Frequencies are checked at fixed seeds to within 4 binomial standard errors (a two-sided
probability of about 6e-5 that a correct wheel fails).
"""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.envs.roulette import BET_13, BET_EVEN, RouletteEnv

N_SPINS = 38_000
N_SE = 4.0


def spin(action: int, seed: int) -> tuple[np.ndarray, list[str]]:
    env = RouletteEnv()
    env.reset(seed=seed)
    rewards, pockets = [], []
    for _ in range(N_SPINS):
        obs, reward, terminated, truncated, info = env.step(action)
        assert obs == 0 and not terminated and not truncated
        rewards.append(reward)
        pockets.append(info["pocket"])
    return np.array(rewards), pockets


def assert_binomial(count: int, n: int, p: float) -> None:
    se = math.sqrt(n * p * (1 - p))
    assert abs(count - n * p) <= N_SE * se, (count, n * p, se)


def test_bet_even_payouts_and_frequency() -> None:
    rewards, pockets = spin(BET_EVEN, seed=0)
    assert set(rewards.tolist()) == {1.0, -1.0}
    assert_binomial(int((rewards == 1.0).sum()), N_SPINS, 18 / 38)
    # a win is exactly an even pocket from 2 to 36 (0 and 00 lose)
    for reward, pocket in zip(rewards, pockets, strict=True):
        assert (reward == 1.0) == (pocket not in ("0", "00") and int(pocket) % 2 == 0)
    assert rewards.mean() == pytest.approx(-2 / 38, abs=N_SE * rewards.std() / math.sqrt(N_SPINS))


def test_bet_13_payouts_and_frequency() -> None:
    rewards, pockets = spin(BET_13, seed=1)
    assert set(rewards.tolist()) == {35.0, -1.0}
    assert_binomial(int((rewards == 35.0).sum()), N_SPINS, 1 / 38)
    assert all((r == 35.0) == (p == "13") for r, p in zip(rewards, pockets, strict=True))


def test_pockets_are_uniform_over_the_american_wheel() -> None:
    _, pockets = spin(BET_EVEN, seed=2)
    names = [str(k) for k in range(1, 37)] + ["0", "00"]
    assert set(pockets) == set(names)
    counts = np.array([pockets.count(name) for name in names])
    from scipy import stats

    assert stats.chisquare(counts).pvalue > 1e-3


def test_tabular_model() -> None:
    env = RouletteEnv()
    for action in (BET_EVEN, BET_13):
        outcomes = env.P[0][action]
        assert sum(p for p, *_ in outcomes) == pytest.approx(1.0)
        assert sum(p * r for p, _, r, _ in outcomes) == pytest.approx(-2 / 38)
        assert all(s == 0 and not done for _, s, _, done in outcomes)


def test_seeded_determinism() -> None:
    def run(seed):
        env = RouletteEnv()
        env.reset(seed=seed)
        return [env.step(i % 2)[1] for i in range(500)]

    assert run(5) == run(5)
    assert run(5) != run(6)


def test_check_env_registered() -> None:
    env = gym.make("delayed_rl/Roulette-v0")
    check_env(env.unwrapped)
    assert env.observation_space == gym.spaces.Discrete(1)
    assert env.action_space == gym.spaces.Discrete(2)


def test_max_steps_truncates_and_flushes() -> None:
    env = gym.make("delayed_rl/Roulette-v0", reward_delay=20, max_steps=30)
    env.reset(seed=0)
    delivered = undelayed = 0.0
    for t in range(1, 31):
        _, reward, terminated, truncated, info = env.step(t % 2)
        delivered += reward
        undelayed += info["undelayed_reward"]
        assert truncated == (t == 30) and not terminated
    assert delivered == pytest.approx(undelayed, abs=1e-12)


def test_pickle_round_trip_mid_episode() -> None:
    env = gym.make("delayed_rl/Roulette-v0", reward_delay=5, max_steps=500)
    env.reset(seed=3)
    for i in range(50):
        env.step(i % 2)
    clone = pickle.loads(pickle.dumps(env))
    a = [env.step(i % 2) for i in range(100)]
    b = [clone.step(i % 2) for i in range(100)]
    assert a == b
    assert len({x[1] for x in a}) > 3  # real randomness was replayed


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"max_steps": 0}, ValueError, "max_steps"),
        ({"max_steps": 1.5}, TypeError, "max_steps"),
        ({"render_mode": "ansi"}, ValueError, "render_mode"),
    ],
)
def test_invalid_arguments(kwargs, exc, name) -> None:
    with pytest.raises(exc, match=name):
        RouletteEnv(**kwargs)


@pytest.mark.parametrize(
    ("name", "wrong_type", "bad_value"),
    [("max_steps", "5", -1), ("render_mode", 1, "human")],
)
def test_each_argument_refuses_a_wrong_type_and_a_bad_value(name, wrong_type, bad_value) -> None:
    with pytest.raises(TypeError, match=name):
        RouletteEnv(**{name: wrong_type})
    with pytest.raises(ValueError, match=name):
        RouletteEnv(**{name: bad_value})


def test_invalid_action() -> None:
    env = RouletteEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(2)

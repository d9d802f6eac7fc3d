"""stable-baselines3: training through the delay wrappers, and the VecRewardDelay twin."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np
import pytest
from support import flush_trap_warnings

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.wrappers import EPISODE_END_MODES, PoissonRewardDelay, reward_delay
from delayed_rl.wrappers.reward_delay import FLUSH_WATCH_STEPS

if TYPE_CHECKING:
    from delayed_rl.wrappers.sb3 import VecRewardDelay

# Every test here imports stable-baselines3 (so torch, over a second), in its body: not at
# collection.
pytestmark = pytest.mark.sb3


class RandomEndEnv(gym.Env):
    """Random real rewards, episodes that end at random times (all from ``np_random``)."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, p_end: float = 0.1, reward=None):
        self.p_end, self.reward = p_end, reward

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action):
        reward = float(self.np_random.normal() + action) if self.reward is None else self.reward
        u = float(self.np_random.random())
        terminated = u < self.p_end / 2
        truncated = not terminated and u < self.p_end
        return np.zeros(2, np.float32), reward, terminated, truncated, {}


def test_importing_delayed_rl_does_not_import_torch_or_sb3() -> None:
    code = (
        "import delayed_rl, delayed_rl.wrappers, delayed_rl.delays, delayed_rl.envs, sys; "
        "bad = [m for m in ('torch', 'stable_baselines3') if m in sys.modules]; "
        "assert not bad, bad"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("on_episode_end", EPISODE_END_MODES)
@pytest.mark.parametrize("delay", [Poisson(0), Poisson(3.5), Constant(2), Uniform(0, 8)], ids=repr)
def test_vec_reward_delay_conservation_and_info(on_episode_end, delay) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.wrappers.reference import ReferenceRewardDelay
    from delayed_rl.wrappers.sb3 import VecRewardDelay

    n_envs = 3
    venv = make_vec_env(RandomEndEnv, n_envs=n_envs, seed=4)
    twin = make_vec_env(RandomEndEnv, n_envs=n_envs, seed=4)
    env = VecRewardDelay(venv, delay, on_episode_end=on_episode_end, seed=9)
    env.reset()
    twin.reset()
    refs = [ReferenceRewardDelay(on_episode_end) for _ in range(n_envs)]  # one per sub-env
    delivered_sum, undelayed_sum, dropped_sum = np.zeros(n_envs), np.zeros(n_envs), np.zeros(n_envs)
    ep_delivered, ep_undelayed = np.zeros(n_envs), np.zeros(n_envs)
    episodes = 0
    rng = np.random.default_rng(0)
    for _ in range(300):
        actions = rng.integers(2, size=n_envs)
        _, rewards, dones, infos = env.step(actions)
        _, raw, raw_dones, _ = twin.step(actions)
        np.testing.assert_array_equal(dones, raw_dones)
        assert rewards.dtype == np.float32
        for i, info in enumerate(infos):
            assert info["undelayed_reward"] == pytest.approx(float(raw[i]), rel=1e-6)
            d = info["drawn_reward_delay"]
            assert isinstance(d, int) and d >= 0
            if delay.support_max is not None:
                assert d <= delay.support_max
            arrivals, flushed, dropped = refs[i].step(info["undelayed_reward"], d, bool(dones[i]))
            expected = math.fsum(r for _, r in arrivals)
            if dones[i]:
                if on_episode_end == "flush":
                    assert info["flushed_reward"] == pytest.approx(flushed, abs=1e-9)
                elif on_episode_end == "drop":
                    assert info["dropped_reward"] == pytest.approx(dropped, abs=1e-9)
                    dropped_sum[i] += dropped
                else:
                    assert "flushed_reward" not in info and "dropped_reward" not in info
            assert rewards[i] == pytest.approx(expected, rel=1e-6, abs=1e-5)  # float32 output
            assert info["pending_reward"] == pytest.approx(refs[i].pending(), abs=1e-9)
            delivered_sum[i] += rewards[i]
            undelayed_sum[i] += info["undelayed_reward"]
            ep_delivered[i] += rewards[i]
            ep_undelayed[i] += info["undelayed_reward"]
            pending = info["pending_reward"]
            assert delivered_sum[i] + pending + dropped_sum[i] == pytest.approx(
                undelayed_sum[i], abs=1e-4
            )
            if dones[i]:
                episodes += 1
                if on_episode_end == "flush":
                    assert ep_delivered[i] == pytest.approx(ep_undelayed[i], abs=1e-4)
                ep_delivered[i] = ep_undelayed[i] = 0.0
    assert episodes >= 30


def test_vec_reward_delay_seeding() -> None:
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    def delays(seed=None, via_seed_method=False):
        env = VecRewardDelay(
            make_vec_env(RandomEndEnv, n_envs=2, seed=0), 5, seed=None if via_seed_method else seed
        )
        if via_seed_method:
            env.seed(seed)
        env.reset()
        return [
            [info["drawn_reward_delay"] for info in env.step(np.zeros(2, dtype=int))[3]]
            for _ in range(80)
        ]

    assert delays(3) == delays(3)
    assert delays(3) != delays(4)
    assert delays(3, via_seed_method=True) == delays(3, via_seed_method=True)
    assert delays(3, via_seed_method=True) != delays(4, via_seed_method=True)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_vec_reward_delay_non_finite_reward_raises(bad) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(DummyVecEnv([lambda: RandomEndEnv(reward=bad)]), 2, seed=0)
    env.reset()
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.zeros(1, dtype=int))


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"delay": -1}, ValueError, "^delay must be a number in \\[0, "),
        ({"delay": "x"}, TypeError, "delay"),
        ({"delay": 1, "max_delay": -1}, ValueError, "max_delay"),
        ({"delay": 1, "on_episode_end": "nope"}, ValueError, "on_episode_end"),
        ({"delay": 1, "max_delay": "5"}, TypeError, "max_delay"),
        ({"delay": 1, "on_episode_end": 0}, TypeError, "on_episode_end"),
        ({"delay": 1, "seed": "5"}, TypeError, "seed"),
        ({"delay": 1, "seed": 1.0}, TypeError, "seed"),
        ({"delay": 1, "seed": -1}, ValueError, "seed"),
        ({"delay": True}, TypeError, "delay"),
    ],
)
def test_vec_reward_delay_invalid_arguments(kwargs, exc, name) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    with pytest.raises(exc, match=name):
        VecRewardDelay(DummyVecEnv([RandomEndEnv]), **kwargs)


def test_dqn_trains_through_the_gymnasium_wrapper() -> None:
    from stable_baselines3 import DQN

    env = PoissonRewardDelay(gym.make("CartPole-v1"), 5)
    model = DQN("MlpPolicy", env, learning_starts=500, train_freq=16, seed=0, device="cpu")
    model.learn(2000)
    assert model.num_timesteps >= 2000
    # SB3's Monitor sits outside the delay wrapper: with "flush" it still sees the true returns
    returns = [(ep["r"], ep["l"]) for ep in model.ep_info_buffer]
    assert len(returns) >= 10
    assert all(r == pytest.approx(length) for r, length in returns)  # CartPole pays 1 per step


def test_dqn_trains_on_a_registered_env_with_reward_delay() -> None:
    from stable_baselines3 import DQN

    env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2, max_steps=50)
    model = DQN("MlpPolicy", env, learning_starts=100, train_freq=16, seed=0, device="cpu")
    model.learn(1000)
    assert model.num_timesteps >= 1000 and len(model.ep_info_buffer) >= 10
    assert all(ep["l"] == 50 for ep in model.ep_info_buffer)  # max_steps truncation, seen by SB3


def test_ppo_trains_through_vec_reward_delay() -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    venv = DummyVecEnv([lambda: gym.make("CartPole-v1") for _ in range(2)])
    env = VecMonitor(VecRewardDelay(venv, 5, seed=0))
    model = PPO("MlpPolicy", env, n_steps=512, batch_size=256, n_epochs=1, seed=0, device="cpu")
    model.learn(2048)
    assert model.num_timesteps >= 2048
    returns = [(ep["r"], ep["l"]) for ep in model.ep_info_buffer]
    assert len(returns) >= 10
    assert all(r == pytest.approx(length, rel=1e-5) for r, length in returns)


# --- reset infos, per-sub-env seeds, precision ------------------------------------------------


def test_mid_episode_reset_reports_dropped_reward_in_reset_infos() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(DummyVecEnv([lambda: RandomEndEnv(0.0, 1.0)] * 2), Constant(5), seed=0)
    env.reset()
    assert all("dropped_reward" not in info for info in env.reset_infos)  # no episode yet
    for _ in range(3):
        env.step(np.zeros(2, dtype=int))
    with pytest.warns(UserWarning, match="discarded"):
        env.reset()
    assert [info["dropped_reward"] for info in env.reset_infos] == [3.0, 3.0]
    assert [info["pending_reward"] for info in env.reset_infos] == [0.0, 0.0]
    _, _, _, infos = env.step(np.zeros(2, dtype=int))
    assert [info["pending_reward"] for info in infos] == [1.0, 1.0]


def test_mid_episode_reset_with_nothing_pending_reports_zero_without_warning() -> None:
    import warnings

    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(DummyVecEnv([lambda: RandomEndEnv(0.0, 0.0)]), Constant(5), seed=0)
    env.reset()
    env.step(np.zeros(1, dtype=int))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env.reset()
    assert env.reset_infos[0]["dropped_reward"] == 0.0


def test_mid_episode_reset_under_carry_keeps_pending() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(
        DummyVecEnv([lambda: RandomEndEnv(0.0, 1.0)]), Constant(5), on_episode_end="carry", seed=0
    )
    env.reset()
    for _ in range(3):
        env.step(np.zeros(1, dtype=int))
    env.reset()
    assert "dropped_reward" not in env.reset_infos[0]
    assert env.reset_infos[0]["pending_reward"] == 3.0


def sb3_delays(seed=None, n_envs=2, via_seed_method=False, steps=60):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    venv = DummyVecEnv([lambda: RandomEndEnv(0.0, 1.0) for _ in range(n_envs)])
    env = VecRewardDelay(venv, 5, seed=None if via_seed_method else seed)
    if via_seed_method:
        env.seed(seed)
    env.reset()
    return np.array(
        [
            [info["drawn_reward_delay"] for info in env.step(np.zeros(n_envs, int))[3]]
            for _ in range(steps)
        ]
    )


def test_sub_env_i_gets_seed_plus_i_like_sb3_vec_env_seed() -> None:
    from delayed_rl.wrappers import RewardDelay

    for via in (False, True):
        d = sb3_delays(20, n_envs=3, via_seed_method=via)
        for i in range(3):
            single = RewardDelay(RandomEndEnv(0.0, 1.0), 5)
            single.reset(seed=20 + i)
            expected = [single.step(0)[4]["drawn_reward_delay"] for _ in range(60)]
            assert d[:, i].tolist() == expected
    assert not np.array_equal(sb3_delays(20)[:, 0], sb3_delays(20)[:, 1])


def Float64VecEnv(env_fns):
    """A VecEnv whose rewards are float64 (DummyVecEnv's own buffer is float32).

    (Its class is made here, so that stable-baselines3 is imported by the tests, not at collection.)
    """
    from stable_baselines3.common.vec_env import DummyVecEnv

    class _Float64VecEnv(DummyVecEnv):
        def step_wait(self):
            obs, _, dones, infos = super().step_wait()
            return obs, np.full(self.num_envs, 0.1, dtype=np.float64), dones, infos

    return _Float64VecEnv(env_fns)


def ScriptedRewardVecEnv(env_fns, rewards):
    """A VecEnv whose ``step_wait`` returns ``rewards`` as they are (of any type)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    class _Scripted(DummyVecEnv):
        def step_wait(self):
            obs, _, dones, infos = super().step_wait()
            return obs, rewards, dones, infos

    return _Scripted(env_fns)


@pytest.mark.parametrize(
    ("rewards", "exc", "match"),
    [
        (None, TypeError, r"^rewards must be a 1-D array of 2 real numbers"),
        ([None, 1.0], TypeError, r"^rewards\[0\] must be a real scalar"),
        (np.array([1 + 0j, 1]), TypeError, r"^rewards\[0\] must be a real scalar"),
        (np.array([True, False]), TypeError, r"^rewards\[0\] must be a real scalar"),
        (np.ones((2, 1)), ValueError, r"^rewards must be .*shape \(2, 1\)"),
        ([1.0, 10**400], ValueError, r"^rewards\[1\] must be a real number within float64"),
    ],
    ids=repr,
)
def test_vec_reward_delay_refuses_rewards_of_the_wrong_form(rewards, exc, match) -> None:
    from delayed_rl.wrappers.sb3 import VecRewardDelay

    inner = ScriptedRewardVecEnv([lambda: RandomEndEnv(0.0, 0.0)] * 2, rewards)
    env = VecRewardDelay(inner, Constant(0), seed=0)
    env.reset()
    with pytest.raises(exc, match=match):
        env.step(np.zeros(2, dtype=int))


def test_vec_reward_delay_takes_a_list_of_rewards() -> None:
    from delayed_rl.wrappers.sb3 import VecRewardDelay

    inner = ScriptedRewardVecEnv([lambda: RandomEndEnv(0.0, 0.0)] * 2, [1, 0.5])
    env = VecRewardDelay(inner, Constant(0), seed=0)
    env.reset()
    _, rewards, _, _ = env.step(np.zeros(2, dtype=int))
    assert rewards.dtype == np.float32 and rewards.tolist() == [1.0, 0.5]


def test_delivered_sums_keep_float64_until_sb3_casts() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(Float64VecEnv([lambda: RandomEndEnv(0.0, 0.0)]), Constant(0), seed=0)
    env.reset()
    _, rewards, _, _ = env.step(np.zeros(1, dtype=int))
    assert rewards.dtype == np.float64 and rewards[0] == 0.1
    env = VecRewardDelay(DummyVecEnv([lambda: RandomEndEnv(0.0, 0.1)]), Constant(0), seed=0)
    env.reset()
    _, rewards, _, infos = env.step(np.zeros(1, dtype=int))
    assert rewards.dtype == np.float32 and rewards[0] == np.float32(0.1)  # DummyVecEnv's float32
    assert isinstance(infos[0]["pending_reward"], float)


def test_sb3_pending_sum_beyond_float64_is_a_clear_error_not_inf() -> None:
    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(
        Float64VecEnv([lambda: RandomEndEnv(0.0, 0.0)]), Constant(5), seed=0
    )  # float64 rewards of 0.1 ...
    env.venv.step_wait = lambda: (
        np.zeros((1, 2), np.float32),
        np.array([1e308]),
        np.array([False]),
        [{}],
    )
    env.reset()
    env.step(np.zeros(1, dtype=int))
    with pytest.raises(ValueError, match="float64"):
        env.step(np.zeros(1, dtype=int))


# --- the flush trap ---------------------------------------------------------------------------


def _sb3_walk(env: VecRewardDelay, steps: int, seed: int = 0) -> int | None:
    """Seeded random steps until the flush-trap watch is off: how many (``None``: over ``steps``)."""
    rng = np.random.default_rng(seed)
    env.reset()
    for step in range(1, steps + 1):
        env.step(rng.integers(env.action_space.n, size=env.num_envs))
        if env._watch is None:
            return step
    return None


def test_frozen_lake_sub_envs_warn_of_the_flush_trap_once() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    n_envs = 3
    venv = DummyVecEnv([lambda: gym.make("FrozenLake-v1") for _ in range(n_envs)])
    env = VecRewardDelay(venv, Poisson(5), seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _sb3_walk(env, FLUSH_WATCH_STEPS // n_envs) is not None
        for _ in range(50):  # and never again
            env.step(np.zeros(n_envs, dtype=int))
    (warning,) = flush_trap_warnings(caught)
    assert "on_episode_end='carry'" in str(warning.message)
    assert warning.filename == __file__  # it names the line that called step()


def test_rewards_along_the_way_end_the_sb3_watch_at_once() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    env = VecRewardDelay(DummyVecEnv([lambda: RandomEndEnv(0.1)] * 3), Poisson(5), seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _sb3_walk(env, 10) == 1
    assert flush_trap_warnings(caught) == []


def test_the_sb3_step_cap_counts_every_sub_envs_steps(monkeypatch) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    n_envs, cap = 3, 30
    monkeypatch.setattr(reward_delay, "FLUSH_WATCH_STEPS", cap)
    venv = DummyVecEnv([lambda: RandomEndEnv(0.2, reward=0.0) for _ in range(n_envs)])
    env = VecRewardDelay(venv, Poisson(3), seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _sb3_walk(env, 100) == cap // n_envs
    assert flush_trap_warnings(caught) == []


@pytest.mark.parametrize("on_episode_end", ["carry", "drop"])
def test_carry_and_drop_never_watch_sb3_sub_envs(on_episode_end) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    venv = DummyVecEnv([lambda: gym.make("FrozenLake-v1") for _ in range(3)])
    env = VecRewardDelay(venv, Poisson(5), on_episode_end=on_episode_end, seed=0)
    assert env._watch is None
    rng = np.random.default_rng(0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset()
        for _ in range(300):
            env.step(rng.integers(4, size=3))
    assert flush_trap_warnings(caught) == []

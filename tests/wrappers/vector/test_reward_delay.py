"""VectorRewardDelay: per-sub-env semantics under every gymnasium autoreset mode."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from support import flush_trap_warnings

from delayed_rl.delays import Constant, Empirical, Poisson
from delayed_rl.wrappers import EPISODE_END_MODES, VectorRewardDelay, reward_delay
from delayed_rl.wrappers.reference import ReferenceRewardDelay
from delayed_rl.wrappers.reward_delay import FLUSH_WATCH_EPISODES, FLUSH_WATCH_STEPS

TOL = 1e-9
MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED]


class RandomEndEnv(gym.Env):
    """Random real rewards, episodes that end at random times (all from ``np_random``)."""

    observation_space = gym.spaces.Discrete(4)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, p_end: float = 0.1, reward=None):
        self.p_end, self.reward = p_end, reward

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        reward = float(self.np_random.normal() * 5 + action) if self.reward is None else self.reward
        u = float(self.np_random.random())
        terminated = u < self.p_end / 2
        truncated = not terminated and u < self.p_end
        return int(self.np_random.integers(4)), reward, terminated, truncated, {}


def make_vec(n: int, mode: AutoresetMode, p_end: float = 0.1, reward=None) -> SyncVectorEnv:
    return SyncVectorEnv(
        [lambda: RandomEndEnv(p_end, reward) for _ in range(n)], autoreset_mode=mode
    )


def run_vector(autoreset: AutoresetMode, on_episode_end: str, delay, n_envs=3, steps=300, seed=0):
    env = VectorRewardDelay(make_vec(n_envs, autoreset), delay, on_episode_end=on_episode_end)
    twin = make_vec(n_envs, autoreset)  # the same sub-envs, undelayed, stepped in lockstep
    assert env.autoreset_mode == autoreset
    env.reset(seed=seed)
    twin.reset(seed=seed)
    refs = [ReferenceRewardDelay(on_episode_end) for _ in range(n_envs)]  # one per sub-env
    resetting = np.zeros(n_envs, dtype=bool)  # NEXT_STEP: this step is sub-env i's reset step
    delivered_sum = np.zeros(n_envs)
    undelayed_sum = np.zeros(n_envs)
    dropped_sum = np.zeros(n_envs)
    ep_delivered = np.zeros(n_envs)
    ep_undelayed = np.zeros(n_envs)
    episodes = np.zeros(n_envs, dtype=int)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        actions = rng.integers(2, size=n_envs)
        _, rewards, terminated, truncated, info = env.step(actions)
        _, raw, raw_term, raw_trunc, _ = twin.step(actions)
        np.testing.assert_array_equal(terminated, raw_term)
        np.testing.assert_array_equal(truncated, raw_trunc)
        assert rewards.shape == (n_envs,)
        ended = terminated | truncated
        active = ~resetting
        np.testing.assert_array_equal(info["_undelayed_reward"], active)
        np.testing.assert_array_equal(info["_drawn_reward_delay"], active)
        for i in range(n_envs):
            if not active[i]:  # the reset step emits and delivers nothing
                assert rewards[i] == 0.0 and info["drawn_reward_delay"][i] == 0
                assert info["undelayed_reward"][i] == 0.0
                assert not ended[i]
                continue
            d = int(info["drawn_reward_delay"][i])
            assert d >= 0
            assert info["undelayed_reward"][i] == raw[i]
            arrivals, flushed, dropped = refs[i].step(float(raw[i]), d, bool(ended[i]))
            expected = math.fsum(r for _, r in arrivals)
            assert rewards[i] == pytest.approx(expected, abs=TOL)
            if ended[i] and on_episode_end == "flush":
                assert info["_flushed_reward"][i] and info["flushed_reward"][i] == pytest.approx(
                    flushed, abs=TOL
                )
            if ended[i] and on_episode_end == "drop":
                assert info["_dropped_reward"][i] and info["dropped_reward"][i] == pytest.approx(
                    dropped, abs=TOL
                )
            dropped_sum[i] += dropped
            undelayed_sum[i] += raw[i]
            ep_undelayed[i] += raw[i]
        delivered_sum += rewards
        ep_delivered += rewards
        pending = info["pending_reward"]
        for i in range(n_envs):
            assert pending[i] == pytest.approx(refs[i].pending(), abs=TOL)
        # conservation per sub-env at every step
        np.testing.assert_allclose(delivered_sum + pending + dropped_sum, undelayed_sum, atol=TOL)
        for i in np.flatnonzero(ended):
            episodes[i] += 1
            if on_episode_end == "flush":  # each sub-env's episode return is the undelayed one
                assert ep_delivered[i] == pytest.approx(ep_undelayed[i], abs=TOL)
                assert pending[i] == 0.0
            ep_delivered[i] = ep_undelayed[i] = 0.0
        if autoreset == AutoresetMode.NEXT_STEP:
            resetting = ended.copy()
        elif autoreset == AutoresetMode.DISABLED and ended.any():
            _, reset_info = env.reset(options={"reset_mask": ended})
            twin.reset(options={"reset_mask": ended})
            assert "dropped_reward" not in reset_info  # those episodes had ended properly
    assert (episodes >= 10).all()
    return env


@pytest.mark.parametrize("autoreset", MODES, ids=[m.name for m in MODES])
@pytest.mark.parametrize("on_episode_end", EPISODE_END_MODES)
@pytest.mark.parametrize(
    "delay",
    [Poisson(0), Poisson(0.5), Poisson(13.7), Constant(3), Empirical([0.3, 0, 0.7])],
    ids=repr,
)
def test_per_sub_env_conservation(autoreset, on_episode_end, delay) -> None:
    run_vector(autoreset, on_episode_end, delay)


@pytest.mark.parametrize("autoreset", MODES, ids=[m.name for m in MODES])
def test_large_delays_grow_the_rings(autoreset) -> None:
    run_vector(autoreset, "carry", Poisson(90), steps=500)


def test_same_seed_same_delays_different_seeds_differ() -> None:
    def delays(seed):
        env = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP), 5)
        env.reset(seed=seed)
        return np.array(
            [env.step(np.zeros(2, dtype=int))[4]["drawn_reward_delay"] for _ in range(100)]
        )

    np.testing.assert_array_equal(delays(1), delays(1))
    assert not np.array_equal(delays(1), delays(2))
    d = delays(1)
    assert not np.array_equal(d[:, 0], d[:, 1])  # sub-envs draw their own delays


def test_disabled_mode_mid_episode_reset_drops_pending() -> None:
    env = VectorRewardDelay(make_vec(2, AutoresetMode.DISABLED, p_end=0.0, reward=1.0), Constant(5))
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, dtype=int))
    _, info = env.reset(options={"reset_mask": np.array([True, False])})
    np.testing.assert_array_equal(info["_dropped_reward"], [True, False])
    assert info["dropped_reward"][0] == 3.0
    *_, info = env.step(np.zeros(2, dtype=int))
    np.testing.assert_array_equal(info["pending_reward"], [1.0, 4.0])


def test_disabled_mode_mid_episode_reset_carry_keeps_pending() -> None:
    env = VectorRewardDelay(
        make_vec(2, AutoresetMode.DISABLED, p_end=0.0, reward=1.0),
        Constant(5),
        on_episode_end="carry",
    )
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, dtype=int))
    _, info = env.reset(options={"reset_mask": np.array([True, False])})
    assert "dropped_reward" not in info
    *_, info = env.step(np.zeros(2, dtype=int))
    np.testing.assert_array_equal(info["pending_reward"], [4.0, 4.0])


def test_next_step_reset_step_value_by_value() -> None:
    """Episode of 2 steps, Constant(1): the flush lands on the last step, the reset step is 0."""

    class TwoStep(RandomEndEnv):
        def reset(self, *, seed=None, options=None):
            self.t = 0
            return super().reset(seed=seed)

        def step(self, action):
            self.t += 1
            return 0, float(self.t), self.t == 2, False, {}

    env = VectorRewardDelay(
        SyncVectorEnv([TwoStep], autoreset_mode=AutoresetMode.NEXT_STEP), Constant(1)
    )
    env.reset(seed=0)
    got = [env.step(np.zeros(1, dtype=int)) for _ in range(6)]
    assert [float(g[1][0]) for g in got] == [0.0, 3.0, 0.0, 0.0, 3.0, 0.0]
    assert [bool(g[2][0]) for g in got] == [False, True, False, False, True, False]
    assert float(got[1][4]["flushed_reward"][0]) == 2.0


@pytest.mark.parametrize("autoreset", MODES, ids=[m.name for m in MODES])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_reward_raises(autoreset, bad) -> None:
    env = VectorRewardDelay(make_vec(2, autoreset, reward=bad), 2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.zeros(2, dtype=int))


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"delay": -1}, ValueError, "^delay must be a number in \\[0, "),
        ({"delay": float("nan")}, ValueError, "^delay must be a number in \\[0, "),
        ({"delay": "x"}, TypeError, "delay"),
        ({"delay": 1, "max_delay": -2}, ValueError, "max_delay"),
        ({"delay": 1, "max_delay": 2.0}, TypeError, "max_delay"),
        ({"delay": 1, "on_episode_end": "later"}, ValueError, "on_episode_end"),
        ({"delay": 1, "max_delay": "5"}, TypeError, "max_delay"),
        ({"delay": 1, "on_episode_end": None}, TypeError, "on_episode_end"),
        ({"delay": True}, TypeError, "delay"),
    ],
)
def test_invalid_arguments(kwargs, exc, name) -> None:
    with pytest.raises(exc, match=name):
        VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP), **kwargs)


def test_records_its_constructor_arguments() -> None:
    """Like RewardDelay, the wrapper keeps its arguments (``gym.utils.RecordConstructorArgs``)."""
    delay = Empirical([0.5, 0.5])
    env = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP), delay, 3, on_episode_end="drop")
    assert isinstance(env, gym.utils.RecordConstructorArgs)
    assert env._saved_kwargs == {  # the delay as its JSON description
        "delay": {"type": "Empirical", "pmf": [0.5, 0.5]},
        "max_delay": 3,
        "on_episode_end": "drop",
    }
    rebuilt = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP), **env._saved_kwargs)
    assert (rebuilt.delay, rebuilt.max_delay, rebuilt.on_episode_end) == (delay, 3, "drop")


# --- per-sub-env seeding -------------------------------------------------------------------------


def vector_delays(seed, n_envs=2, steps=60, delay=5, mode=AutoresetMode.NEXT_STEP):
    env = VectorRewardDelay(make_vec(n_envs, mode, p_end=0.0), delay)
    env.reset(seed=seed)
    return np.array(
        [env.step(np.zeros(n_envs, dtype=int))[4]["drawn_reward_delay"] for _ in range(steps)]
    )


def single_delays(seed, steps=60, delay=5):
    from delayed_rl.wrappers import RewardDelay

    env = RewardDelay(RandomEndEnv(p_end=0.0), delay)
    env.reset(seed=seed)
    return np.array([env.step(0)[4]["drawn_reward_delay"] for _ in range(steps)])


def test_each_sub_env_follows_its_own_seed() -> None:
    a, b = vector_delays([0, 1]), vector_delays([0, 7])
    np.testing.assert_array_equal(a[:, 0], b[:, 0])
    assert not np.array_equal(a[:, 1], b[:, 1])
    np.testing.assert_array_equal(a[:, 1], vector_delays([1, 0])[:, 0])


def test_an_int_seed_seeds_sub_env_i_with_seed_plus_i_like_sync_vector_env() -> None:
    d = vector_delays(10, n_envs=3)
    np.testing.assert_array_equal(d, vector_delays([10, 11, 12], n_envs=3))
    for i in range(3):  # the same stream as a single RewardDelay reset with that seed
        np.testing.assert_array_equal(d[:, i], single_delays(10 + i))


def test_a_none_entry_leaves_that_sub_env_unseeded() -> None:
    env = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP, p_end=0.0), 5)
    env.reset(seed=[3, 4])
    first = np.array([env.step(np.zeros(2, dtype=int))[4]["drawn_reward_delay"] for _ in range(30)])
    env.reset(seed=[3, None])  # sub-env 0 starts over, sub-env 1 continues its stream
    again = np.array([env.step(np.zeros(2, dtype=int))[4]["drawn_reward_delay"] for _ in range(30)])
    np.testing.assert_array_equal(again[:, 0], first[:, 0])
    np.testing.assert_array_equal(again[:, 1], single_delays(4, steps=60)[30:])


def test_reset_mask_seeds_only_the_reset_sub_envs() -> None:
    env = VectorRewardDelay(make_vec(2, AutoresetMode.DISABLED, p_end=0.0), 5)
    env.reset(seed=[3, 4])
    first = np.array([env.step(np.zeros(2, dtype=int))[4]["drawn_reward_delay"] for _ in range(30)])
    env.reset(seed=[3, 3], options={"reset_mask": np.array([False, True])})
    again = np.array([env.step(np.zeros(2, dtype=int))[4]["drawn_reward_delay"] for _ in range(30)])
    np.testing.assert_array_equal(again[:, 0], single_delays(3, steps=60)[30:])
    np.testing.assert_array_equal(again[:, 1], first[:, 0])


@pytest.mark.parametrize(
    ("seed", "exc"),
    [("3", TypeError), (-1, ValueError), ([0], ValueError), ([0, "1"], TypeError),
     ([0, -1], ValueError), (1.5, TypeError), (True, TypeError)],
)  # fmt: skip
def test_bad_seeds_are_refused_naming_seed(seed, exc) -> None:
    env = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP), 5)
    with pytest.raises(exc, match="seed"):
        env.reset(seed=seed)


@pytest.mark.parametrize("on_episode_end", EPISODE_END_MODES)
def test_pending_sum_beyond_float64_is_a_clear_error_not_inf(on_episode_end) -> None:
    env = VectorRewardDelay(
        make_vec(2, AutoresetMode.NEXT_STEP, p_end=0.0, reward=1e308),
        Constant(5),
        on_episode_end=on_episode_end,
    )
    env.reset(seed=0)
    *_, info = env.step(np.zeros(2, dtype=int))
    np.testing.assert_array_equal(info["pending_reward"], [1e308, 1e308])
    with pytest.raises(ValueError, match="float64"):
        env.step(np.zeros(2, dtype=int))


def test_huge_rewards_whose_sum_fits_are_exact_in_the_pending_rewards() -> None:
    from delayed_rl.wrappers.pending_rewards import PendingRewards

    pending = PendingRewards(1, Constant(20), None)
    for reward in (1e308, 1.0, -1e308, 1e308):
        delivered, _, _ = pending.step(np.array([reward]), [True], [False], "flush")
        assert delivered[0] == 0.0 and np.isfinite(pending.pending).all()
    np.testing.assert_array_equal(pending.clear(np.array([True])), [1e308])


# ---------------------------------------------------------------------- the flush trap
class TerminalReward(gym.Env):
    """Episodes of ``length`` steps whose only reward, ``final``, comes at the last step."""

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, length: int = 6, final: float = 1.0):
        self.length, self.final = length, final

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return 0, {}

    def step(self, action):
        self.t += 1
        done = self.t >= self.length
        return 0, self.final if done else 0.0, done, False, {}


def _random_step(env: VectorRewardDelay) -> None:
    """One step of random actions; under DISABLED, reset the sub-envs whose episode ended."""
    _, _, terminated, truncated, _ = env.step(env.action_space.sample())
    ended = np.asarray(terminated) | np.asarray(truncated)
    if env.autoreset_mode == AutoresetMode.DISABLED and ended.any():
        env.reset(options={"reset_mask": ended})


def _walk(env: VectorRewardDelay, steps: int, seed: int = 0) -> int | None:
    """Seeded random steps until the watch is off: how many it took (``None``: over ``steps``)."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    for step in range(1, steps + 1):
        _random_step(env)
        if env._watch is None:
            return step
    return None


@pytest.mark.parametrize("autoreset", MODES, ids=[m.name for m in MODES])
def test_frozen_lake_sub_envs_warn_of_the_flush_trap_once(autoreset) -> None:
    n_envs = 4
    inner = SyncVectorEnv(
        [lambda: gym.make("FrozenLake-v1") for _ in range(n_envs)], autoreset_mode=autoreset
    )
    env = VectorRewardDelay(inner, Poisson(5))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _walk(env, FLUSH_WATCH_STEPS // n_envs) is not None
        for _ in range(50):  # and never again
            _random_step(env)
    (warning,) = flush_trap_warnings(caught)
    assert "on_episode_end='carry'" in str(warning.message)
    assert warning.filename == __file__  # it names the line that called step()


def test_the_sub_envs_rewarded_episodes_count_together() -> None:
    n_envs, length = 4, 6
    inner = SyncVectorEnv(
        [lambda: TerminalReward(length) for _ in range(n_envs)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    env = VectorRewardDelay(inner, Poisson(3))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        steps = _walk(env, 1_000)
    # every sub-env ends an episode every `length` steps: the watch has its rewarded episodes
    # once the rounds of n_envs episodes reach FLUSH_WATCH_EPISODES, not FLUSH_WATCH_EPISODES each
    assert steps == length * math.ceil(FLUSH_WATCH_EPISODES / n_envs)
    assert len(flush_trap_warnings(caught)) == 1


def test_rewards_along_the_way_end_the_vector_watch_at_once() -> None:
    env = VectorRewardDelay(make_vec(3, AutoresetMode.NEXT_STEP), Poisson(5))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _walk(env, 10) == 1
        for _ in range(100):
            env.step(env.action_space.sample())
    assert flush_trap_warnings(caught) == []


def test_the_step_cap_counts_every_sub_envs_steps(monkeypatch) -> None:
    n_envs, cap = 4, 40
    monkeypatch.setattr(reward_delay, "FLUSH_WATCH_STEPS", cap)
    inner = SyncVectorEnv(
        [lambda: TerminalReward(final=0.0) for _ in range(n_envs)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    env = VectorRewardDelay(inner, Poisson(3))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _walk(env, 100) == cap // n_envs
    assert flush_trap_warnings(caught) == []


@pytest.mark.parametrize("on_episode_end", ["carry", "drop"])
def test_carry_and_drop_never_watch_sub_envs(on_episode_end) -> None:
    inner = SyncVectorEnv([lambda: TerminalReward() for _ in range(3)])
    env = VectorRewardDelay(inner, Poisson(3), on_episode_end=on_episode_end)
    assert env._watch is None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        for _ in range(200):
            env.step(env.action_space.sample())
    assert flush_trap_warnings(caught) == []


def test_copies_of_an_unseeded_vector_wrapper_draw_their_own_delays() -> None:
    import copy

    original = VectorRewardDelay(make_vec(2, AutoresetMode.NEXT_STEP, p_end=0.0), Poisson(20.0))
    twin = copy.deepcopy(original)
    drawn = []
    for env in (original, twin):
        env.reset()
        drawn.append([env.step(np.zeros(2, dtype=np.int64))[4]["drawn_reward_delay"].tolist()
                      for _ in range(20)])  # fmt: skip
    assert drawn[0] != drawn[1]

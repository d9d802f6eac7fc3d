"""RewardDelay / PoissonRewardDelay: conservation, constructed cases, determinism, validation."""

from __future__ import annotations

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import NeverEndingEnv, ScriptedDelay, flush_trap_warnings

from delayed_rl.delays import Constant, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import (
    EPISODE_END_MODES,
    ActionDelay,
    ObservationDelay,
    PoissonRewardDelay,
    RewardDelay,
    reward_delay,
    wrap_reward_delay,
)
from delayed_rl.wrappers.reference import ReferenceRewardDelay
from delayed_rl.wrappers.reward_delay import FLUSH_WATCH_EPISODES, FLUSH_WATCH_STEPS

TOL = 1e-9


# --- test envs and delays ----------------------------------------------------------------------


class RandomEndEnv(gym.Env):
    """Discrete env with real-valued random rewards and episodes that end at random times.

    Everything random comes from ``np_random``; ``info["raw_reward"]`` repeats the reward so a test
    can compare it with the wrapper's ``undelayed_reward``.
    """

    observation_space = gym.spaces.Discrete(4)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, p_terminate: float = 0.05, p_truncate: float = 0.03, scale: float = 10.0):
        self.p_terminate, self.p_truncate, self.scale = p_terminate, p_truncate, scale

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        reward = float(self.np_random.normal() * self.scale + action)
        u = float(self.np_random.random())
        terminated = u < self.p_terminate
        truncated = not terminated and u < self.p_terminate + self.p_truncate
        obs = int(self.np_random.integers(4))
        return obs, reward, terminated, truncated, {"raw_reward": reward}


class ScriptedEnv(gym.Env):
    """Emits ``rewards`` in order (0.0 once they run out); episode ``i`` lasts ``lengths[i]``."""

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, rewards, lengths=(), truncate: bool = False):
        self.rewards, self.lengths, self.truncate = list(rewards), list(lengths), truncate
        self.emitted, self.episode, self.t = 0, -1, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode += 1
        self.t = 0
        return 0, {}

    def step(self, action):
        i = self.emitted
        reward = self.rewards[i] if i < len(self.rewards) else 0.0
        self.emitted += 1
        self.t += 1
        end = self.episode < len(self.lengths) and self.t >= self.lengths[self.episode]
        return 0, reward, end and not self.truncate, end and self.truncate, {}


def run_and_check(env: RewardDelay, inner_seed: int, n_steps: int, mode: str, record: bool):
    """Drive ``env`` with random actions; check every step against the rule's reference."""
    ref = ReferenceRewardDelay(mode)
    rng = np.random.default_rng(inner_seed)
    obs, info = env.reset(seed=inner_seed)
    assert info["pending_reward"] == 0.0
    delivered_total = undelayed_total = dropped_total = 0.0
    ep_delivered = ep_undelayed = 0.0
    episode_start = 0
    bound = env.max_delay if env.max_delay is not None else env.delay.support_max
    episodes = 0
    for _ in range(n_steps):
        obs, reward, terminated, truncated, info = env.step(int(rng.integers(2)))
        assert isinstance(reward, float)
        ended = terminated or truncated
        d = info["drawn_reward_delay"]
        assert isinstance(d, int) and d >= 0
        if bound is not None:
            assert d <= bound
        assert info["undelayed_reward"] == info["raw_reward"]
        arrivals, flushed, dropped = ref.step(info["undelayed_reward"], d, ended)
        assert reward == pytest.approx(math.fsum(r for _, r in arrivals), abs=TOL)
        if record:
            expected = [(t - episode_start, r) for t, r in arrivals]
            assert info["reward_arrivals"] == expected
        else:
            assert "reward_arrivals" not in info
        if ended and mode == "flush":
            assert info["flushed_reward"] == pytest.approx(flushed, abs=TOL)
        if ended and mode == "drop":
            assert info["dropped_reward"] == pytest.approx(dropped, abs=TOL)
        if not ended or mode == "carry":
            assert "flushed_reward" not in info and "dropped_reward" not in info
        delivered_total += reward
        undelayed_total += info["undelayed_reward"]
        dropped_total += dropped
        ep_delivered += reward
        ep_undelayed += info["undelayed_reward"]
        # conservation at every step
        assert info["pending_reward"] == pytest.approx(ref.pending(), abs=TOL)
        assert env.pending_reward == info["pending_reward"]
        assert delivered_total + info["pending_reward"] + dropped_total == pytest.approx(
            undelayed_total, abs=TOL
        )
        if ended:
            episodes += 1
            if mode == "flush":  # the episode return is the undelayed one
                assert ep_delivered == pytest.approx(ep_undelayed, abs=TOL)
                assert info["pending_reward"] == 0.0
            elif mode == "drop":
                assert ep_delivered + info["dropped_reward"] == pytest.approx(ep_undelayed, abs=TOL)
                assert info["pending_reward"] == 0.0
            obs, info = env.reset()
            assert info["pending_reward"] == pytest.approx(ref.pending(), abs=TOL)
            assert "dropped_reward" not in info
            ep_delivered = ep_undelayed = 0.0
            episode_start = ref.clock
    return episodes


DELAYS = st.one_of(
    st.floats(0.0, 40.0, allow_nan=False).map(Poisson),
    st.sampled_from([0.0, 0.5, 5.0, 13.7]).map(Poisson),
    st.integers(0, 12).map(Constant),
    st.floats(0.05, 1.0).map(Geometric),
    st.tuples(st.integers(0, 5), st.integers(0, 15)).map(lambda t: Uniform(t[0], t[0] + t[1])),
    st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12)
    .filter(lambda w: sum(w) > 0.01)
    .map(lambda w: Empirical(np.asarray(w) / math.fsum(w))),
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    delay=DELAYS,
    max_delay=st.one_of(st.none(), st.integers(0, 20)),
    mode=st.sampled_from(EPISODE_END_MODES),
    record=st.booleans(),
    p_terminate=st.floats(0.0, 0.2),
    p_truncate=st.floats(0.0, 0.2),
    n_steps=st.integers(1, 300),
)
def test_conservation_property(
    seed, delay, max_delay, mode, record, p_terminate, p_truncate, n_steps
) -> None:
    env = RewardDelay(
        RandomEndEnv(p_terminate, p_truncate),
        delay,
        max_delay=max_delay,
        on_episode_end=mode,
        record_arrivals=record,
    )
    run_and_check(env, seed, n_steps, mode, record)


@pytest.mark.parametrize("mode", EPISODE_END_MODES)
@pytest.mark.parametrize("lam", [0, 0.5, 5, 13.7, 90])
def test_conservation_poisson_many_episodes(mode: str, lam: float) -> None:
    env = PoissonRewardDelay(
        RandomEndEnv(0.02, 0.02), lam, on_episode_end=mode, record_arrivals=True
    )
    assert run_and_check(env, 123, 3000, mode, True) > 30


def test_zero_delay_is_the_identity() -> None:
    env = PoissonRewardDelay(RandomEndEnv(), 0)
    env.reset(seed=3)
    for _ in range(500):
        _, reward, terminated, truncated, info = env.step(0)
        assert reward == info["raw_reward"] and info["drawn_reward_delay"] == 0
        assert info["pending_reward"] == 0.0
        if terminated or truncated:
            env.reset()


# --- constructed cases, value by value ---------------------------------------------------------


def test_thesis_table_3_1_overlap_and_out_of_order() -> None:
    """Thesis Table 3.1: wagers 1-8, delays 2,5,0,6,10,4,5,5, received in rounds 3,7,3,10,15,10,12,13.

    Rounds are 1-indexed in the thesis and 0-indexed steps here; the rewards after wager 8 are 0
    with a delay (50) that keeps them out of the 15 rounds looked at.
    """
    outcomes = [1.0, -1.0, 1.0, -1.0, -1.0, -1.0, 1.0, 1.0]  # Win Lose Win Lose Lose Lose Win Win
    delays = [2, 5, 0, 6, 10, 4, 5, 5]
    received_round = [3, 7, 3, 10, 15, 10, 12, 13]
    assert [i + 1 + d for i, d in enumerate(delays)] == received_round
    env = RewardDelay(ScriptedEnv(outcomes), ScriptedDelay(delays, then=50), record_arrivals=True)
    env.reset(seed=0)
    expected_arrivals = {
        3: [(0, 1.0), (2, 1.0)],  # wagers 1 and 3 overlap; wager 3 overtakes wager 2
        7: [(1, -1.0)],
        10: [(3, -1.0), (5, -1.0)],
        12: [(6, 1.0)],
        13: [(7, 1.0)],
        15: [(4, -1.0)],
    }
    undelayed = outcomes + [0.0] * 7
    pending = 0.0
    for round_ in range(1, 16):
        _, reward, terminated, truncated, info = env.step(0)
        arrivals = expected_arrivals.get(round_, [])
        assert info["reward_arrivals"] == arrivals, round_
        assert reward == sum(r for _, r in arrivals), round_
        assert info["drawn_reward_delay"] == (delays + [50] * 7)[round_ - 1]
        assert info["undelayed_reward"] == undelayed[round_ - 1]
        pending += undelayed[round_ - 1] - reward
        assert info["pending_reward"] == pytest.approx(pending)
        assert not (terminated or truncated)
    assert pending == 0.0


def test_flush_value_by_value() -> None:
    env = RewardDelay(ScriptedEnv([1.0, 2.0, 3.0, 4.0], [4]), Constant(3), record_arrivals=True)
    env.reset(seed=0)
    got = [env.step(0) for _ in range(4)]
    assert [g[1] for g in got] == [0.0, 0.0, 0.0, 10.0]  # r0 due at step 3, then 2+3+4 flushed
    assert [g[4]["pending_reward"] for g in got] == [1.0, 3.0, 6.0, 0.0]
    assert got[3][2] is True and got[3][4]["flushed_reward"] == 9.0
    assert got[3][4]["reward_arrivals"] == [(0, 1.0), (1, 2.0), (2, 3.0), (3, 4.0)]
    assert all("flushed_reward" not in g[4] for g in got[:3])


def test_drop_value_by_value() -> None:
    env = RewardDelay(
        ScriptedEnv([1.0, 2.0, 3.0, 4.0, 5.0], [4], truncate=True),
        Constant(2),
        on_episode_end="drop",
    )
    env.reset(seed=0)
    got = [env.step(0) for _ in range(4)]
    assert [g[1] for g in got] == [0.0, 0.0, 1.0, 2.0]
    assert got[3][3] is True and got[3][4]["dropped_reward"] == 7.0
    assert got[3][4]["pending_reward"] == 0.0
    # nothing from the dropped rewards shows up later
    _, info = env.reset()
    assert info["pending_reward"] == 0.0 and "dropped_reward" not in info
    assert [env.step(0)[1] for _ in range(3)] == [0.0, 0.0, 5.0]


def test_carry_value_by_value() -> None:
    """Leftovers arrive in the next episode at their scheduled offsets."""
    rewards = [1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0]
    env = RewardDelay(
        ScriptedEnv(rewards, [5, 5, 3]), Constant(2), on_episode_end="carry", record_arrivals=True
    )
    env.reset(seed=0)
    ep1 = [env.step(0) for _ in range(5)]
    assert [g[1] for g in ep1] == [0.0, 0.0, 1.0, 2.0, 3.0]
    assert ep1[-1][2] is True and ep1[-1][4]["pending_reward"] == 9.0
    assert "flushed_reward" not in ep1[-1][4] and "dropped_reward" not in ep1[-1][4]
    _, info = env.reset()
    assert info["pending_reward"] == 9.0
    ep2 = [env.step(0) for _ in range(5)]
    assert [g[1] for g in ep2] == [4.0, 5.0, 10.0, 20.0, 30.0]
    # carried rewards are reported with negative emission steps on the new episode's clock
    assert ep2[0][4]["reward_arrivals"] == [(-2, 4.0)]
    assert ep2[1][4]["reward_arrivals"] == [(-1, 5.0)]
    assert ep2[2][4]["reward_arrivals"] == [(0, 10.0)]
    env.reset()
    ep3 = [env.step(0) for _ in range(3)]
    assert [g[1] for g in ep3] == [40.0, 50.0, 0.0]
    assert ep3[-1][4]["pending_reward"] == 0.0
    total = sum(g[1] for g in ep1 + ep2 + ep3)
    assert total == sum(rewards)


def test_a_grown_schedule_keeps_pending_rewards_in_place() -> None:
    """Delays far beyond the first schedule's reach (grown mid-stream) still land value by value."""
    delays = [100, 3, 300, 0, 1, 40, 5]
    rewards = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0]
    env = RewardDelay(ScriptedEnv(rewards), ScriptedDelay(delays, then=0, mean=0.0))
    env.reset(seed=0)
    due = {i + d: r for i, (d, r) in enumerate(zip(delays, rewards, strict=True))}
    for t in range(400):
        _, reward, *_ = env.step(0)
        assert reward == due.get(t, 0.0), t
    assert env.pending_reward == 0.0


def test_mid_episode_reset_reports_dropped_reward() -> None:
    # an outer TimeLimit the delay wrapper cannot see: the reset cuts the episode short
    inner = RewardDelay(ScriptedEnv([1.0, 2.0, 3.0, 4.0, 5.0]), Constant(3))
    env = gym.wrappers.TimeLimit(inner, max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        *_, truncated, info = env.step(0)
    assert truncated and info["pending_reward"] == 12.0
    with pytest.warns(UserWarning, match="discarded"):
        _, info = env.reset()
    assert info["dropped_reward"] == 12.0 and info["pending_reward"] == 0.0
    assert [env.step(0)[1] for _ in range(4)] == [0.0] * 4


def test_mid_episode_reset_carry_keeps_pending() -> None:
    env = RewardDelay(ScriptedEnv([1.0, 2.0]), Constant(3), on_episode_end="carry")
    env.reset(seed=0)
    env.step(0)
    env.step(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, info = env.reset()
    assert "dropped_reward" not in info and info["pending_reward"] == 3.0
    # scheduled at steps 3 and 4 of the run: offsets 1 and 2 of the new episode
    assert [env.step(0)[1] for _ in range(3)] == [0.0, 1.0, 2.0]


def test_mid_episode_reset_with_nothing_pending_does_not_warn() -> None:
    env = RewardDelay(ScriptedEnv([1.0, 2.0]), Constant(0), on_episode_end="drop")
    env.reset(seed=0)
    env.step(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, info = env.reset()
    assert info["dropped_reward"] == 0.0


def test_numpy_and_integer_rewards_are_floats() -> None:
    for raw in (np.float32(1.5), np.int64(3), 2, np.array(0.25)):
        env = PoissonRewardDelay(NeverEndingEnv(raw), 0)
        env.reset(seed=0)
        _, reward, *_, info = env.step(0)
        assert type(reward) is float and reward == float(raw) == info["undelayed_reward"]


class Float32RewardEnv(RandomEndEnv):
    """RandomEndEnv whose rewards are ``np.float32`` (as some third-party envs return)."""

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        info["raw_reward"] = float(np.float32(reward))
        return obs, np.float32(reward), terminated, truncated, info


@pytest.mark.parametrize("mode", EPISODE_END_MODES)
def test_float32_rewards_are_summed_in_double_precision(mode: str) -> None:
    """Regression: float32 rewards used to be accumulated in float32 (errors of ~1e-4)."""
    env = PoissonRewardDelay(
        Float32RewardEnv(0.002, 0.002), 5, on_episode_end=mode, record_arrivals=True
    )
    run_and_check(env, 77, 8000, mode, True)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), np.float32("nan")])
@pytest.mark.parametrize("lam", [0, 3])
def test_non_finite_reward_raises(bad, lam) -> None:
    env = PoissonRewardDelay(NeverEndingEnv(bad), lam)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite reward"):
        env.step(0)


# --- determinism -------------------------------------------------------------------------------


def trajectory(env: gym.Env, seed: int, n: int = 400):
    env.reset(seed=seed)
    env.action_space.seed(seed)
    out = []
    for _ in range(n):
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        out.append((reward, info["drawn_reward_delay"]))
        if terminated or truncated:
            env.reset()
    return out


@pytest.mark.filterwarnings("ignore:reset\\(\\) in the middle of an episode")
def test_same_seed_same_delays_and_rewards() -> None:
    a = trajectory(PoissonRewardDelay(RandomEndEnv(), 5), 42)
    b = trajectory(PoissonRewardDelay(RandomEndEnv(), 5), 42)
    assert a == b
    # reseeding the same wrapper replays it too
    env = PoissonRewardDelay(RandomEndEnv(), 5)
    assert trajectory(env, 42) == a and trajectory(env, 42) == a


def test_different_seeds_differ() -> None:
    delays = [
        [d for _, d in trajectory(PoissonRewardDelay(RandomEndEnv(), 5), s)] for s in range(4)
    ]
    assert len({tuple(d) for d in delays}) == 4


def test_delays_do_not_depend_on_the_inner_env() -> None:
    """The delay stream is the wrapper's own: the inner env's randomness does not shift it."""
    a = [d for _, d in trajectory(PoissonRewardDelay(RandomEndEnv(0, 0, scale=1.0), 7), 9)]
    b = [d for _, d in trajectory(PoissonRewardDelay(NeverEndingEnv(1.0), 7), 9)]
    assert a == b


def test_delay_stream_is_independent_of_env_np_random() -> None:
    env = PoissonRewardDelay(NeverEndingEnv(1.0), 5)
    env.reset(seed=11)
    wrapper_delays = [env.step(0)[4]["drawn_reward_delay"] for _ in range(200)]
    twin = NeverEndingEnv(1.0)
    twin.reset(seed=11)
    env_stream = twin.np_random.poisson(5, 200).tolist()
    plain_stream = np.random.default_rng(11).poisson(5, 200).tolist()
    assert wrapper_delays != env_stream and wrapper_delays != plain_stream
    # not merely shifted either: the correlation between the streams is small
    assert abs(np.corrcoef(wrapper_delays, env_stream)[0, 1]) < 0.3


def test_reset_without_seed_continues_the_stream() -> None:
    env = PoissonRewardDelay(ScriptedEnv([], [5, 5]), 4)
    env.reset(seed=1)
    first = [env.step(0)[4]["drawn_reward_delay"] for _ in range(5)]
    env.reset()
    second = [env.step(0)[4]["drawn_reward_delay"] for _ in range(5)]
    twin = PoissonRewardDelay(ScriptedEnv([], [10]), 4)
    twin.reset(seed=1)
    assert [twin.step(0)[4]["drawn_reward_delay"] for _ in range(10)] == first + second


# --- third-party envs --------------------------------------------------------------------------

THIRD_PARTY = [
    ("FrozenLake-v1", {}),
    ("CliffWalking-v1", {"max_episode_steps": 100}),
    ("Taxi-v4", {}),
    ("CartPole-v1", {}),
    ("Pendulum-v1", {}),
]


@pytest.mark.parametrize(("env_id", "kwargs"), THIRD_PARTY, ids=[t[0] for t in THIRD_PARTY])
@pytest.mark.parametrize("mode", EPISODE_END_MODES)
def test_third_party_envs_wrap_and_conserve(env_id: str, kwargs: dict, mode: str) -> None:
    inner = gym.make(env_id, **kwargs)
    env = PoissonRewardDelay(inner, 3.5, on_episode_end=mode)
    assert env.observation_space == inner.observation_space
    assert env.action_space == inner.action_space
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    env.action_space.seed(0)
    delivered = undelayed = dropped = 0.0
    episodes = 0
    ep_delivered = ep_undelayed = 0.0
    for _ in range(450):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        delivered += reward
        undelayed += info["undelayed_reward"]
        ep_delivered += reward
        ep_undelayed += info["undelayed_reward"]
        dropped += info.get("dropped_reward", 0.0)
        assert delivered + dropped + info["pending_reward"] == pytest.approx(undelayed, abs=1e-6)
        if terminated or truncated:
            episodes += 1
            if mode == "flush":
                assert ep_delivered == pytest.approx(ep_undelayed, abs=1e-6)
            ep_delivered = ep_undelayed = 0.0
            env.reset()
    assert episodes >= 2
    if mode == "flush":
        assert dropped == 0.0


@pytest.mark.parametrize(("env_id", "kwargs"), THIRD_PARTY, ids=[t[0] for t in THIRD_PARTY])
def test_check_env_on_wrapped_third_party(env_id: str, kwargs: dict) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # check_env warns that the env is wrapped
        check_env(PoissonRewardDelay(gym.make(env_id, **kwargs), 2))
        check_env(RewardDelay(gym.make(env_id, **kwargs), Uniform(0, 4), on_episode_end="drop"))
    # ("carry" deliberately keeps rewards across resets, so seeded resets need not replay rewards)


def test_spec_rebuilds_the_wrapper_stack() -> None:
    env = PoissonRewardDelay(gym.make("CartPole-v1"), 4.5, max_delay=12, on_episode_end="drop")
    rebuilt = gym.make(env.spec)
    layer, found = rebuilt, None
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, PoissonRewardDelay):
            found = layer
        layer = layer.env
    assert found is not None
    assert (found.lam, found.max_delay, found.on_episode_end) == (4.5, 12, "drop")
    assert trajectory(env, 5, 300) == trajectory(rebuilt, 5, 300)


def test_pickle_round_trip_mid_episode() -> None:
    env = PoissonRewardDelay(gym.make("CartPole-v1"), 6, record_arrivals=True)
    env.reset(seed=3)
    for i in range(10):
        assert not any(env.step(i % 2)[2:4])
    clone = pickle.loads(pickle.dumps(env))
    assert clone.pending_reward == env.pending_reward
    for i in range(30):
        a, b = env.step(i % 2), clone.step(i % 2)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4] and a[4] == b[4]
        if a[2] or a[3]:
            break


# --- validation ----------------------------------------------------------------------------------


def _env():
    return RandomEndEnv()


@pytest.mark.parametrize(
    ("make", "exc", "name"),
    [
        (lambda: PoissonRewardDelay(_env(), -1), ValueError, "lam"),
        (lambda: PoissonRewardDelay(_env(), float("nan")), ValueError, "lam"),
        (lambda: PoissonRewardDelay(_env(), float("inf")), ValueError, "lam"),
        (lambda: PoissonRewardDelay(_env(), True), TypeError, "lam"),
        (lambda: PoissonRewardDelay(_env(), "5"), TypeError, "lam"),
        (lambda: RewardDelay(_env(), -0.5), ValueError, "^delay must be"),
        (lambda: RewardDelay(_env(), float("nan")), ValueError, "^delay must be"),
        (lambda: RewardDelay(_env(), "5"), TypeError, "delay"),
        (lambda: RewardDelay(_env(), True), TypeError, "delay"),
        (lambda: RewardDelay(_env(), None), TypeError, "delay"),
        (lambda: PoissonRewardDelay(_env(), 2, max_delay=-1), ValueError, "max_delay"),
        (lambda: PoissonRewardDelay(_env(), 2, max_delay=2.5), TypeError, "max_delay"),
        (lambda: PoissonRewardDelay(_env(), 2, max_delay=3.0), TypeError, "max_delay"),
        (lambda: PoissonRewardDelay(_env(), 2, max_delay=True), TypeError, "max_delay"),
        (lambda: PoissonRewardDelay(_env(), 2, max_delay="3"), TypeError, "max_delay"),
        (
            lambda: RewardDelay(_env(), Constant(1), on_episode_end="keep"),
            ValueError,
            "on_episode_end",
        ),
        (
            lambda: RewardDelay(_env(), Constant(1), on_episode_end=None),
            TypeError,
            "on_episode_end",
        ),
        (lambda: RewardDelay(_env(), Constant(1), record_arrivals=1), TypeError, "record_arrivals"),
        (
            lambda: RewardDelay(_env(), Constant(1), record_arrivals="yes"),
            TypeError,
            "record_arrivals",
        ),
        (lambda: wrap_reward_delay(_env(), "5"), TypeError, "reward_delay"),
        (lambda: wrap_reward_delay(_env(), -2), ValueError, "^reward_delay must be"),
    ],
)
def test_invalid_arguments(make, exc, name) -> None:
    with pytest.raises(exc, match=name):
        make()


WRONG_TYPE_AND_BAD_VALUE = [
    # (argument, a value of the wrong type, a value of the right type that is not allowed)
    ("max_delay", "5", -1),
    ("max_delay", 2.0, -3),
    ("on_episode_end", 1, "keep"),
    ("record_arrivals", "yes", None),  # any bool is allowed: no bad value of the right type
]


@pytest.mark.parametrize(("name", "wrong_type", "bad_value"), WRONG_TYPE_AND_BAD_VALUE)
@pytest.mark.parametrize("wrapper", ["RewardDelay", "PoissonRewardDelay"])
def test_each_argument_refuses_a_wrong_type_and_a_bad_value(
    wrapper, name, wrong_type, bad_value
) -> None:
    def make(value):
        if wrapper == "RewardDelay":
            return RewardDelay(_env(), Constant(1), **{name: value})
        return PoissonRewardDelay(_env(), 2.0, **{name: value})

    with pytest.raises(TypeError, match=name):
        make(wrong_type)
    if bad_value is not None:
        with pytest.raises(ValueError, match=name):
            make(bad_value)


@pytest.mark.parametrize(("wrong_type", "bad_value"), [("5", -1.0), (True, float("inf"))])
def test_the_delay_argument_refuses_a_wrong_type_and_a_bad_value(wrong_type, bad_value) -> None:
    with pytest.raises(TypeError, match="delay"):
        RewardDelay(_env(), wrong_type)
    with pytest.raises(ValueError, match="^delay must be"):
        RewardDelay(_env(), bad_value)
    with pytest.raises(TypeError, match="lam"):
        PoissonRewardDelay(_env(), wrong_type)
    with pytest.raises(ValueError, match="lam"):
        PoissonRewardDelay(_env(), bad_value)
    with pytest.raises(TypeError, match="reward_delay"):
        wrap_reward_delay(_env(), wrong_type)
    with pytest.raises(ValueError, match="^reward_delay must be"):
        wrap_reward_delay(_env(), bad_value)


def test_valid_argument_types() -> None:
    assert PoissonRewardDelay(_env(), 2, max_delay=np.int64(3)).max_delay == 3
    assert PoissonRewardDelay(_env(), 2, max_delay=0).max_delay == 0
    assert type(PoissonRewardDelay(_env(), 2, max_delay=np.int64(3)).max_delay) is int
    assert RewardDelay(_env(), 1, record_arrivals=np.bool_(True)).record_arrivals is True


def test_wrap_reward_delay_dispatch() -> None:
    env = wrap_reward_delay(_env(), 2.5)
    assert type(env) is PoissonRewardDelay and env.lam == 2.5
    env = wrap_reward_delay(_env(), Geometric(0.5))
    assert type(env) is RewardDelay and env.delay == Geometric(0.5)


# --- sums beyond float64, and the env spec's JSON round trip ----------------------------------


@pytest.mark.parametrize("mode", EPISODE_END_MODES)
def test_pending_sum_beyond_float64_is_a_clear_error_not_inf(mode: str) -> None:
    env = RewardDelay(
        ScriptedEnv([1e308, 1e308, 0.0], lengths=[3]), Constant(5), on_episode_end=mode
    )
    env.reset(seed=0)
    _, reward, *_, info = env.step(0)
    assert reward == 0.0 and info["pending_reward"] == 1e308
    with pytest.raises(ValueError, match="float64"):
        env.step(0)


def test_rewards_due_at_one_step_beyond_float64_are_a_clear_error() -> None:
    env = RewardDelay(ScriptedEnv([1e308, 1e308]), ScriptedDelay([1, 0]))
    env.reset(seed=0)
    env.step(0)
    with pytest.raises(ValueError, match="float64"):
        env.step(0)


def test_huge_rewards_whose_sum_fits_are_summed_exactly() -> None:
    """The pending sum never leaves float64, though a plain ``math.fsum`` of it overflows."""
    rewards = [1e308, 1.0, -1e308, 1e308]  # due at steps 20, 21, 22 and again 21
    env = RewardDelay(ScriptedEnv(rewards, lengths=[4]), ScriptedDelay([20, 20, 20, 18]))
    env.reset(seed=0)
    got = [env.step(0) for _ in rewards]
    assert all(math.isfinite(g[4]["pending_reward"]) for g in got)
    assert [g[1] for g in got] == [0.0, 0.0, 0.0, 1e308]
    assert got[-1][4]["flushed_reward"] == 1e308


def test_spec_of_a_wrapper_with_a_delay_object_is_json() -> None:
    env = RewardDelay(gym.make("CartPole-v1"), Constant(2), max_delay=7)
    spec = gym.envs.registration.EnvSpec.from_json(env.spec.to_json())
    rebuilt = gym.make(spec)
    layer = rebuilt
    while not isinstance(layer, RewardDelay):
        layer = layer.env
    assert (layer.delay, layer.max_delay) == (Constant(2), 7)
    assert trajectory(env, 5, 200) == trajectory(rebuilt, 5, 200)


@pytest.mark.parametrize(
    "delay", [Constant(2), Poisson(3.5), Uniform(0, 4), Geometric(0.5), Empirical([0.5, 0.5])]
)
def test_registered_reward_delay_survives_the_json_round_trip(delay) -> None:
    env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=delay, max_steps=30)
    text = env.spec.to_json()
    rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(text))
    layer = rebuilt
    while not isinstance(layer, RewardDelay):
        layer = layer.env
    assert type(layer) is RewardDelay and layer.delay == delay
    assert trajectory(env, 3, 200) == trajectory(rebuilt, 3, 200)


# ---------------------------------------------------------------------- the flush trap
class _TerminalReward(gym.Env):
    """Episodes of ``length`` steps; reward ``final`` at the last step, ``along`` at the others.

    With ``every`` > 1 only every ``every``-th episode to end has its ``final`` reward; the
    others end with 0.
    """

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, length=6, final=1.0, along=0.0, every=1):
        self.length, self.final, self.along, self.every = length, final, along, every
        self.ended = 0

    def reset(self, *, seed=None, options=None):
        self.t = 0
        return 0, {}

    def step(self, action):
        self.t += 1
        if self.t < self.length:
            return 0, self.along, False, False, {}
        self.ended += 1
        return 0, self.final if self.ended % self.every == 0 else 0.0, True, False, {}


def _trap_warnings(env, episodes):
    """The flush-trap warnings raised over ``episodes`` episodes of ``env``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        for _ in range(episodes):
            while not env.step(0)[2]:
                pass
            env.reset()
    return flush_trap_warnings(caught)


@pytest.mark.parametrize(
    "inner, mode, delay, warned",
    [
        (_TerminalReward(), "flush", Poisson(5.0), True),  # the trap: the delay did nothing
        (_TerminalReward(), "carry", Poisson(5.0), False),  # carry delays it: no trap
        (_TerminalReward(), "drop", Poisson(5.0), False),
        (_TerminalReward(), "flush", Constant(0), False),  # no delay asked for: nothing to say
        (_TerminalReward(along=-1.0), "flush", Constant(1), False),  # rewards along the way
        (_TerminalReward(final=0.0), "flush", Poisson(5.0), False),  # no reward at all
        (_TerminalReward(along=1.0), "flush", Poisson(90.0), False),  # all flushed: delayed
    ],
)
def test_the_flush_trap_warns_once_naming_carry(inner, mode, delay, warned):
    env = RewardDelay(inner, delay, on_episode_end=mode)
    caught = _trap_warnings(env, 25)
    assert len(caught) == (1 if warned else 0)
    if warned:
        assert "on_episode_end='carry'" in str(caught[0].message)
        assert "first 10 episodes" in str(caught[0].message)


def test_the_watch_ends_at_the_first_reward_before_an_end_or_after_ten_rewarded_episodes():
    env = RewardDelay(_TerminalReward(along=1.0), Poisson(3.0))
    assert env._watch is not None
    assert _trap_warnings(env, 2) == []
    assert env._watch is None  # a reward before the end settled it
    trapped = RewardDelay(_TerminalReward(), Poisson(3.0))
    assert len(_trap_warnings(trapped, FLUSH_WATCH_EPISODES)) == 1 and trapped._watch is None
    assert _trap_warnings(trapped, 20) == []  # once


def test_episodes_without_a_reward_do_not_count_towards_the_watch():
    every = 3  # one episode in three has its terminal reward
    env = RewardDelay(_TerminalReward(every=every), Poisson(3.0))
    before = every * FLUSH_WATCH_EPISODES - 1  # one rewarded episode short
    assert _trap_warnings(env, before) == [] and env._watch is not None
    assert env._watch.episodes == before and env._watch.rewarded == FLUSH_WATCH_EPISODES - 1
    (caught,) = _trap_warnings(env, 1)
    expected = f"first {before + 1} episodes ({FLUSH_WATCH_EPISODES} of them with a reward)"
    assert expected in str(caught.message)
    assert env._watch is None


def _random_walk(env, seed, steps):
    """Step ``env`` with a seeded random policy, resetting at episode ends, until its watch is off.

    Returns how many steps it took (``None`` if the watch was still on after ``steps``).
    """
    env.action_space.seed(seed)
    env.reset(seed=seed)
    for step in range(1, steps + 1):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if env._watch is None:
            return step
        if terminated or truncated:
            env.reset()
    return None


def test_frozen_lake_under_a_random_policy_warns_of_the_flush_trap():
    env = PoissonRewardDelay(gym.make("FrozenLake-v1"), lam=5)
    with pytest.warns(UserWarning, match="the delay had no effect") as caught:
        steps = _random_walk(env, 0, FLUSH_WATCH_STEPS)
    assert steps is not None and steps < FLUSH_WATCH_STEPS  # its rewarded episodes ended it
    (warning,) = [w for w in caught if "the delay had no effect" in str(w.message)]
    assert "on_episode_end='carry'" in str(warning.message)
    assert warning.filename == __file__  # it names the line that called step()


def test_a_reward_before_the_final_step_ends_the_watch_silently_however_late():
    # 30 episodes of nothing, then a reward in the middle of an episode: the watch waits for it
    quiet = [0.0] * (30 * 5)
    env = RewardDelay(ScriptedEnv([*quiet, 0.0, 2.0], lengths=[5] * 31), Poisson(4.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        for _ in range(30):
            for _ in range(5):
                env.step(0)
            env.reset()
        assert env._watch is not None and env._watch.episodes == 30
        env.step(0)
        env.step(0)  # the reward, at the episode's second step of five
        assert env._watch is None
        for _ in range(3):
            env.step(0)
    assert [w for w in caught if "the delay had no effect" in str(w.message)] == []


def test_taxi_rewards_along_the_way_end_the_watch_at_the_first_step():
    env = PoissonRewardDelay(gym.make("Taxi-v4"), lam=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _random_walk(env, 0, 10) == 1  # Taxi's -1 per step, before any end
    assert [w for w in caught if "the delay had no effect" in str(w.message)] == []


def test_the_step_cap_ends_the_watch_of_an_env_that_never_rewards(monkeypatch):
    monkeypatch.setattr(reward_delay, "FLUSH_WATCH_STEPS", 50)
    env = RewardDelay(_TerminalReward(length=6, final=0.0), Poisson(3.0))
    assert _trap_warnings(env, 8) == [] and env._watch is not None  # 48 steps: still on
    assert _trap_warnings(env, 1) == [] and env._watch is None  # 54 steps: off, silently


def test_at_the_step_cap_rare_terminal_rewards_still_warn(monkeypatch):
    monkeypatch.setattr(reward_delay, "FLUSH_WATCH_STEPS", 60)
    env = RewardDelay(_TerminalReward(length=6, every=4), Poisson(3.0))
    assert _trap_warnings(env, 9) == [] and env._watch.rewarded == 2  # 54 steps
    (caught,) = _trap_warnings(env, 1)
    assert "first 10 episodes (2 of them with a reward)" in str(caught.message)
    assert env._watch is None


@pytest.mark.parametrize("mode", ["carry", "drop"])
def test_carry_and_drop_never_watch(mode):
    env = PoissonRewardDelay(gym.make("FrozenLake-v1"), lam=5, on_episode_end=mode)
    assert env._watch is None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _random_walk(env, 0, 3_000)
    assert [w for w in caught if "the delay had no effect" in str(w.message)] == []


def test_a_delay_clipped_to_zero_is_not_watched():
    assert RewardDelay(_TerminalReward(), Poisson(5.0), max_delay=0)._watch is None
    assert RewardDelay(_TerminalReward(), Poisson(5.0), max_delay=1)._watch is not None


@pytest.mark.parametrize(
    ("wrap", "key"),
    [
        (lambda env: RewardDelay(env, Poisson(20.0)), "drawn_reward_delay"),
        (lambda env: ActionDelay(env, Poisson(20.0)), "drawn_action_delay"),
        (lambda env: ObservationDelay(env, Poisson(20.0)), "observation_age"),
    ],
)
def test_copies_of_an_unseeded_wrapper_draw_their_own_delays(wrap, key):
    """Entropy is taken at the first draw, so copies made before it (SuperSuit's) differ."""
    import copy

    original = wrap(gym.make("delayed_rl/GridWorld-5x5-v0"))  # a continuing env: never ends

    def delays(env, seed):
        env.reset(seed=seed)
        return [env.step(0)[4][key] for _ in range(40)]

    first, second = (delays(copy.deepcopy(original), None) for _ in range(2))
    assert first != second
    again = [delays(copy.deepcopy(original), 3) for _ in range(2)]
    assert again[0] == again[1]  # a seed still gives the same delays

"""Fuzzing the delay wrappers: conservation over random envs, delays, end modes and resets.

For the single (:class:`RewardDelay`), vector (:class:`VectorRewardDelay`, every Gymnasium
autoreset mode) and stable-baselines3 (:class:`VecRewardDelay`) wrappers, hypothesis draws small
envs with random rewards, episode lengths, terminations and truncations, a delay from every
distribution of :mod:`delayed_rl.delays` (with or without ``max_delay``), an end mode, resets in
the middle of episodes and ``TimeLimit`` inside (and, for the single env, outside) the wrapper.
At every step and every reset, per (sub-)env::

    delivered + pending + dropped == emitted

exactly: rewards are multiples of 1/8 of moderate size, so every float sum is exact whatever its
order. The second half is a table of bad inputs to every public argument of the wrappers, delays,
envs and controller that other test files do not already cover: ``TypeError`` for a wrong type,
``ValueError`` for a bad value, the argument named in the message.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.wrappers import TimeLimit
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from support import examples

from delayed_rl.delays import Constant, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import EPISODE_END_MODES, RewardDelay, VectorRewardDelay

FUZZ = settings(
    max_examples=examples(100),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
NONE, TERMINATE, TRUNCATE = 0, 1, 2


class ScriptEnv(gym.Env):
    """Plays ``script``, a list of ``(reward, end)`` steps, across its episodes; then 0 forever.

    ``end`` is ``NONE``, ``TERMINATE`` or ``TRUNCATE``: the step ends the episode that way.
    """

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, script):
        self.script = list(script)
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        reward, end = self.script[self.t] if self.t < len(self.script) else (0.0, NONE)
        self.t += 1
        return 0, reward, end == TERMINATE, end == TRUNCATE, {}


eighths = st.integers(-64, 64).map(lambda k: k / 8)
ends = st.sampled_from([NONE] * 8 + [TERMINATE, TRUNCATE])
scripts = st.lists(st.tuples(eighths, ends), min_size=1, max_size=60)
weights = st.lists(st.integers(0, 5), min_size=1, max_size=8).filter(sum)
delays = st.one_of(
    st.floats(0.0, 20.0).map(Poisson),
    st.floats(0.0, 20.0),  # a number: a Poisson mean
    st.integers(0, 12).map(Constant),
    st.floats(0.05, 1.0).map(Geometric),
    st.tuples(st.integers(0, 6), st.integers(0, 8)).map(lambda t: Uniform(t[0], t[0] + t[1])),
    weights.map(lambda w: Empirical([x / sum(w) for x in w])),
    st.sampled_from([Constant(10**7), Geometric(1e-6), Poisson(1e6)]),  # beyond any ring
)
max_delays = st.one_of(st.none(), st.integers(0, 15))
modes = st.sampled_from(EPISODE_END_MODES)
limits = st.one_of(st.none(), st.integers(1, 12))
seeds = st.integers(0, 2**32)


# --- the single env ------------------------------------------------------------------------------


@FUZZ
@given(
    script=scripts,
    delay=delays,
    max_delay=max_delays,
    mode=modes,
    inside=limits,
    outside=limits,
    resets=st.lists(st.sampled_from([False] * 15 + [True]), min_size=1, max_size=80),
    seed=seeds,
)
def test_single_env_conserves_every_reward(
    script, delay, max_delay, mode, inside, outside, resets, seed
) -> None:
    env: gym.Env = ScriptEnv(script)
    if inside is not None:
        env = TimeLimit(env, inside)
    env = RewardDelay(env, delay, max_delay=max_delay, on_episode_end=mode, record_arrivals=True)
    if outside is not None:
        env = TimeLimit(env, outside)
    emitted = delivered = dropped = 0.0
    episode_emitted = episode_delivered = 0.0

    def balance(pending: float) -> None:
        assert delivered + pending + dropped == emitted

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mid-episode resets' warnings
        _, info = env.reset(seed=seed)
        ended = False
        for reset_now in resets:
            if reset_now or ended:
                _, info = env.reset()
                dropped += info.get("dropped_reward", 0.0)
                balance(info["pending_reward"])
                episode_emitted = episode_delivered = 0.0
            _, reward, terminated, truncated, info = env.step(0)
            emitted += info["undelayed_reward"]
            delivered += reward
            dropped += info.get("dropped_reward", 0.0)
            episode_emitted += info["undelayed_reward"]
            episode_delivered += reward
            balance(info["pending_reward"])
            assert sum(r for _, r in info["reward_arrivals"]) == reward
            ended = terminated or truncated
            if "flushed_reward" in info:  # "flush", and the wrapper saw the episode end
                assert info["pending_reward"] == 0.0
                assert episode_delivered == episode_emitted  # it began with nothing pending


# --- the gymnasium vector env ------------------------------------------------------------------


def _sub_env(script, inside):
    """A thunk making the scripted sub-env, behind a ``TimeLimit(inside)`` unless ``None``."""

    def thunk():
        env = ScriptEnv(script)
        return env if inside is None else TimeLimit(env, inside)

    return thunk


@FUZZ
@given(
    data=st.data(),
    n_envs=st.integers(1, 3),
    delay=delays,
    max_delay=max_delays,
    mode=modes,
    autoreset=st.sampled_from(list(AutoresetMode)),
    inside=limits,
    steps=st.integers(1, 70),
    seed=st.one_of(seeds, st.none()),
)
def test_vector_env_conserves_every_sub_envs_rewards(
    data, n_envs, delay, max_delay, mode, autoreset, inside, steps, seed
) -> None:
    sub_scripts = [data.draw(scripts) for _ in range(n_envs)]

    vec = SyncVectorEnv([_sub_env(s, inside) for s in sub_scripts], autoreset_mode=autoreset)
    env = VectorRewardDelay(vec, delay, max_delay=max_delay, on_episode_end=mode)
    emitted, delivered, dropped = np.zeros(n_envs), np.zeros(n_envs), np.zeros(n_envs)

    def add_dropped(info) -> None:
        if "dropped_reward" in info:
            dropped[:] += np.where(info["_dropped_reward"], info["dropped_reward"], 0.0)

    env.reset(seed=seed)
    ended = np.zeros(n_envs, dtype=bool)
    for _ in range(steps):
        cut = np.array(data.draw(st.lists(st.booleans(), min_size=n_envs, max_size=n_envs)))
        if autoreset == AutoresetMode.DISABLED:
            mask = ended | (cut & (data.draw(st.integers(0, 9)) == 0))
            if mask.any():
                _, info = env.reset(options={"reset_mask": mask})
                add_dropped(info)
        elif data.draw(st.integers(0, 19)) == 0:
            _, info = env.reset()
            add_dropped(info)
        _, rewards, terminated, truncated, info = env.step(np.zeros(n_envs, dtype=int))
        emitted += np.where(info["_undelayed_reward"], info["undelayed_reward"], 0.0)
        delivered += rewards
        add_dropped(info)
        pending = info["pending_reward"]
        np.testing.assert_array_equal(delivered + pending + dropped, emitted)
        ended = terminated | truncated
        if mode == "flush":
            assert (pending[ended] == 0.0).all()


# --- the stable-baselines3 vector env ----------------------------------------------------------


@pytest.mark.sb3
@FUZZ
@given(
    data=st.data(),
    n_envs=st.integers(1, 3),
    delay=delays,
    max_delay=max_delays,
    mode=modes,
    inside=limits,
    steps=st.integers(1, 70),
    seed=st.one_of(seeds, st.none()),
)
def test_sb3_vec_env_conserves_every_sub_envs_rewards(
    data, n_envs, delay, max_delay, mode, inside, steps, seed
) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    sub_scripts = [data.draw(scripts) for _ in range(n_envs)]

    env = VecRewardDelay(
        DummyVecEnv([_sub_env(s, inside) for s in sub_scripts]), delay, max_delay, mode, seed=seed
    )
    emitted, delivered, dropped = np.zeros(n_envs), np.zeros(n_envs), np.zeros(n_envs)

    def after_reset() -> None:
        dropped[:] += [info.get("dropped_reward", 0.0) for info in env.reset_infos]
        pending = np.array([info["pending_reward"] for info in env.reset_infos])
        np.testing.assert_array_equal(delivered + pending + dropped, emitted)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mid-episode resets' warnings
        env.reset()
        after_reset()
        for _ in range(steps):
            if data.draw(st.integers(0, 19)) == 0:
                env.reset()
                after_reset()
            _, rewards, dones, infos = env.step(np.zeros(n_envs, dtype=int))
            emitted += [info["undelayed_reward"] for info in infos]
            delivered += rewards.astype(np.float64)
            dropped += [info.get("dropped_reward", 0.0) for info in infos]
            pending = np.array([info["pending_reward"] for info in infos])
            np.testing.assert_array_equal(delivered + pending + dropped, emitted)
            if mode == "flush":
                assert (pending[dones] == 0.0).all()


# --- bad inputs to every public argument not covered elsewhere ---------------------------------


def _cartpole():
    return gym.make("CartPole-v1")


def _vector(n=2):
    return SyncVectorEnv([lambda: ScriptEnv([(1.0, NONE)])] * n)


def _sb3(delay=2, **kwargs):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    return VecRewardDelay(DummyVecEnv([lambda: ScriptEnv([(1.0, NONE)])]), delay, **kwargs)


def _reset_vector(seed):
    VectorRewardDelay(_vector(), 2).reset(seed=seed)


def _seed_sb3(seed):
    _sb3().seed(seed)


def _track():
    from delayed_rl.envs.linefollow.track import make_track

    return make_track("oval")


def _predict(**kwargs):
    from delayed_rl.agents.proportional import ProportionalController

    return ProportionalController().predict(**{"observation": 0, **kwargs})


def _entry(path):
    from delayed_rl.envs.registration import DelayableEntryPoint

    return DelayableEntryPoint(path)


def _gridworld(**kwargs):
    from delayed_rl.envs.gridworld import GridWorldEnv

    return GridWorldEnv(**kwargs)


def _random_track(**kwargs):
    from delayed_rl.envs.linefollow.track import random_track

    return random_track(0, **kwargs)


def _from_points(points):
    from delayed_rl.envs.linefollow.track import Track

    return Track(points)


def _delay_rng(seed):
    from delayed_rl.wrappers._delay_draws import delay_rng

    return delay_rng(seed)


#: The stable-baselines3 rows' mark: importing stable-baselines3 imports torch (over a second).
SB3 = pytest.mark.sb3

# (what to call with the bad value, argument name, a wrong-type value, a bad value or None)
BAD_INPUTS = [
    # delays
    (lambda v: Constant(v), "k", "2", 2**63),
    (lambda v: Uniform(0, v), "high", 2.5, 2**63),
    (lambda v: Uniform(v, 2**63), "low", "0", 2**63),
    (lambda v: Poisson(v), "lam", [1.0], 1e19),
    (lambda v: Geometric(v), "p", None, 1e-19),
    (lambda v: __import__("delayed_rl.delays").delays.as_delay(v), "delay", b"2", {"k": 2}),
    # wrappers
    (lambda v: RewardDelay(_cartpole(), 2, max_delay=v), "max_delay", 1.5, 2**63),
    (lambda v: RewardDelay(_cartpole(), {"type": "Constant", "k": v}), "k", "2", -1),
    (lambda v: RewardDelay(_cartpole(), {"type": v, "k": 2}), "delay", 2, "Cosntant"),
    (
        lambda v: __import__("delayed_rl.wrappers").wrappers.ObservationDelay(_cartpole(), v),
        "delay",
        "2",
        {"type": "Poisson"},
    ),
    (lambda v: VectorRewardDelay(_vector(), 2, max_delay=v), "max_delay", "3", 2**63),
    (_reset_vector, "seed", "3", -3),
    (lambda v: _reset_vector([0, v]), "seed", 1.5, -1),
    (lambda v: _reset_vector(v), "seed", {0: 1}, [0, 1, 2]),
    pytest.param(lambda v: _sb3(max_delay=v), "max_delay", "3", 2**63, marks=SB3),
    pytest.param(lambda v: _sb3(delay=v), "delay", None, {"type": "Uniform", "low": 3}, marks=SB3),
    pytest.param(_seed_sb3, "seed", "3", -1, marks=SB3),
    (_delay_rng, "seed", "x", -1),
    # envs
    (lambda v: _gridworld(size=v), "size", 9.0, 1000),
    (_entry, "env_path", 3, "no_colon_here"),
    (lambda v: _track().clearance(v), "exclude_arc", "0.5", -0.5),
    (_from_points, "points", "ab", [[0.0, 0.0], [float("nan"), 1.0]]),
    (lambda v: _random_track(mean_radius=v), "mean_radius", "50", 50.0),
    # the controller
    (lambda v: _predict(state=v), "state", "fast", [np.nan, 0.0]),
    (lambda v: _predict(state=v), "state", [None, 1.0], [1.0, 2.0, 3.0]),
    (lambda v: _predict(observation=v), "observation", None, 41),
]


@pytest.mark.parametrize(
    ("call", "name", "wrong_type", "bad_value"),
    BAD_INPUTS,
    ids=[f"{getattr(row, 'values', row)[1]}-{i}" for i, row in enumerate(BAD_INPUTS)],
)
def test_bad_inputs_raise_naming_the_argument(call, name, wrong_type, bad_value) -> None:
    with pytest.raises(TypeError, match=name):
        call(wrong_type)
    if bad_value is not None:
        with pytest.raises(ValueError, match=name):
            call(bad_value)


# --- a refused step changes nothing ------------------------------------------------------------
#
# Rewards of k · 2**1020 (|k| <= 6): their sums are exact, and pass float64's range (2**1024)
# once |Σk| reaches 16, so the wrappers refuse steps at random points: a pending sum, the sum
# due at one step, or an episode's flush. A refused step must leave the wrapper as it was:
# conservation then holds exactly over the steps taken.

UNIT = 2.0**1020
huge = st.integers(-6, 6).map(lambda k: k * UNIT)


def units(value) -> np.ndarray:
    """``value`` (a multiple of :data:`UNIT`) in units, as exact integers: sums do not overflow."""
    return np.asarray(np.asarray(value) / UNIT).round().astype(np.int64)


huge_scripts = st.lists(st.tuples(huge, ends), min_size=1, max_size=50)
short_delays = st.one_of(
    st.integers(0, 6).map(Constant),
    st.floats(0.0, 5.0).map(Poisson),
    st.floats(0.2, 1.0).map(Geometric),
)


def _same(a, b) -> bool:
    """Whether two saved states are equal (arrays by value, containers entry by entry)."""
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(map(_same, a, b))
    return a == b


def _single_state(env: RewardDelay) -> tuple:
    sampler = env._sampler
    return (
        env._clock,
        dict(env._due),
        env._pending,
        list(sampler.block),
        sampler.rng.bit_generator.state,
        env._episode_ended,
    )


@FUZZ
@given(script=huge_scripts, delay=short_delays, mode=modes, seed=seeds)
@example(  # refused at a delivery: paying the −1 out leaves 16 units pending, beyond float64
    script=[(-UNIT, 0), (0.0, 0), (0.0, 0), (0.0, 0), (4 * UNIT, 0), (6 * UNIT, 0), (6 * UNIT, 0)],
    delay=Constant(6),
    mode="carry",
    seed=0,
)
def test_a_single_env_step_refused_for_a_sum_beyond_float64_changes_nothing(
    script, delay, mode, seed
) -> None:
    env = RewardDelay(ScriptEnv(script), delay, on_episode_end=mode)
    emitted = delivered = dropped = 0  # in units: exact
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.reset(seed=seed)
        ended = False
        for _ in range(len(script)):
            if ended:
                _, info = env.reset()
                dropped += units(info.get("dropped_reward", 0.0))
            before = _single_state(env)
            try:
                _, reward, terminated, truncated, info = env.step(0)
            except ValueError as error:
                assert "float64" in str(error)
                assert _same(_single_state(env), before)
                ended = False
                continue
            emitted += units(info["undelayed_reward"])
            delivered += units(reward)
            dropped += units(info.get("dropped_reward", 0.0))
            assert delivered + units(info["pending_reward"]) + dropped == emitted
            ended = terminated or truncated


@FUZZ
@given(
    scripts=st.lists(huge_scripts, min_size=1, max_size=3),
    delay=short_delays,
    mode=modes,
    autoreset=st.sampled_from([AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]),
    seed=seeds,
)
def test_a_vector_step_refused_for_a_sum_beyond_float64_changes_nothing(
    scripts, delay, mode, autoreset, seed
) -> None:
    n = len(scripts)
    inner = SyncVectorEnv([_sub_env(s, None) for s in scripts], autoreset_mode=autoreset)
    env = VectorRewardDelay(inner, delay, on_episode_end=mode)
    emitted, delivered, dropped = (np.zeros(n, dtype=np.int64) for _ in range(3))  # in units
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.reset(seed=seed)
        for _ in range(max(map(len, scripts))):
            before = env.pending_rewards._save()
            try:
                _, rewards, _, _, info = env.step(np.zeros(n, dtype=np.int64))
            except ValueError as error:
                assert "float64" in str(error)
                assert _same(env.pending_rewards._save(), before)
                continue
            emitted += units(np.where(info["_undelayed_reward"], info["undelayed_reward"], 0.0))
            delivered += units(rewards)
            if "dropped_reward" in info:
                dropped += units(np.where(info["_dropped_reward"], info["dropped_reward"], 0.0))
            pending = units(info["pending_reward"])
            np.testing.assert_array_equal(delivered + pending + dropped, emitted)

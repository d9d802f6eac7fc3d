"""The compiled kernel: the exact MMQ update, the env tables, and the reward-delay ring."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from support import ScriptedDelay

import delayed_rl  # noqa: F401
from delayed_rl.compiled import CompiledRun, NotCompilable, inspect_stack
from delayed_rl.compiled.kernel import (
    _rescan,
    _rescan_lanes,
    _rescan_scalar,
    replay,
)
from delayed_rl.compiled.state import TableAverage
from delayed_rl.delays import Constant, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import RewardDelay


def _cache(q):
    """(qmax, qcell): each state's max and its flat index in q (the agents' layout)."""
    flat = q.reshape(q.shape[0], -1)
    return flat.max(axis=1), np.arange(q.shape[0]) * flat.shape[1] + flat.argmax(axis=1)


def _run(run, q, cache, steps, start, alpha, gamma, eps_initial, eps_final, eps_steps, **options):
    """``run.run`` with the rule's constants in the kernel's order (``options``: its keywords)."""
    rule = {"learning_rate": alpha, "gamma": gamma, "eps_steps": eps_steps}
    rule.update(eps_initial=eps_initial, eps_final=eps_final)
    return run.run(q, *cache, steps, start_step=start, **rule, **options)


def test_roulette_walk_through_tables_3_2_to_3_5():
    """Thesis section 3.2: q_init 50, α 0.1, γ 0.9, Λ = {0, 1, 2}; EVEN = 0, THIRTEEN = 1."""
    rounds = [(0, 0.0), (1, 35.0), (0, -1.0)]  # (wager, payout received that round)
    expected = [
        [[49.5, 50], [50, 50], [50, 50]],
        [[49.5, 53], [53, 50], [50, 50]],
        [[49.22, 53], [53, 49.67], [49.67, 50]],
    ]
    for n in range(1, 4):
        q = np.full((1, 3, 2), 50.0)
        wagers = np.array([[0, a, 0] for a, _ in rounds[:n]])
        replay(q, np.arange(3), wagers, np.zeros(n, bool), [r for _, r in rounds[:n]], 0.1, 0.9)
        np.testing.assert_allclose(q[0], expected[n - 1], rtol=0, atol=1e-12)


def test_constant_delay_ring_delivers_k_steps_late():
    env = RewardDelay(gym.make("delayed_rl/GridWorld-3x3-v0").unwrapped, Constant(3))
    run = CompiledRun(env, np.array([0]), seed=1)
    q = np.zeros((9, 1, 4))
    log = _run(run, q, _cache(q), 5000, 0, 0.1, 0.9, 1.0, 1.0, 1)
    np.testing.assert_array_equal(log.reward[3:], log.undelayed_reward[:-3])
    assert not log.reward[:3].any()


def test_flush_at_episode_end_conserves_each_episode():
    env = gym.make("delayed_rl/GridWorld-v0", size=4, max_steps=50, reward_delay=8)
    run = CompiledRun(env, np.array([0, 4]), seed=2)
    q = np.zeros((16, 2, 4))
    log = _run(run, q, _cache(q), 5000, 0, 0.1, 0.9, 0.5, 0.5, 1)
    ends = np.flatnonzero(log.episode_end) + 1
    assert ends.size == 100
    delivered_parts = np.split(log.reward, ends)[:-1]
    undelayed_parts = np.split(log.undelayed_reward, ends)[:-1]
    for delivered, undelayed in zip(delivered_parts, undelayed_parts, strict=True):
        assert delivered.sum() == pytest.approx(undelayed.sum())


def test_same_seed_same_run_and_tables_follow_the_env():
    env = gym.make("delayed_rl/Roulette-v0", reward_delay=2)
    logs = []
    for _ in range(2):
        q = np.zeros((1, 1, 2))
        run = CompiledRun(env, np.array([0]), seed=7)
        logs.append(_run(run, q, _cache(q), 38_000, 0, 0.1, 0.9, 1.0, 1.0, 1))
    np.testing.assert_array_equal(logs[0].undelayed_reward, logs[1].undelayed_reward)
    even = logs[0].undelayed_reward[logs[0].action == 0]
    win = (even == 1).mean()
    se = np.sqrt(18 / 38 * 20 / 38 / even.size)
    assert abs(win - 18 / 38) < 4 * se


def test_unsupported_stacks_are_refused_with_a_reason():
    with pytest.raises(NotCompilable, match="TransformReward is not supported"):
        inspect_stack(gym.wrappers.TransformReward(gym.make("Taxi-v4"), lambda r: 2 * r))
    limit = gym.make("delayed_rl/GridWorld-3x3-v0", max_episode_steps=10)
    limit._max_episode_steps = 2.5  # what TimeLimit's own check would have refused
    with pytest.raises(NotCompilable, match=r"TimeLimit with max_episode_steps=2.5"):
        inspect_stack(limit)
    with pytest.raises(NotCompilable, match="P"):
        inspect_stack(gym.make("CartPole-v1").unwrapped)
    model, wrapper = inspect_stack(gym.make("FrozenLake-v1").unwrapped)
    assert wrapper is None and model.out_cdf.shape[:2] == (16, 4)


@pytest.mark.parametrize("q_init", [0.0, 50.0])
def test_cached_maxima_stay_exact(q_init):
    """After compiled training, each state's cached max and cell agree with a brute-force max."""
    env = gym.make("delayed_rl/GridWorld-v0", size=4, max_steps=300, reward_delay=3)
    q = np.full((16, 8, 4), q_init)
    qmax, qcell = _cache(q)
    run = CompiledRun(env, np.arange(8), seed=3)
    _run(run, q, (qmax, qcell), 20_000, 0, 0.3, 0.9, 0.2, 0.2, 1)
    brute = q.reshape(16, -1).max(axis=1)
    np.testing.assert_array_equal(qmax, brute)
    np.testing.assert_array_equal(run.tie_counts, (q.reshape(16, -1) == brute[:, None]).sum(1))
    np.testing.assert_array_equal(q.reshape(-1)[qcell], brute)
    assert np.all(qcell // 32 == np.arange(16))  # each cell lies in its own state's row


@pytest.mark.parametrize("rescan", [_rescan, _rescan_scalar, _rescan_lanes])
@pytest.mark.parametrize("size", [1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 15, 16, 17, 19, 204, 206])
def test_a_rescan_finds_the_max_its_first_holder_ties_and_the_others_max(rescan, size):
    """Each pass of the rescan against numpy, on rows with many exact ties."""
    rng = np.random.default_rng(size)
    for _ in range(200):
        row = rng.integers(-3, 3, size).astype(float) * rng.choice([1.0, 0.5])
        values = np.concatenate([rng.normal(size=5), row, rng.normal(size=3)])  # an inner row
        best, first, ties, second = rescan(values, 5, size)
        others = np.delete(row, row.argmax())
        assert (best, first, ties) == (row.max(), 5 + row.argmax(), (row == row.max()).sum())
        assert second == (others.max() if size > 1 else -np.inf)


@pytest.mark.parametrize("rescan", [_rescan_scalar, _rescan_lanes])
@pytest.mark.parametrize("size", [1, 3, 5, 8, 16, 19])
def test_a_rescan_counts_minus_infinity_as_a_value(rescan, size):
    """Rows of -inf (an agent's q_init may be -inf): the max, its first holder, ties, others."""
    row = np.full(size, -np.inf)
    assert rescan(row, 0, size) == (-np.inf, 0, size, -np.inf)
    row[-1] = 1.0  # the max in the last entry: the others are all -inf
    assert rescan(row, 0, size) == (1.0, size - 1, 1, -np.inf)


@pytest.mark.parametrize("rescan", [_rescan_scalar, _rescan_lanes])
def test_a_rescan_of_a_row_with_a_nan_stays_in_the_row(rescan):
    values = np.array([7.0, np.nan, 1.0, 2.0, 3.0, np.nan, 2.0, 7.0])
    assert rescan(values, 1, 6)[1] in range(1, 7)
    assert rescan(np.full(9, np.nan), 2, 5)[1] in range(2, 7)


def test_an_average_the_loop_cannot_keep_is_refused():
    env = gym.make("delayed_rl/GridWorld-v0", size=4, reward_delay=3)
    q = np.zeros((16, 2, 4))
    run = CompiledRun(env, np.arange(2), seed=0)
    good = TableAverage(np.zeros_like(q), np.zeros(2, np.int64), 5, 0.1)
    bad = {
        "table": good._replace(table=np.zeros((16, 2, 3))),
        "clock": good._replace(clock=np.zeros(3, np.int64)),
        "every": good._replace(every=0),
        "rate": good._replace(rate=float("nan")),
    }
    for name, average in bad.items():
        with pytest.raises(ValueError, match=f"average's {name}"):
            _run_averaged(run, q, average)
    _run_averaged(run, q, good)  # 10 steps: two updates of the average
    assert good.clock.tolist() == [0, 2] and good.table.shape == q.shape


def _run_averaged(run, q, average):
    return _run(run, q, _cache(q), 10, 0, 0.1, 0.9, 0.1, 0.1, 1, average=average)


@pytest.mark.parametrize(
    "env_id, kwargs", [("delayed_rl/GridWorld-v0", {"size": 4}), ("delayed_rl/Roulette-v0", {})]
)
def test_tie_counts_kept_within_a_call_match_a_fresh_count(env_id, kwargs):
    """One long call and one call per step make the same choices, draw for draw.

    A call counts each state's tied maxima once, at its start, then keeps the counts up to date
    as it learns; they decide whether the acting model is read off the cached arg-max or drawn
    among the tied ones. α = 1, γ = 0 and integer rewards keep many exact ties appearing and
    disappearing: the counts must equal a fresh count after the long call, and the runs must not
    part.
    """
    env = RewardDelay(gym.make(env_id, **kwargs).unwrapped, Constant(2))
    logs, tables = [], []
    for chunk in (3000, 1):
        q = np.zeros((env.observation_space.n, 6, env.action_space.n))
        cache = _cache(q)
        run = CompiledRun(env, np.arange(6), seed=9)
        parts = [
            _run(run, q, cache, chunk, start, 1.0, 0.0, 0.1, 0.1, 1)
            for start in range(0, 3000, chunk)
        ]
        logs.append(
            {key: np.concatenate([getattr(p, key) for p in parts]) for key in parts[0]._fields}
        )
        tables.append(q)
        fresh = (q.reshape(q.shape[0], -1) == q.reshape(q.shape[0], -1).max(1)[:, None]).sum(1)
        np.testing.assert_array_equal(run.tie_counts, fresh)
    assert (
        len(np.unique(logs[0]["acting_delay_index"])) == 6
    )  # ties were broken among all the models
    for key in logs[0]:
        np.testing.assert_array_equal(logs[0][key], logs[1][key], err_msg=key)
    np.testing.assert_array_equal(tables[0], tables[1])


class _Replay(gym.Env):
    """Emits a logged reward stream and its episode ends, whatever the action."""

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, rewards, ends, terminals):
        self.steps = iter(zip(rewards.tolist(), ends.tolist(), terminals.tolist(), strict=True))

    def reset(self, *, seed=None, options=None):
        return 0, {}

    def step(self, action):
        reward, end, terminal = next(self.steps)
        return 0, reward, terminal, end and not terminal, {}


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize(
    "delay, max_delay",
    [
        (Geometric(0.15), None),
        (Uniform(0, 9), None),
        (Empirical([0.5, 0, 0.2, 0.3]), None),
        (Poisson(6.0), 4),
    ],  # fmt: skip
)
def test_compiled_delay_ring_matches_the_wrapper(mode, delay, max_delay):
    """Same delays, same undelayed rewards: the compiled ring delivers what ``RewardDelay`` does.

    The compiled run acts at random on a 4×4 grid that truncates every 40 steps; its log's
    undelayed rewards and episode ends are then fed through the Python wrapper with the same
    scripted delays, episode-end mode and cap.
    """
    draws = delay.sample(np.random.default_rng(3), 4000).tolist()
    grid = gym.make("delayed_rl/GridWorld-v0", size=4, max_steps=40).unwrapped
    env = RewardDelay(grid, ScriptedDelay(draws), max_delay=max_delay, on_episode_end=mode)
    q = np.zeros((16, 1, 4))
    log = _run(
        CompiledRun(env, np.array([0]), seed=5), q, _cache(q), 4000, 0, 0.1, 0.9, 1.0, 1.0, 1
    )
    assert log.episode_end.sum() == 100 and np.count_nonzero(log.undelayed_reward) > 100
    replay = _Replay(log.undelayed_reward, log.episode_end, log.terminated)
    wrapper = RewardDelay(replay, ScriptedDelay(draws), max_delay=max_delay, on_episode_end=mode)
    wrapper.reset(seed=0)
    delivered = []
    for _ in range(4000):
        _, reward, terminated, truncated, _ = wrapper.step(0)
        delivered.append(reward)
        if terminated or truncated:
            wrapper.reset()
    np.testing.assert_allclose(log.reward, delivered, rtol=0, atol=1e-9)


class _ReplayGrid(gym.Env):
    """Emits a logged reward stream, never ending an episode itself (TimeLimits end them)."""

    observation_space = gym.spaces.Discrete(16)
    action_space = gym.spaces.Discrete(4)

    def __init__(self, rewards):
        self.rewards = iter(rewards.tolist())

    def reset(self, *, seed=None, options=None):
        return 0, {}

    def step(self, action):
        return 0, next(self.rewards), False, False, {}


def _stack(env, delay, mode, inner, outer):
    """``TimeLimit(outer)`` over ``RewardDelay`` over ``TimeLimit(inner)`` over ``env``."""
    if inner:
        env = gym.wrappers.TimeLimit(env, inner)
    env = RewardDelay(env, delay, on_episode_end=mode)
    return gym.wrappers.TimeLimit(env, outer) if outer else env


@pytest.mark.filterwarnings("ignore:reset\\(\\) in the middle of an episode discarded")
@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize("inner, outer", [(30, None), (None, 30), (50, 30), (20, 30)])
def test_time_limits_compile_and_deliver_what_the_python_stack_does(mode, inner, outer):
    """A TimeLimit below the RewardDelay ends episodes the wrapper sees (its mode applies).

    One above it cuts them unseen: the reset discards what is pending (kept under "carry").
    """
    draws = Uniform(0, 12).sample(np.random.default_rng(8), 3000).tolist()
    grid = gym.make("delayed_rl/GridWorld-v0", size=4).unwrapped
    env = _stack(grid, ScriptedDelay(draws), mode, inner, outer)
    model, _ = inspect_stack(env)
    cut = outer is not None and (inner is None or outer < inner)
    length = min(x for x in (inner, outer) if x)
    assert model.max_steps == (inner or 0 if cut else length)
    assert model.cut_steps == (outer if cut else 0)
    q = np.zeros((16, 1, 4))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = _run(
            CompiledRun(env, np.array([0]), seed=3), q, _cache(q), 3000, 0, 0.1, 0.9, 1.0, 1.0, 1
        )
    np.testing.assert_array_equal(
        np.flatnonzero(log.episode_end) + 1, np.arange(length, 3001, length)
    )
    assert not log.terminated.any()
    replayed = _stack(_ReplayGrid(log.undelayed_reward), ScriptedDelay(draws), mode, inner, outer)
    replayed.reset(seed=0)
    delivered, ends = [], []
    for _ in range(3000):
        _, reward, terminated, truncated, _ = replayed.step(0)
        delivered.append(reward)
        ends.append(terminated or truncated)
        if ends[-1]:
            replayed.reset()
    np.testing.assert_array_equal(log.reward, delivered)
    np.testing.assert_array_equal(log.episode_end, ends)
    discarding = cut and mode != "carry"
    assert any("cut episodes short" in str(w.message) for w in caught) == discarding
    if mode == "flush" and not cut:  # every episode delivered all of its rewards
        assert log.reward.sum() == log.undelayed_reward.sum() != 0


def _credit_table(steps, **options):
    """The Q-table after ``steps`` compiled MMQ steps, Λ = {0, 1, 2}, on GridWorld-3x3, seed 0."""
    run = CompiledRun(
        RewardDelay(gym.make("delayed_rl/GridWorld-3x3-v0"), Constant(1)), np.arange(3), 0
    )
    q = np.full((9, 3, 4), 1.0)
    _run(run, q, _cache(q), steps, 0, 0.1, 0.9, 0.2, 0.2, 1, **options)
    return q


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"credit_kernel": np.ones(2)}, "credit_kernel must hold a float64 weight per distance"),
        ({"credit_kernel": np.ones(3, np.float32)}, "credit_kernel must hold a float64"),
        ({"trace_decay": 0.5}, r"trace must be a float64 array of shape \(3,\)"),
        ({"trace_decay": 0.5, "trace": np.zeros(2)}, r"trace must be a float64 array"),
        ({"lag_rates": np.ones(2)}, r"lag_rates must be a float64 array of shape \(3,\)"),
        ({"lag_rates": np.ones(3, np.int64)}, r"lag_rates must be a float64 array"),
    ],
)
def test_bad_credit_options_are_refused_by_name(options, message):
    with pytest.raises(ValueError, match=message):
        _credit_table(10, **options)


@pytest.mark.parametrize(
    ("options", "same_as"),
    [
        ({"credit_kernel": np.ones(3)}, {}),  # weight 1 at every distance: the thesis's rule
        ({"lag_rates": np.full(3, 0.1)}, {}),  # α for every lag
        (
            {"credit_kernel": np.ones(3), "trace_decay": 0.5, "trace": np.zeros(3)},
            {"trace_decay": 0.5, "trace": np.zeros(3)},
        ),
        (
            {"lag_rates": np.full(3, 0.1), "trace_decay": 0.5, "trace": np.zeros(3)},
            {"trace_decay": 0.5, "trace": np.zeros(3)},
        ),
    ],
)
def test_an_option_that_changes_nothing_gives_the_loop_without_it(options, same_as):
    """Each combination of options is its own compiled loop: the loops agree to the bit."""
    with_option = _credit_table(3000, **options)
    without = _credit_table(3000, **same_as)
    np.testing.assert_array_equal(with_option, without)
    assert not np.array_equal(without, _credit_table(3000, credit_kernel=np.array([1, 0.5, 0.2])))

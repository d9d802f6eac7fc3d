"""MMQ's options beyond the thesis's rule: the reward kernel, the delay trace, the greedy readout.

With the defaults MMQ is the thesis's rule, draw for draw. With an option on, the Python path and
the compiled loop still agree to the bit: on scripted transitions (``update()`` against
:func:`~delayed_rl.compiled.kernel.replay`), and on a ``learn()`` run replayed through the compiled
loop with the acting models it drew (the two paths of ``learn()`` draw from different streams, so
their runs agree in distribution only).
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import pickle

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import FixedDelayQLearning, MultipleModelQLearning, QLearning
from delayed_rl.agents.common import q_table
from delayed_rl.agents.common.q_table import greedy_actions
from delayed_rl.compiled.kernel import replay
from delayed_rl.compiled.state import credit_kernel

GRID5 = "delayed_rl/GridWorld-5x5-v0"
STATES = np.arange(25)


def make(delay=3, lags=6, **options):
    env = gym.make(GRID5, reward_delay=delay)
    return MultipleModelQLearning(env, max_delay_estimate=lags, q_init=10.0, seed=3, **options)


def recorded_run(agent, steps):
    """``agent.learn(steps)`` on the Python path; every step's transition and acting model."""
    rows = []

    def record(locals_, globals_):
        rows.append(
            (
                locals_["obs"],
                locals_["action"],
                int(locals_["new_obs"][0]),
                locals_["terminated"],
                locals_["reward"],
                locals_["acting_delay_index"],
            )
        )
        assert not locals_["truncated"]  # the grid never ends its episodes: one script
        return True

    agent.learn(steps, callback=record, compiled=False, log_interval=None)
    s, a, s2, terminated, reward, acting = (np.array(column) for column in zip(*rows, strict=True))
    return np.stack([s, a, s2], axis=1), terminated, reward, acting


# ---------------------------------------------------------------------- defaults
# sha256 of q_table.tobytes() before the options existed: GridWorld-5x5, Poisson(3) delays,
# Λ = 0..6, q_init 10, seed 3, 5000 steps (compiled: since deterministic moves stopped drawing
# a uniform number, which changed the compiled stream, not the rule)
PINNED = {True: "5701b5a0d24b8919", False: "71356b05a87c31d0"}


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_defaults_are_the_thesis_rule_draw_for_draw(compiled):
    plain = make().learn(5_000, compiled=compiled, log_interval=None)
    explicit = make(reward_kernel=None, delay_trace=None, greedy_window=None)
    explicit.learn(5_000, compiled=compiled, log_interval=None)
    assert plain.last_learn_path == ("compiled" if compiled else "python")
    np.testing.assert_array_equal(explicit.q_table, plain.q_table)
    assert hashlib.sha256(plain.q_table.tobytes()).hexdigest()[:16] == PINNED[compiled]
    np.testing.assert_array_equal(plain.greedy_table, plain.q_table)
    assert plain.delay_trace_values is None
    assert (plain.reward_kernel, plain.delay_trace, plain.greedy_window) == (None, None, None)


# ---------------------------------------------------------------------- the paths agree
OPTIONS = [
    {"reward_kernel": 2.0},
    {"delay_trace": 0.7},
    {"reward_kernel": 1.5, "delay_trace": 0.9},
]
IDS = ["kernel", "trace", "both"]


@pytest.mark.parametrize("options", OPTIONS, ids=IDS)
@pytest.mark.parametrize("lags", [[0, 2, 5, 11], [3, 4], list(range(8))])
def test_scripted_transitions_give_identical_tables(options, lags):
    """``update()`` (acting model: the greedy one) and the compiled loop, equal to the bit."""
    rng = np.random.default_rng(len(lags))
    n = 2_000
    transitions = rng.integers(0, [6, 4, 6], size=(n, 3))
    rewards = rng.normal(scale=2.0, size=n)
    terminated = rng.random(n) < 0.02
    agent = MultipleModelQLearning(GRID5, delay_estimates=lags, q_init=1.0, **options)
    for (s, a, s2), reward, done in zip(transitions, rewards, terminated, strict=True):
        agent.update(int(s), int(a), float(reward), int(s2), bool(done))
    q = np.full(agent.q_table.shape, 1.0)
    trace = np.zeros(len(lags))
    replay(q, np.array(lags), transitions, terminated, rewards, 0.1, 0.9, **options, trace=trace)
    np.testing.assert_array_equal(agent.q_table, q)
    if "delay_trace" in options:
        np.testing.assert_array_equal(agent.delay_trace_values, trace)
    plain = np.full(agent.q_table.shape, 1.0)
    replay(plain, np.array(lags), transitions, terminated, rewards, 0.1, 0.9)
    assert not np.array_equal(plain, q)  # the option changed something


@pytest.mark.parametrize("options", OPTIONS, ids=IDS)
def test_a_learn_run_replayed_through_the_compiled_loop_is_identical(options):
    """The Python ``learn()``'s steps and acting models, through the compiled loop: same tables."""
    agent = make(**options)
    transitions, terminated, rewards, acting = recorded_run(agent, 4_000)
    assert np.unique(acting).size > 1  # the kernel and the trace saw several acting models
    q = np.full(agent.q_table.shape, 10.0)
    trace = np.zeros(agent.n_models)
    replay(
        q,
        np.array(agent.delay_estimates),
        transitions,
        terminated,
        rewards,
        0.1,
        0.9,
        **options,
        trace=trace,
        acting=acting,
    )
    np.testing.assert_array_equal(agent.q_table, q)
    if "delay_trace" in options:
        np.testing.assert_array_equal(agent.delay_trace_values, trace)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_runs_continue_across_learn_calls(compiled):
    """In pieces with ``reset_num_timesteps=False`` as in one go: tables, trace, average."""
    options = {"reward_kernel": 2.0, "delay_trace": 0.8, "greedy_window": 700}
    whole = make(**options).learn(3_000, compiled=compiled, log_interval=None)
    pieces = make(**options)
    for steps in (1_000, 7, 1_993):
        pieces.learn(steps, compiled=compiled, reset_num_timesteps=False, log_interval=None)
    assert pieces.last_learn_path == ("compiled" if compiled else "python")
    np.testing.assert_array_equal(pieces.q_table, whole.q_table)
    np.testing.assert_array_equal(pieces.delay_trace_values, whole.delay_trace_values)
    np.testing.assert_array_equal(pieces.greedy_table, whole.greedy_table)


# ---------------------------------------------------------------------- the reward kernel
def test_kernel_credits_each_table_the_weighted_reward():
    """λ̂ ∈ {0, 2, 5}, σ = 2, γ = 0, Q = 0: one reward, each table credited r·exp(−(λ̂−λ̂*)²/8)."""
    lags, sigma, r = [0, 2, 5], 2.0, 3.0
    transitions = np.array([[s, 1, s + 1] for s in range(6)])  # distinct states: no interplay
    rewards = np.array([0.0] * 5 + [r])

    def expected(star):
        q = np.zeros((25, 3, 4))
        for j, (lag, s) in enumerate(zip(lags, (5, 3, 0), strict=True)):
            q[s, j, 1] = 0.1 * r * math.exp(-((lag - star) ** 2) / (2 * sigma**2))
        return q

    # the Python path: update()'s acting model is the greedy one, model 0 (all rows tie)
    agent = MultipleModelQLearning(GRID5, delay_estimates=lags, gamma=0.0, reward_kernel=sigma)
    for (s, a, s2), reward in zip(transitions, rewards, strict=True):
        agent.update(int(s), int(a), float(reward), int(s2))
    np.testing.assert_allclose(agent.q_table, expected(0), rtol=1e-15, atol=0)
    # the compiled loop with λ̂* = 2 acting at the rewarded step
    q = np.zeros((25, 3, 4))
    acting = [0] * 5 + [1]
    replay(q, np.array(lags), transitions, np.zeros(6, bool), rewards, 0.1, 0.0,
           reward_kernel=sigma, acting=acting)  # fmt: skip
    np.testing.assert_allclose(q, expected(2), rtol=1e-15, atol=0)
    assert q[3, 1, 1] == 0.1 * r  # the acting model (λ̂ = 2) credits step 3 in full
    weights = credit_kernel(np.array(lags), sigma)
    assert weights.shape == (6,) and weights[0] == 1.0
    assert weights[3] == pytest.approx(math.exp(-9 / 8), rel=1e-15)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_a_very_wide_kernel_is_the_thesis_rule(compiled):
    plain = make().learn(3_000, compiled=compiled, log_interval=None)
    overflowing = make(reward_kernel=1e200).learn(3_000, compiled=compiled, log_interval=None)
    np.testing.assert_array_equal(overflowing.q_table, plain.q_table)  # every weight exactly 1
    narrow = make(reward_kernel=0.5).learn(3_000, compiled=compiled, log_interval=None)
    assert not np.allclose(narrow.q_table, plain.q_table)


def test_a_wide_kernel_approaches_the_thesis_rule():
    """σ = 10⁶ over Λ = 0..11 on scripted steps: weights within 10⁻¹⁰ of 1, tables as close.

    (In ``learn()`` the last bits can flip a tie-break, and the runs part ways.)
    """
    rng = np.random.default_rng(3)
    n, lags = 2_000, np.arange(12)
    transitions = rng.integers(0, [6, 4, 6], size=(n, 3))
    rewards, terminated = rng.normal(size=n), rng.random(n) < 0.02
    wide, thesis = np.ones((25, 12, 4)), np.ones((25, 12, 4))
    replay(wide, lags, transitions, terminated, rewards, 0.1, 0.9, reward_kernel=1e6,
           acting=rng.integers(0, 12, size=n))  # fmt: skip
    replay(thesis, lags, transitions, terminated, rewards, 0.1, 0.9)
    np.testing.assert_allclose(wide, thesis, rtol=1e-9, atol=1e-9)
    assert not np.array_equal(wide, thesis)


def test_a_tiny_kernel_credits_only_the_acting_model():
    weights = credit_kernel(np.array([0, 1, 4]), 1e-300)  # σ² underflows: still no NaN
    np.testing.assert_array_equal(weights, [1.0, 0.0, 0.0, 0.0, 0.0])


# ---------------------------------------------------------------------- the delay trace
def test_trace_values_after_a_known_sequence_of_acting_models():
    """β = 0.5: ``e(λ̂) = β^(steps since λ̂ last acted)``, 0 for a model that never acted."""
    lags = [0, 1, 2, 3]
    trace = np.zeros(4)
    acting = [0, 2, 2, 1]
    transitions = np.array([[0, 0, 1], [1, 0, 2], [2, 0, 3], [3, 0, 4]])
    replay(np.zeros((25, 4, 4)), np.array(lags), transitions, np.zeros(4, bool), np.zeros(4),
           0.1, 0.9, delay_trace=0.5, trace=trace, acting=acting)  # fmt: skip
    np.testing.assert_array_equal(trace, [0.125, 1.0, 0.5, 0.0])
    # the Python path, learning: the trace follows the acting models the behaviour drew
    agent = make(delay_trace=0.5)
    *_, drawn = recorded_run(agent, 500)
    expected = np.zeros(agent.n_models)
    for step, model in enumerate(drawn.tolist()):
        expected[model] = 0.5 ** (len(drawn) - 1 - step)
    np.testing.assert_array_equal(agent.delay_trace_values, expected)


def test_trace_zero_credits_only_the_acting_model():
    """β = 0, γ = 0, Q = 0: the rewarded step writes α·r into the acting model's table only."""
    lags = [0, 1, 2]
    transitions = np.array([[0, 0, 1], [1, 1, 2], [2, 2, 3]])
    rewards = np.array([0.0, 0.0, 2.0])
    q, trace = np.zeros((25, 3, 4)), np.zeros(3)
    replay(q, np.array(lags), transitions, np.zeros(3, bool), rewards, 0.1, 0.0,
           delay_trace=0.0, trace=trace, acting=[2, 0, 1])  # fmt: skip
    np.testing.assert_array_equal(trace, [0.0, 1.0, 0.0])
    expected = np.zeros((25, 3, 4))
    expected[1, 1, 1] = 0.1 * 2.0  # λ̂ = 1 acted: its table credits the step one back
    np.testing.assert_array_equal(q, expected)


def test_trace_one_is_full_credit_once_every_model_has_acted():
    """β = 1: after each model has acted (at reward-free steps), the thesis's rule exactly."""
    rng = np.random.default_rng(7)
    lags = np.array([0, 1, 3, 6])
    n = 1_500
    transitions = rng.integers(0, [8, 4, 8], size=(n, 3))
    rewards = rng.normal(size=n)
    rewards[:4] = 0.0
    acting = rng.integers(0, 4, size=n)
    acting[:4] = [3, 1, 0, 2]
    terminated = np.zeros(n, bool)
    q, trace = np.full((25, 4, 4), 2.0), np.zeros(4)
    replay(q, lags, transitions, terminated, rewards, 0.1, 0.9, delay_trace=1.0, trace=trace,
           acting=acting)  # fmt: skip
    thesis = np.full((25, 4, 4), 2.0)
    replay(thesis, lags, transitions, terminated, rewards, 0.1, 0.9)
    np.testing.assert_array_equal(q, thesis)
    np.testing.assert_array_equal(trace, np.ones(4))


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_trace_carries_over_episode_ends(compiled):
    env = gym.make(GRID5, reward_delay=2, max_steps=7)  # an episode every 7 steps
    agent = MultipleModelQLearning(env, max_delay_estimate=4, q_init=10.0, seed=1, delay_trace=0.5)
    agent.learn(35, compiled=compiled, record=True, log_interval=None)
    drawn = agent.training_log["acting_delay_index"]
    assert agent.training_log["episode_end"].sum() == 5
    expected = np.zeros(agent.n_models)
    for step, model in enumerate(drawn.tolist()):
        expected[model] = 0.5 ** (len(drawn) - 1 - step)
    np.testing.assert_array_equal(agent.delay_trace_values, expected)


# ---------------------------------------------------------------------- the greedy readout
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_greedy_table_is_the_moving_average_of_the_q_table(compiled):
    window = 1_000
    interval = window // 100
    agent = make(greedy_window=window)
    np.testing.assert_array_equal(agent.greedy_table, agent.q_table)  # before any update
    average = None
    for _ in range(300):
        agent.learn(interval, compiled=compiled, reset_num_timesteps=False, log_interval=None)
        q = agent.q_table.copy()
        average = q if average is None else average + (interval / window) * (q - average)
    np.testing.assert_array_equal(agent.greedy_table, average)
    assert not np.array_equal(agent.greedy_table, agent.q_table)
    # the deterministic policy reads it; the exploring one and λ̂* read the live table
    np.testing.assert_array_equal(
        agent.predict(STATES, deterministic=True)[0], greedy_actions(agent.greedy_table)
    )
    agent.exploration_rate = 0.0
    actions = agent.predict(STATES)[0]
    q = agent.q_table
    best = q.reshape(25, -1).max(axis=1)
    for s, a in zip(STATES, actions, strict=True):
        assert q[s, :, a].max() == best[s]
    with pytest.raises(ValueError, match="read-only"):
        agent.greedy_table[0, 0, 0] = 1.0


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_greedy_updates_fall_on_the_same_training_steps_in_one_run(compiled):
    """One ``learn()`` call averages at every ``interval``-th step, as the pieces above did."""
    window = 250  # interval 2
    whole = make(greedy_window=window).learn(999, compiled=compiled, log_interval=None)
    pieces = make(greedy_window=window)
    average = None
    for steps in [2] * 499 + [1]:
        pieces.learn(steps, compiled=compiled, reset_num_timesteps=False, log_interval=None)
        if pieces.num_timesteps % 2 == 0:
            q = pieces.q_table.copy()
            average = q if average is None else average + (2 / window) * (q - average)
    np.testing.assert_array_equal(pieces.greedy_table, average)
    np.testing.assert_array_equal(whole.greedy_table, average)
    np.testing.assert_array_equal(whole.q_table, pieces.q_table)


def test_greedy_window_counts_update_steps_and_small_windows():
    agent = MultipleModelQLearning(
        GRID5, delay_estimates=[0, 1], greedy_window=1
    )  # interval 1, weight 1: G = Q
    agent.update(0, 1, 5.0, 1)
    np.testing.assert_array_equal(agent.greedy_table, agent.q_table)
    agent = MultipleModelQLearning(GRID5, delay_estimates=[0, 1], greedy_window=300)  # interval 3
    for step in range(5):
        agent.update(step, 1, 5.0, step + 1)
        if step == 2:
            first = agent.q_table.copy()
    np.testing.assert_array_equal(agent.greedy_table, first)  # updated once, at step 3


def test_the_averaged_table_counts_towards_the_memory_limit(monkeypatch):
    plain = q_table.table_bytes(25, 4, 7, 6)
    assert q_table.table_bytes(25, 4, 7, 6, averaged_table=True) == plain + 8 * 25 * 7 * 4
    monkeypatch.setattr(q_table, "MAX_TABLE_BYTES", plain + 100)
    make()  # fits
    with pytest.raises(ValueError, match="needs .* GiB of tables"):
        make(greedy_window=100)


# ---------------------------------------------------------------------- copies and files
ALL = {"reward_kernel": 2.5, "delay_trace": 0.75, "greedy_window": 400}


def assert_same_state(a, b):
    np.testing.assert_array_equal(a.q_table, b.q_table)
    np.testing.assert_array_equal(a.delay_trace_values, b.delay_trace_values)
    np.testing.assert_array_equal(a.greedy_table, b.greedy_table)
    assert (a.reward_kernel, a.delay_trace, a.greedy_window) == (
        b.reward_kernel,
        b.delay_trace,
        b.greedy_window,
    )


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
@pytest.mark.parametrize(
    "duplicate",
    [copy.deepcopy, lambda agent: pickle.loads(pickle.dumps(agent))],
    ids=["deepcopy", "pickle"],
)
def test_copies_keep_the_options_and_continue_exactly(compiled, duplicate):
    original = make(**ALL).learn(1_001, compiled=compiled, log_interval=None)
    twin = duplicate(original)
    assert_same_state(twin, original)
    assert not np.shares_memory(twin.delay_trace_values, original._credit.trace)
    for agent in (original, twin):
        agent.learn(1_500, compiled=compiled, reset_num_timesteps=False, log_interval=None)
        agent.update(3, 1, 1.0, 4)
    assert_same_state(twin, original)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_save_load_keeps_the_options_and_training_continues_exactly(tmp_path, compiled):
    original = make(**ALL).learn(1_001, compiled=compiled, log_interval=None)
    path = original.save(tmp_path / "m")
    with np.load(path) as data:
        saved = json.loads(str(data["metadata"]))["hyperparameters"]
    assert {name: saved[name] for name in ALL} == ALL
    loaded = MultipleModelQLearning.load(path, env=gym.make(GRID5, reward_delay=3))
    assert_same_state(loaded, original)
    original.set_env(gym.make(GRID5, reward_delay=3))  # a fresh env, as the loaded agent's
    for agent in (original, loaded):
        agent.learn(1_500, compiled=compiled, reset_num_timesteps=False, log_interval=None)
    assert_same_state(loaded, original)


def test_files_written_before_the_options_load_with_the_defaults(tmp_path):
    agent = make().learn(100)
    path = agent.save(tmp_path / "m")
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    metadata = json.loads(str(arrays["metadata"]))
    for name in ALL:
        assert metadata["hyperparameters"].pop(name) is None
    arrays["metadata"] = np.array(json.dumps(metadata))
    with open(tmp_path / "old.npz", "wb") as file:
        np.savez(file, **arrays)
    old = MultipleModelQLearning.load(tmp_path / "old.npz")
    assert (old.reward_kernel, old.delay_trace, old.greedy_window) == (None, None, None)
    np.testing.assert_array_equal(old.q_table, agent.q_table)


def test_a_file_missing_the_trace_is_refused(tmp_path):
    path = make(delay_trace=0.5).learn(100).save(tmp_path / "m")
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files if key != "delay_trace"}
    with open(tmp_path / "bad.npz", "wb") as file:
        np.savez(file, **arrays)
    with pytest.raises(ValueError, match="delay_trace must be a float64 array"):
        MultipleModelQLearning.load(tmp_path / "bad.npz")


def test_single_model_agents_do_not_take_the_options(tmp_path):
    for agent in (QLearning(GRID5, seed=0), FixedDelayQLearning(GRID5, delay_estimate=2, seed=0)):
        assert not set(ALL) & set(type(agent)._hyperparameter_names)
        path = agent.learn(200).save(tmp_path / type(agent).__name__)
        loaded = type(agent).load(path)
        np.testing.assert_array_equal(loaded.q_table, agent.q_table)
        with pytest.raises(ValueError, match="custom_objects may override"):
            type(agent).load(path, custom_objects={"greedy_window": 10})
    with pytest.raises(TypeError, match="unexpected keyword argument 'reward_kernel'"):
        QLearning(GRID5, reward_kernel=1.0)


# ---------------------------------------------------------------------- bad values
@pytest.mark.parametrize(
    ("options", "error", "message"),
    [
        ({"reward_kernel": 0}, ValueError, r"reward_kernel must be None or a number > 0, got 0"),
        ({"reward_kernel": -1.0}, ValueError, "reward_kernel"),
        ({"reward_kernel": float("inf")}, ValueError, "reward_kernel"),
        ({"reward_kernel": float("nan")}, ValueError, "reward_kernel"),
        ({"reward_kernel": "1"}, TypeError, r"reward_kernel must be .*'1' \(str\)"),
        ({"reward_kernel": True}, TypeError, "reward_kernel"),
        ({"delay_trace": 1.5}, ValueError, r"delay_trace must be None or a number in \[0, 1\]"),
        ({"delay_trace": -0.1}, ValueError, "delay_trace"),
        ({"delay_trace": "0.5"}, TypeError, "delay_trace"),
        ({"greedy_window": 0}, ValueError, r"greedy_window must be None or an integer >= 1"),
        ({"greedy_window": 2.5}, TypeError, r"greedy_window must be .*2.5 \(float\)"),
        ({"greedy_window": True}, TypeError, "greedy_window"),
    ],
)
def test_bad_option_values_are_refused_with_the_argument_named(options, error, message):
    with pytest.raises(error, match=message):
        MultipleModelQLearning(GRID5, **options)

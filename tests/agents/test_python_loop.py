"""The Python training path at its floor: the same numbers as the numpy rule it replaced.

The compiled batch update of MMQ, the Python-scalar views of the tables, the random streams and
the reward-delay wrapper's refusal of a non-finite reward are each checked against a reference
written out here (the numpy code they replaced) or against a run that never took the shortcut.
"""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from delayed_rl.agents import FixedDelayQLearning, MultipleModelQLearning, QLearning
from delayed_rl.agents.common.streams import UniformStream
from delayed_rl.agents.mmq.updates import FULL_CREDIT, NO_OPTION, model_weights, update_models
from delayed_rl.delays import Poisson
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import RewardDelay


def numpy_update(q, v_max, v_cell, history, positions, r, alpha, gamma, terminal):
    """The numpy batch update of MMQ before it was compiled (``r`` a number or one per model)."""
    n_states, n_models, n_actions = q.shape
    q_rows, q_flat = q.reshape(n_states, -1), q.reshape(-1)
    n = positions.size
    states = history[0][positions]
    cells = history[2][positions] + np.arange(n) * n_actions
    bootstrap = v_max[history[1][positions]]
    if terminal:
        bootstrap[0] = 0.0
    target = r + gamma * bootstrap
    old = q_flat[cells]
    new = old + alpha * (target - old)
    q_flat[cells] = new
    old_max = v_max[states]
    fell = (v_cell[states] == cells) & (new < old)
    if fell.any():
        repaired = np.unique(states[fell])
        arg = q_rows[repaired].argmax(axis=1)
        v_max[repaired] = q_rows[repaired, arg]
        v_cell[repaired] = repaired * q_rows.shape[1] + arg
    rose = new > old_max
    if rose.any():
        rose_states, rose_values, rose_cells = states[rose], new[rose], cells[rose]
        np.maximum.at(v_max, rose_states, rose_values)
        top = rose_values == v_max[rose_states]
        v_cell[rose_states[top]] = rose_cells[top]


def exact_cache(q):
    """Each state's max over its row and the flat index of its first arg-max."""
    rows = q.reshape(q.shape[0], -1)
    return rows.max(axis=1), np.arange(q.shape[0]) * rows.shape[1] + rows.argmax(axis=1)


@pytest.mark.parametrize("seed", range(40))
def test_compiled_batch_update_is_the_numpy_one(seed: int) -> None:
    """Same tables and caches (the cached cells included), ties and repeated states included."""
    rng = np.random.default_rng(seed)
    n_states, n_models, n_actions, ring = 4, int(rng.integers(2, 7)), 3, 8
    q = rng.choice([0.0, 0.5, 1.0, 2.0], size=(n_states, n_models, n_actions))
    v_max, v_cell = exact_cache(q)
    history = np.stack(
        [
            rng.integers(0, n_states, ring),
            rng.integers(0, n_states, ring),
            rng.integers(0, n_states, ring) * n_models * n_actions
            + rng.integers(0, n_actions, ring),
        ]
    )
    positions = rng.integers(0, ring, n_models)
    if seed % 3 == 0:  # transitions grouped by state: several models update one state
        positions = history[0].argsort()[:n_models]
    r, alpha, gamma, terminal = float(rng.choice([-1.0, 0.0, 1.0])), 0.5, 0.9, bool(seed % 2)
    weights = rng.choice([0.0, 0.5, 1.0], n_models) if seed % 4 == 1 else FULL_CREDIT
    expected = [q.copy(), v_max.copy(), v_cell.copy()]
    credit = r if weights is FULL_CREDIT else r * weights
    numpy_update(*expected, history, positions, credit, alpha, gamma, terminal)
    q_flat = q.reshape(-1)
    args = (positions, n_models, 0, ring - 1, r, weights, alpha, gamma, terminal, n_actions)
    update_models(q_flat, v_max, v_cell, history, *args)
    for got, want in zip((q, v_max, v_cell), expected, strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("options", ["kernel", "trace", "both"])
def test_compiled_model_weights_are_the_numpy_ones(options: str) -> None:
    rng = np.random.default_rng(len(options))
    estimates = np.sort(rng.choice(40, 9, replace=False)).astype(np.int64)
    kernel = np.exp(-(np.arange(40.0) ** 2) / 8.0) if options != "trace" else None
    trace = rng.uniform(0, 1, 9) if options != "kernel" else None
    for acting in rng.integers(0, 9, 20).tolist():
        expected_trace = None if trace is None else trace * 0.7
        if expected_trace is not None:
            expected_trace[acting] = 1.0
        expected = expected_trace
        if kernel is not None:
            expected = kernel[np.abs(estimates - estimates[acting])]
            expected = expected if expected_trace is None else expected * expected_trace
        got = model_weights(
            NO_OPTION if trace is None else trace,
            0.7,
            NO_OPTION if kernel is None else kernel,
            estimates,
            acting,
        )
        np.testing.assert_array_equal(got, expected)
        if trace is not None:
            np.testing.assert_array_equal(trace, expected_trace)


def _trained(agent_class, **kwargs):
    env = RewardDelay(GridWorldEnv(size=4, max_steps=40), Poisson(2))
    agent = agent_class(env, q_init=5.0, seed=3, **kwargs)
    return agent.learn(1_500, compiled=False)


@pytest.mark.parametrize(
    ("agent_class", "kwargs"),
    [
        (QLearning, {}),
        (FixedDelayQLearning, {"delay_estimate": 2}),
        (MultipleModelQLearning, {"max_delay_estimate": 4}),
    ],
)
@pytest.mark.parametrize("duplicate", [copy.deepcopy, lambda a: pickle.loads(pickle.dumps(a))])
def test_copies_learn_into_their_own_tables(agent_class, kwargs, duplicate) -> None:
    """The scalar views are rebuilt on a copy: it learns what the original learns, apart."""
    agent = _trained(agent_class, **kwargs)
    twin = duplicate(agent)
    before = agent.q_table.copy()
    twin.learn(1_000, reset_num_timesteps=False, compiled=False)
    np.testing.assert_array_equal(agent.q_table, before)
    assert not np.array_equal(twin.q_table, before)
    agent.learn(1_000, reset_num_timesteps=False, compiled=False)
    np.testing.assert_array_equal(agent.q_table, twin.q_table)
    for trained in (agent, twin):
        v_max, _ = exact_cache(trained.q_table)
        np.testing.assert_array_equal(trained._table.v_max, v_max)
        rows = trained.q_table.reshape(trained.n_states, -1)
        cells = trained._table.v_cell - np.arange(trained.n_states) * rows.shape[1]
        np.testing.assert_array_equal(rows[np.arange(trained.n_states), cells], v_max)


def test_single_model_agents_choose_with_the_action_choice() -> None:
    """One model: the behaviour policy is the action choice, the same draws as MMQ's."""
    assert QLearning._choose is FixedDelayQLearning._choose  # the one-table choice of QAgent
    q, mmq = _trained(QLearning), _trained(MultipleModelQLearning, delay_estimates=[0])
    np.testing.assert_array_equal(q.q_table, mmq.q_table)
    for agent in (q, mmq):
        agent._table.values[...] = 1.0  # every action tied: a random tie-break at every greedy step
        agent._table.rebuild_cache()
    draws = [[agent._choose(s % 16, 0.3, agent._uniform) for s in range(300)] for agent in (q, mmq)]
    assert draws[0] == draws[1]
    assert len({action for _, action in draws[0]}) == 4


@pytest.mark.parametrize("taken", [0, 1, 700, 1023, 1024, 1025, 2500])
def test_uniform_stream_resumes_from_its_state_and_copies(taken: int) -> None:
    stream = UniformStream.from_seed(11)
    reference = UniformStream.from_seed(11)
    expected = [reference() for _ in range(taken + 3000)]
    assert [stream.next() for _ in range(taken)] == expected[:taken]
    state, remaining = stream.get_state()
    assert remaining.size == (-taken) % UniformStream.BLOCK_SIZE
    restored = UniformStream.from_seed(0)
    restored.set_state(state, remaining)
    for twin in (restored, copy.deepcopy(stream), pickle.loads(pickle.dumps(stream)), stream):
        assert [twin() for _ in range(3000)] == expected[taken:]


def test_a_refused_reward_leaves_the_delay_wrapper_as_it_was() -> None:
    """A non-finite reward raises before the step counts: the delays and the clock stay put."""

    class Scripted(gym.Env):
        observation_space, action_space = spaces.Discrete(1), spaces.Discrete(1)

        def __init__(self, rewards):
            self.rewards = iter(rewards)

        def reset(self, *, seed=None, options=None):
            return 0, {}

        def step(self, action):
            return 0, next(self.rewards), False, False, {}

    rewards = [1.0, 0.0, -2.0, 0.5] * 300
    plain = RewardDelay(Scripted(rewards), Poisson(3), record_arrivals=True)
    refused = RewardDelay(
        Scripted([*rewards[:5], float("inf"), float("nan"), *rewards[5:]]),
        Poisson(3),
        record_arrivals=True,
    )
    plain.reset(seed=5)
    refused.reset(seed=5)
    for step in range(len(rewards)):
        if step == 5:
            for _ in range(2):
                with pytest.raises(ValueError, match="non-finite reward .* at episode step 5"):
                    refused.step(0)
        assert refused.step(0) == plain.step(0)

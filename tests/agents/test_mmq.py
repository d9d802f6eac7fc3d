"""Multiple Model Q-learning's rule, exactly.

The thesis's Roulette walk-through, a brute-force reference implementation, the cached maxima,
and the single-model special cases.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import examples

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import FixedDelayQLearning, MultipleModelQLearning, QLearning
from delayed_rl.agents.reference import ReferenceMMQ
from delayed_rl.delays import Constant
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.envs.roulette import BET_13, BET_EVEN
from delayed_rl.wrappers import RewardDelay

ALPHA, GAMMA, Q0 = 0.1, 0.9, 50.0


def roulette_agent() -> MultipleModelQLearning:
    return MultipleModelQLearning(
        gym.make("delayed_rl/Roulette-v0"),
        learning_rate=ALPHA,
        gamma=GAMMA,
        q_init=Q0,
        max_delay_estimate=2,
    )


def test_roulette_walkthrough_tables_3_2_to_3_5():
    """Thesis section 3.2: λ̂max = 2, α = 0.1, γ = 0.9, Q initialised to 50, one state."""
    agent = roulette_agent()
    assert agent.delay_estimates == [0, 1, 2]
    assert agent.q_table.shape == (1, 3, 2)
    np.testing.assert_array_equal(agent.q_table, np.full((1, 3, 2), 50.0))  # Table 3.2

    # Round 1: bet even, nothing arrives. Only λ̂ = 0 has a step to credit.
    agent.update(0, BET_EVEN, 0.0, 0)
    expected = np.full((3, 2), Q0)
    expected[0, BET_EVEN] = Q0 + ALPHA * (0.0 + GAMMA * Q0 - Q0)
    np.testing.assert_allclose(agent.q_table[0], expected, rtol=0, atol=1e-12)
    assert agent.q_table[0, 0, BET_EVEN] == pytest.approx(49.50, abs=1e-12)  # Table 3.3

    # Round 2: bet 13, its $35 arrives at once. λ̂ = 0 credits the bet on 13, λ̂ = 1 round 1's
    # bet on even; λ̂ = 2 has no step two rounds back.
    agent.update(0, BET_13, 35.0, 0)
    max_before = Q0  # the max over all models at s′ before this step's writes
    expected[0, BET_13] = Q0 + ALPHA * (35.0 + GAMMA * max_before - Q0)
    expected[1, BET_EVEN] = Q0 + ALPHA * (35.0 + GAMMA * max_before - Q0)
    np.testing.assert_allclose(agent.q_table[0], expected, rtol=0, atol=1e-12)
    assert agent.q_table[0, 0, BET_13] == pytest.approx(53.0, abs=1e-12)  # Table 3.4
    assert agent.q_table[0, 1, BET_EVEN] == pytest.approx(53.0, abs=1e-12)

    # Round 3: bet even; round 1's loss (−1) arrives. All three models learn, every target from
    # the max *before* this step's writes (53, not the new values): the parallel update.
    max_before = 53.0
    agent.update(0, BET_EVEN, -1.0, 0)
    exact_even_0 = 49.5 + ALPHA * (-1.0 + GAMMA * max_before - 49.5)
    exact_13_1 = Q0 + ALPHA * (-1.0 + GAMMA * max_before - Q0)
    exact_even_2 = Q0 + ALPHA * (-1.0 + GAMMA * max_before - Q0)
    expected[0, BET_EVEN], expected[1, BET_13], expected[2, BET_EVEN] = (
        exact_even_0,
        exact_13_1,
        exact_even_2,
    )
    np.testing.assert_allclose(agent.q_table[0], expected, rtol=0, atol=1e-12)
    assert exact_even_0 == pytest.approx(49.22, abs=1e-12)
    assert exact_13_1 == pytest.approx(49.67, abs=1e-12)
    # Table 3.5 as printed (2 decimals): λ̂=0: 49.22 53.00, λ̂=1: 53.00 49.67, λ̂=2: 49.67 50.00
    thesis = np.array([[49.22, 53.00], [53.00, 49.67], [49.67, 50.00]])
    np.testing.assert_allclose(agent.q_table[0], thesis, rtol=0, atol=0.005)
    assert agent.num_timesteps == 3


def test_roulette_round_four_uses_all_models_max():
    """After Table 3.5 the max at s′ over all models is still 53 (λ̂=0 on 13, λ̂=1 on even)."""
    agent = roulette_agent()
    for action, reward in ((BET_EVEN, 0.0), (BET_13, 35.0), (BET_EVEN, -1.0)):
        agent.update(0, action, reward, 0)
    assert agent._table.v_max[0] == 53.0
    before = agent.q_table.copy()
    agent.update(0, BET_13, 1.0, 0)  # round 4 on 13; credits rounds 4, 3, 2
    assert agent.q_table[0, 0, BET_13] == pytest.approx(
        before[0, 0, BET_13] + ALPHA * (1 + 47.7 - 53)
    )
    assert agent.q_table[0, 1, BET_EVEN] == pytest.approx(
        before[0, 1, BET_EVEN] + ALPHA * (1 + 47.7 - 53)
    )
    assert agent.q_table[0, 2, BET_13] == pytest.approx(Q0 + ALPHA * (1 + 47.7 - Q0))


transitions = st.lists(
    st.tuples(
        st.integers(0, 8),  # s
        st.integers(0, 3),  # a
        st.sampled_from([0.0, 1.0, -1.0, 10.0, 0.25]),  # r
        st.integers(0, 8),  # s′
        st.booleans(),  # terminated (rare below)
        st.booleans(),  # truncated
        st.integers(0, 9),  # makes terminations/truncations rare
    ),
    min_size=1,
    max_size=60,
)


@settings(max_examples=examples(60), deadline=None)
@given(
    delays=st.lists(st.integers(0, 6), min_size=1, max_size=5, unique=True),
    q_init=st.sampled_from([0.0, 5.0, 20.0]),
    steps=transitions,
)
def test_matches_reference_and_cache_is_exact(delays, q_init, steps):
    """Same tables as the brute-force reference, and the cached max/arg-max always exact."""
    env = GridWorldEnv(size=3)
    agent = MultipleModelQLearning(
        env, q_init=q_init, delay_estimates=delays, learning_rate=0.3, gamma=0.9
    )
    reference = ReferenceMMQ(9, 4, sorted(delays), q_init, 0.3, 0.9)
    for s, a, r, s2, terminated, truncated, rare in steps:
        terminated, truncated = terminated and rare == 0, truncated and rare == 1
        agent.update(s, a, r, s2, terminated=terminated, truncated=truncated)
        reference.update(s, a, r, s2, terminated, truncated)
        np.testing.assert_array_equal(agent.q_table, reference.q)
        rows = agent.q_table.reshape(9, -1)
        np.testing.assert_array_equal(agent._table.v_max, rows.max(axis=1))
        cells = agent._table.v_cell - np.arange(9) * rows.shape[1]
        np.testing.assert_array_equal(rows[np.arange(9), cells], agent._table.v_max)


@settings(max_examples=examples(40), deadline=None)
@given(
    values=st.lists(st.sampled_from([-1.0, 0.0, 0.5, 1.0]), min_size=12, max_size=12),
    s=st.integers(0, 2),
    seed=st.integers(0, 2**16),
)
def test_vector_and_scalar_paths_agree(values, s, seed):
    """The one-model fast path and the batched path give identical tables and caches."""
    rng = np.random.default_rng(seed)
    env = GridWorldEnv(size=3)
    scalar = MultipleModelQLearning(env, delay_estimates=[0])
    batched = MultipleModelQLearning(env, delay_estimates=[0])
    for agent in (scalar, batched):
        agent._table.values[:3] = np.array(values).reshape(3, 1, 4)
        agent._table.rebuild_cache()
    for _ in range(30):
        a, s2, r = int(rng.integers(4)), int(rng.integers(9)), float(rng.normal())
        scalar.update(s, a, r, s2)
        # the same one-model update, forced through the batched path
        batched._history.record(0, s, s2, s * batched._table.row_size + a)
        batched._update_models(1, r, False, None, 0)
        np.testing.assert_array_equal(scalar.q_table, batched.q_table)
        np.testing.assert_array_equal(scalar._table.v_max, batched._table.v_max)
        np.testing.assert_array_equal(scalar._table.v_cell, batched._table.v_cell)
        s = s2


def test_terminal_transition_does_not_bootstrap():
    env = GridWorldEnv(size=3)
    agent = MultipleModelQLearning(
        env, q_init=5.0, delay_estimates=[0, 1], learning_rate=0.5, gamma=0.9
    )
    agent.update(1, 0, 0.0, 2)
    agent.update(2, 0, 1.0, 3, terminated=True)
    # λ̂=0, the terminal step itself: target = r (no bootstrap)
    assert agent.q_table[2, 0, 0] == pytest.approx(5.0 + 0.5 * (1.0 - 5.0))
    # λ̂=1, step 0 (not terminal): bootstraps from the max at its s′ = 2 before the writes
    assert agent.q_table[1, 1, 0] == pytest.approx(5.0 + 0.5 * (1.0 + 0.9 * 5.0 - 5.0))
    # the episode ended: the next step has no history, only λ̂=0 learns
    before = agent.q_table.copy()
    agent.update(4, 1, 0.0, 5)
    changed = np.argwhere(agent.q_table != before)
    np.testing.assert_array_equal(changed, [[4, 0, 1]])


def test_q_learning_is_mmq_with_lambda_zero():
    """Same seed, same env: identical tables, actions and rewards, step for step."""

    def run(agent_cls, **kwargs):
        env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=3)
        agent = agent_cls(env, q_init=15.0, seed=7, **kwargs)
        return agent.learn(5_000, record=True)

    q = run(QLearning)
    mmq = run(MultipleModelQLearning, delay_estimates=[0])
    fixed = run(FixedDelayQLearning, delay_estimate=0)
    for other in (mmq, fixed):
        np.testing.assert_array_equal(q.q_table, other.q_table)
        for key in ("obs", "action", "reward"):
            np.testing.assert_array_equal(q.training_log[key], other.training_log[key])
    assert q.q_table.shape == (25, 1, 4)
    assert len(np.unique(q.training_log["obs"])) > 5  # it explored, so the check has teeth


@pytest.mark.parametrize("k", [2, 5])
def test_fixed_delay_learns_optimal_5x5_policy_under_constant_delay(k):
    """Under a constant delay k, FixedDelayQLearning(delay_estimate=k) assigns credit exactly.

    Its greedy policy walks start → reward cell in 2(n−1) moves and collects +10 at step
    2(n−1)+1 = 9.
    """
    n = 5
    env = RewardDelay(GridWorldEnv(size=n), Constant(k))
    agent = FixedDelayQLearning(env, delay_estimate=k, q_init=20.0, seed=k).learn(30_000)
    assert agent.delay_estimate == k and agent.delay_estimates == [k]
    world = GridWorldEnv(size=n)
    state, _ = world.reset()
    rewards = []
    for _ in range(2 * (n - 1) + 1):
        action, _ = agent.predict(state, deterministic=True)
        state, reward, *_ = world.step(action)
        rewards.append(reward)
    assert rewards == [0.0] * (2 * (n - 1)) + [10.0]


def test_q_learning_misses_constant_delay_that_fixed_delay_handles():
    """Plain Q-learning under the same constant delay credits the wrong steps.

    It does not learn the route (a control for the test above, so that one cannot pass by luck).
    """
    n, k = 5, 5
    agent = QLearning(RewardDelay(GridWorldEnv(size=n), Constant(k)), q_init=20.0, seed=k)
    agent.learn(30_000, record=True)
    fixed = FixedDelayQLearning(
        RewardDelay(GridWorldEnv(size=n), Constant(k)), delay_estimate=k, q_init=20.0, seed=k
    )
    fixed.learn(30_000, record=True)
    tail = slice(-10_000, None)
    assert (
        fixed.training_log["undelayed_reward"][tail].mean()
        > agent.training_log["undelayed_reward"][tail].mean() + 0.2
    )


def test_fixed_delay_updates_nothing_before_k_steps():
    agent = FixedDelayQLearning(GridWorldEnv(size=3), delay_estimate=3, q_init=1.0)
    for t in range(3):
        agent.update(t, 0, 5.0, t + 1)
        np.testing.assert_array_equal(agent.q_table, np.ones((9, 1, 4)))
    agent.update(3, 1, 5.0, 4)  # credits step 0: (s=0, a=0)
    assert agent.q_table[0, 0, 0] == pytest.approx(1.0 + 0.1 * (5.0 + 0.9 * 1.0 - 1.0))
    assert np.count_nonzero(agent.q_table != 1.0) == 1


def test_acting_picks_best_model_then_best_action():
    env = GridWorldEnv(size=3)
    agent = MultipleModelQLearning(
        env, delay_estimates=[0, 4, 9], exploration_initial_eps=0.0, exploration_final_eps=0.0
    )
    agent._table.values[2, 1, 3] = 7.0  # model λ̂=4 holds the best value at state 2, on action 3
    agent._table.values[2, 2, 0] = 6.0
    agent._table.rebuild_cache()
    for _ in range(20):
        assert agent._choose(2, 0.0, agent._uniform) == (1, 3)
    assert agent.preferred_delay(2) == 4
    np.testing.assert_array_equal(agent.preferred_delay([2, 0]), [4, 0])
    assert agent.predict(2, deterministic=True)[0] == 3


def test_tie_breaks_are_uniform_at_both_levels():
    """All-equal table: λ̂* uniform over 3 models, then a* uniform over 4 actions (greedy, ε=0).

    12 cells, 6000 draws: each count ~ Binomial(6000, 1/12), sd ≈ 21.4; 5 sd bound.
    """
    agent = MultipleModelQLearning(GridWorldEnv(size=3), delay_estimates=[0, 1, 2], seed=3)
    counts = np.zeros((3, 4))
    for _ in range(6000):
        model, action = agent._choose(0, 0.0, agent._uniform)
        counts[model, action] += 1
    sd = np.sqrt(6000 * (1 / 12) * (11 / 12))
    assert np.all(np.abs(counts - 500) < 5 * sd)


def test_two_level_tie_break_is_over_models_first():
    """Model 0 ties on 3 actions, model 1 on 1 action: λ̂* is 50/50.

    Not 3:1, as a flat tie-break over cells would give. 4000 draws, sd of a count = 31.6; 5 sd
    bound.
    """
    agent = MultipleModelQLearning(GridWorldEnv(size=3), delay_estimates=[0, 1], seed=5)
    agent._table.values[0] = 0.0
    agent._table.values[0, 0, :3] = 1.0
    agent._table.values[0, 1, 2] = 1.0
    agent._table.rebuild_cache()
    models = [agent._choose(0, 0.0, agent._uniform)[0] for _ in range(4000)]
    assert abs(models.count(1) - 2000) < 5 * np.sqrt(4000 * 0.25)


def test_exploration_rate_one_is_uniform_over_actions():
    """ε = 1: actions uniform regardless of the table. 4000 draws; sd of a count ≈ 27.4."""
    agent = MultipleModelQLearning(GridWorldEnv(size=3), delay_estimates=[0, 1], seed=1)
    agent._table.values[0, 0, 2] = 100.0
    agent._table.rebuild_cache()
    actions = np.array([agent._choose(0, 1.0, agent._uniform)[1] for _ in range(4000)])
    counts = np.bincount(actions, minlength=4)
    assert np.all(np.abs(counts - 1000) < 5 * np.sqrt(4000 * 0.25 * 0.75))


def test_acting_share_and_record_during_learn():
    env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=2)
    agent = MultipleModelQLearning(env, max_delay_estimate=4, q_init=10.0, seed=0).learn(
        3_000, record=True
    )
    share = agent.acting_delay_share
    assert share.shape == (5,) and share.sum() == pytest.approx(1.0)
    index = agent.training_log["acting_delay_index"]
    np.testing.assert_allclose(np.bincount(index, minlength=5) / 3_000, share)
    metrics = agent.logger.dumps[-1]
    assert metrics["mmq/acting_delay_mean"] == pytest.approx(float(share @ np.arange(5)), rel=1e-9)


def test_delay_estimate_arguments():
    env = GridWorldEnv(size=3)
    assert MultipleModelQLearning(env).delay_estimates == list(range(51))  # the thesis's λ̂max = 50
    assert MultipleModelQLearning(env, max_delay_estimate=10, delay_step=5).delay_estimates == [
        0,
        5,
        10,
    ]
    assert MultipleModelQLearning(env, delay_estimates=[7, 2, 0]).delay_estimates == [0, 2, 7]
    assert MultipleModelQLearning(env, delay_estimates=range(3, 6)).q_table.shape == (9, 3, 4)
    with pytest.raises(ValueError, match="either delay_estimates or max_delay_estimate"):
        MultipleModelQLearning(env, delay_estimates=[1], max_delay_estimate=3)
    with pytest.raises(ValueError, match="distinct"):
        MultipleModelQLearning(env, delay_estimates=[1, 1])
    with pytest.raises(ValueError, match="delay_estimates"):
        MultipleModelQLearning(env, delay_estimates=[])
    with pytest.raises(ValueError, match="delay_estimates"):
        MultipleModelQLearning(env, delay_estimates=[-1, 2])
    with pytest.raises(TypeError, match="delay_estimates"):
        MultipleModelQLearning(env, delay_estimates="012")
    with pytest.raises(
        ValueError, match="max_delay_estimate must be None or an integer >= 0, got -1"
    ):
        MultipleModelQLearning(env, max_delay_estimate=-1)
    with pytest.raises(ValueError, match="delay_step must be an integer >= 1, got 0"):
        MultipleModelQLearning(env, delay_step=0)
    with pytest.raises(TypeError, match="delay_estimate must be an integer >= 0, got 2.5"):
        FixedDelayQLearning(env, delay_estimate=2.5)
    with pytest.raises(ValueError, match="delay_estimate must be an integer >= 0, got -1"):
        FixedDelayQLearning(env, -1)

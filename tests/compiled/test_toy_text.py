"""``gym.make`` of Gymnasium's toy-text envs runs compiled, under any delay wrapper.

``gym.make`` adds ``PassiveEnvChecker``, ``OrderEnforcing`` and (for Taxi and FrozenLake) a
``TimeLimit``; all three compile. The compiled run's transitions are checked against the env's
own table ``P``, its episode ends against the limit, and its Q-table against the Python rule
fed the same transitions through ``update()`` (to the last bit).
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

from delayed_rl.agents import MultipleModelQLearning, QLearning
from delayed_rl.delays import Geometric
from delayed_rl.wrappers import PoissonRewardDelay, RewardDelay

STEPS = 6000


def outcomes(env, s, a):
    """``{next_state: (reward, terminated)}`` of the env's table for (s, a)."""
    return {s2: (r, term) for p, s2, r, term in env.unwrapped.P[s][a] if p > 0}


def logged_next_states(env, log):
    """Each step's next state: the next step's, or at an episode end the table's only outcome.

    (Deterministic envs only: the next state of an episode's last step is not logged.)
    """
    obs, actions, ends = log["obs"], log["action"], log["episode_end"].astype(bool)
    following = np.append(obs[1:], -1)
    ends = ends.copy()
    ends[-1] = True
    for t in np.flatnonzero(ends):
        (following[t],) = outcomes(env, int(obs[t]), int(actions[t]))
    return following


@pytest.mark.parametrize(
    "env_id, kwargs, limit",
    [
        ("Taxi-v4", {}, 200),
        ("CliffWalking-v1", {}, None),
        ("FrozenLake-v1", {"is_slippery": False}, 100),
        ("FrozenLake8x8-v1", {"is_slippery": False}, 200),
    ],
)
@pytest.mark.parametrize("wrap", ["poisson", "geometric-carry", "none"])
def test_gym_make_toy_text_runs_compiled_and_is_the_python_rule(env_id, kwargs, limit, wrap):
    env = gym.make(env_id, **kwargs)
    if wrap == "poisson":
        env = PoissonRewardDelay(env, 3.0)
    elif wrap == "geometric-carry":
        env = RewardDelay(env, Geometric(0.3), on_episode_end="carry")
    settings = {"delay_estimates": [0, 2, 4], "learning_rate": 0.5, "seed": 1}
    agent = MultipleModelQLearning(env, **settings).learn(STEPS, record=True)
    assert agent.last_learn_path == "compiled"  # compiled by default
    log = agent.training_log
    s2 = logged_next_states(env, log)
    ends = np.flatnonzero(log["episode_end"])
    lengths = np.diff(np.concatenate([[-1], ends]))
    for t in range(STEPS):  # every step is an outcome of the env's own table
        reward, terminated = outcomes(env, int(log["obs"][t]), int(log["action"][t]))[int(s2[t])]
        assert log["undelayed_reward"][t] == reward
        assert bool(log["episode_end"][t]) == (terminated or t in ends)
    if limit is not None:
        assert lengths.max() <= limit
        assert (lengths == limit).any() or env_id.startswith("FrozenLake")
    python = MultipleModelQLearning(env, **settings)
    for t in range(STEPS):
        terminated = outcomes(env, int(log["obs"][t]), int(log["action"][t]))[int(s2[t])][1]
        python.update(
            int(log["obs"][t]), int(log["action"][t]), float(log["reward"][t]), int(s2[t]),
            terminated, bool(log["episode_end"][t]) and not terminated,
        )  # fmt: skip
    np.testing.assert_array_equal(agent.q_table, python.q_table)


def test_slippery_frozen_lake_compiles_with_the_tables_probabilities():
    """FrozenLake's slippery moves: each intended direction or one of its two neighbours, ⅓ each."""
    env = gym.make("FrozenLake-v1")
    agent = QLearning(env, seed=0, exploration_initial_eps=1.0, exploration_final_eps=1.0)
    agent.learn(60_000, record=True)
    assert agent.last_learn_path == "compiled"
    log = agent.training_log
    keep = ~log["episode_end"][:-1].astype(bool)  # steps whose next state is logged
    s, a, s2 = log["obs"][:-1][keep], log["action"][:-1][keep], log["obs"][1:][keep]
    start = (s == 0) & (a == 1)  # from the start, "down": down 1/3, left (stay) 1/3, right 1/3
    counts = np.array([np.sum(s2[start] == x) for x in (4, 0, 1)])
    n = counts.sum()
    assert n > 1000
    # a 1/3 share's standard error is sqrt(2/9 / n): within 4 of them
    assert np.all(np.abs(counts / n - 1 / 3) < 4 * np.sqrt(2 / 9 / n))


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_an_agent_is_warned_of_the_flush_trap_on_either_path(compiled):
    env = PoissonRewardDelay(gym.make("FrozenLake-v1"), lam=5)
    with pytest.warns(UserWarning, match="at an episode's final step"):
        QLearning(env, seed=0).learn(20_000, compiled=compiled)
    env = PoissonRewardDelay(gym.make("Taxi-v4"), lam=5)  # rewards along the way
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        QLearning(env, seed=0).learn(5_000, compiled=compiled)

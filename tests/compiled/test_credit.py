"""The compiled expected-credit and oracle rules: the Python rule, update for update.

Each test lets the compiled loop act and learn (``learn(compiled=True, record=True)``), then feeds
the same transitions, one by one, to a fresh agent's Python ``update()`` — for the oracle through
a Python ``RewardDelay`` with the same scripted delays, whose ``info["reward_arrivals"]`` it
reads — and asserts the two Q-tables are equal to the last bit.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from support import ScriptedDelay

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import ExpectedCreditQLearning, OracleQLearning
from delayed_rl.delays import Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import RewardDelay

STEPS = 3000
SETTINGS = {"learning_rate": 0.3, "q_init": 5.0, "gamma": 0.9}


def grid(size=4, max_steps=40):
    """A size×size grid world that truncates its episodes after ``max_steps`` steps."""
    return gym.make("delayed_rl/GridWorld-v0", size=size, max_steps=max_steps)


def next_states(log, table):
    """Each logged step's next state: the next step's state, or the grid's at an episode end."""
    obs, actions = log["obs"], log["action"]
    following = np.append(obs[1:], -1)
    ends = log["episode_end"].astype(bool)
    ends[-1] = True  # the run's last step: its next state is not logged either
    following[ends] = table[obs[ends], actions[ends]]
    return following


class LoggedGrid(gym.Env):
    """Replays a logged run's rewards and episode ends, whatever the action (grid's spaces)."""

    def __init__(self, log, size):
        self.observation_space = gym.spaces.Discrete(size * size)
        self.action_space = gym.spaces.Discrete(4)
        self.steps = iter(
            zip(log["undelayed_reward"].tolist(), log["episode_end"].tolist(), strict=True)
        )

    def reset(self, *, seed=None, options=None):
        return 0, {}

    def step(self, action):
        reward, end = next(self.steps)
        return 0, reward, False, end, {}


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize(
    "delay, bound",
    [(Poisson(3.0), 8), (Geometric(0.2), None), (Empirical([0.5, 0, 0, 0.5]), None)],
)
def test_compiled_expected_credit_is_the_python_rule(mode, delay, bound):
    """The wrapper's clip and the agent's modelled bound set alike (``None``: the pmf's own)."""
    env = RewardDelay(grid(), delay, max_delay=bound, on_episode_end=mode)
    make = {"delay": delay, "max_delay_estimate": bound, **SETTINGS}
    compiled = ExpectedCreditQLearning(env, seed=3, **make)
    compiled.learn(STEPS, compiled=True, record=True)
    assert compiled.last_learn_path == "compiled"
    log = compiled.training_log
    assert np.count_nonzero(log["reward"]) > 50  # rewards came, and got credited
    python = ExpectedCreditQLearning(env, seed=3, **make)
    s2 = next_states(log, env.unwrapped.next_state)
    for t in range(STEPS):
        python.update(
            int(log["obs"][t]), int(log["action"][t]), float(log["reward"][t]), int(s2[t]),
            truncated=bool(log["episode_end"][t]),
        )  # fmt: skip
    np.testing.assert_array_equal(compiled.q_table, python.q_table)
    assert python.credit_weights.size > 3  # several lags shared each update


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize("max_steps", [40, None])
def test_compiled_oracle_is_the_python_rule(mode, max_steps):
    """Delays up to 59 steps: arrivals late, out of order, flushed, dropped, carried over.

    Beyond the 32 transitions the oracle holds for a ``ScriptedDelay``, arrivals are ignored.
    """
    draws = Uniform(0, 59).sample(np.random.default_rng(4), STEPS).tolist()
    draws[:6] = [5, 0, 3, 1, 0, 2]  # arrivals out of order at once
    env = RewardDelay(
        grid(max_steps=max_steps), ScriptedDelay(draws), record_arrivals=True, on_episode_end=mode
    )
    compiled = OracleQLearning(env, seed=5, **SETTINGS)
    assert compiled.history_length == 32  # a ScriptedDelay of mean 1: 1 + 10 + 20 steps back
    compiled.learn(STEPS, compiled=True, record=True)
    assert compiled.last_learn_path == "compiled"
    log = compiled.training_log
    replayed = RewardDelay(
        LoggedGrid(log, 4), ScriptedDelay(draws), record_arrivals=True, on_episode_end=mode
    )
    python = OracleQLearning(replayed, seed=5, **SETTINGS)
    replayed.reset(seed=0)
    s2 = next_states(log, env.unwrapped.next_state)
    arrived = 0
    for t in range(STEPS):
        action = int(log["action"][t])
        _, reward, terminated, truncated, info = replayed.step(action)
        assert reward == log["reward"][t]  # the compiled ring delivered what the wrapper does
        arrived += len(info["reward_arrivals"])
        python.update(
            int(log["obs"][t]), action, reward, int(s2[t]), terminated, truncated,
            info=info,
        )  # fmt: skip
        if terminated or truncated:
            replayed.reset()
    np.testing.assert_array_equal(compiled.q_table, python.q_table)
    assert np.count_nonzero(log["reward"]) > 50
    if max_steps and mode == "flush":  # 75 whole episodes: every reward came by its end
        assert arrived == STEPS
    elif max_steps and mode == "drop":  # the rewards still pending at an episode's end: none
        assert 0 < arrived < STEPS - 500
    else:  # all but those still pending (delays < 60 steps)
        assert arrived > STEPS - 60


@pytest.mark.parametrize("agent", ["oracle", "expected credit"])
def test_the_compiled_rules_learn_the_grid_under_poisson_delays(agent):
    """5×5 grid, Poisson(5) delays, 100k compiled steps: the greedy policy walks the loop."""
    from delayed_rl.experiments.framework.snapshot_runs import greedy_policy, is_optimal

    env = RewardDelay(gym.make("delayed_rl/GridWorld-5x5-v0"), Poisson(5.0), record_arrivals=True)
    settings = {"q_init": 25.0, "exploration_initial_eps": 0.1, "exploration_final_eps": 0.1}
    if agent == "oracle":
        trained = OracleQLearning(env, seed=0, **settings)
    else:
        trained = ExpectedCreditQLearning(env, delay=5.0, max_delay_estimate=30, seed=0, **settings)
    trained.learn(100_000)  # compiled by default
    assert trained.last_learn_path == "compiled"
    assert is_optimal(greedy_policy(trained), 5)

"""The cooperative two-agent grid world: its rules by hand-computed cases, determinism, PettingZoo's API."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.delays import Poisson
from delayed_rl.multiagent import CooperativeGridWorldEnv, ParallelRewardDelay

UP, RIGHT, DOWN, LEFT = 0, 1, 2, 3
A, B = "agent_0", "agent_1"
# pettingzoo.test imports envs the way PettingZoo 1.27 deprecates
pytestmark = pytest.mark.filterwarnings(
    "ignore:The old environment creation API:DeprecationWarning"
)


def placed(first, second, size=5, max_steps=100):
    """A reset env with the agents on cells ``first`` and ``second``."""
    env = CooperativeGridWorldEnv(size, max_steps=max_steps)
    env.reset(seed=0, options={"states": {A: first, B: second}})
    return env


def test_both_agents_start_on_the_bottom_right_cell_and_see_their_own_cell():
    env = CooperativeGridWorldEnv()
    observations, infos = env.reset(seed=3)
    assert observations == {A: 24, B: 24} and infos == {A: {}, B: {}}
    assert env.agents == env.possible_agents == [A, B]
    assert env.observation_space(A).n == 25 and env.action_space(B).n == 4
    assert env.state() == 24 * 25 + 24 and env.state_space.n == 625
    observations, rewards, terminated, truncated, _ = env.step({A: UP, B: LEFT})
    assert observations == {A: 19, B: 23}  # each moves on its own
    assert rewards == {A: 0.0, B: 0.0}
    assert terminated == truncated == {A: False, B: False}
    assert env.state() == 19 * 25 + 23


@pytest.mark.parametrize(
    ("actions", "reward", "cells"),
    [
        ({A: DOWN, B: RIGHT}, -2.0, {A: 24, B: 24}),  # both into a wall: -1 each, shared
        ({A: DOWN, B: UP}, -1.0, {A: 24, B: 19}),  # one wall: the team pays -1
        ({A: LEFT, B: UP}, 0.0, {A: 23, B: 19}),
    ],
)
def test_a_wall_costs_the_team_minus_one_per_agent_that_walks_into_it(actions, reward, cells):
    env = placed(24, 24)
    observations, rewards, *_ = env.step(actions)
    assert observations == cells
    assert rewards == {A: reward, B: reward}  # one shared reward


def test_an_agent_alone_on_the_reward_cell_waits_there_at_no_cost():
    env = placed(0, 12)
    for action, other in zip((UP, LEFT, RIGHT, DOWN), (LEFT, RIGHT, LEFT, RIGHT), strict=True):
        observations, rewards, *_ = env.step({A: action, B: other})  # up, left: walls elsewhere
        assert observations[A] == 0 and rewards == {A: 0.0, B: 0.0}
    assert env.positions == {A: 0, B: 12}


def test_both_on_the_reward_cell_pays_both_ten_and_warps_both_home():
    env = placed(0, 1)
    observations, rewards, *_ = env.step({A: DOWN, B: LEFT})  # B arrives: nothing yet
    assert observations == {A: 0, B: 0} and rewards == {A: 0.0, B: 0.0}
    observations, rewards, *_ = env.step({A: DOWN, B: RIGHT})  # any joint action collects
    assert observations == {A: 24, B: 24} and rewards == {A: 10.0, B: 10.0}
    observations, rewards, *_ = env.step({A: UP, B: UP})  # and they walk again
    assert observations == {A: 19, B: 19} and rewards == {A: 0.0, B: 0.0}


def test_the_optimal_joint_walk_earns_ten_every_nine_steps():
    env = CooperativeGridWorldEnv(size=5, max_steps=100)
    assert env.optimal_average_reward == pytest.approx(10 / 9)
    assert env.optimal_episode_reward(100) == 110.0 and env.optimal_episode_reward(8) == 0.0
    observations, _ = env.reset(seed=0)
    total, ends = 0.0, 0
    while env.agents:
        actions = {agent: UP if cell >= 5 else LEFT for agent, cell in observations.items()}
        observations, rewards, _, truncated, _ = env.step(actions)
        assert rewards[A] == rewards[B]
        total += rewards[A]
        ends += truncated[A]
    assert total == 110.0 == env.optimal_episode_reward(100) and ends == 1
    assert env.steps == 100


def test_one_dawdling_agent_makes_the_other_wait():
    """A goes straight there, B wastes 4 steps: the first +10 comes at step 13, not 9."""
    env = CooperativeGridWorldEnv(size=5, max_steps=None)
    env.reset(seed=0)
    route = [UP] * 4 + [LEFT] * 4
    late = [LEFT, RIGHT, LEFT, RIGHT, *route]  # 4 wasted steps, no wall
    paid = []
    for t in range(13):
        actions = {A: route[t] if t < 8 else DOWN, B: late[t] if t < 12 else DOWN}
        paid.append(env.step(actions)[1][A])
    assert paid == [0.0] * 12 + [10.0]  # A waited on the reward cell from step 8, at no cost
    assert env.positions == {A: 24, B: 24}


def test_episodes_end_by_truncation_after_max_steps():
    env = CooperativeGridWorldEnv(size=3, max_steps=2)
    env.reset()
    *_, truncated, _ = env.step({A: UP, B: UP})
    assert truncated == {A: False, B: False} and env.agents == [A, B]
    _, rewards, terminated, truncated, infos = env.step({A: UP, B: UP})
    assert truncated == {A: True, B: True} and terminated == {A: False, B: False}
    assert set(rewards) == set(infos) == {A, B} and env.agents == []
    with pytest.raises(ValueError, match="call reset"):
        env.step({A: UP, B: UP})
    env.reset()
    assert env.agents == [A, B] and env.steps == 0


@pytest.mark.parametrize(
    ("actions", "error", "match"),
    [
        ({A: True, B: 0}, TypeError, "integer"),
        ({A: 1.0, B: 0}, TypeError, "integer"),
        ({A: 4, B: 0}, ValueError, "Discrete"),
        ({A: 0}, ValueError, "every live agent"),
        ({A: 0, B: 0, "agent_2": 0}, ValueError, "every live agent"),
    ],
)
def test_bad_actions_are_refused(actions, error, match):
    env = placed(24, 24)
    with pytest.raises(error, match=match):
        env.step(actions)
    assert env.positions == {A: 24, B: 24} and env.steps == 0  # nothing moved


def test_numpy_integer_actions_are_actions():
    env = placed(24, 24)
    assert env.step({A: np.int64(UP), B: np.array(LEFT)})[0] == {A: 19, B: 23}


@pytest.mark.parametrize(
    ("options", "error"),
    [
        ({"states": [0, 1]}, TypeError),
        ({"states": {"agent_9": 0}}, ValueError),
        ({"states": {A: 25}}, ValueError),
        ({"states": {A: 2.0}}, TypeError),
    ],
)
def test_bad_start_states_are_refused(options, error):
    with pytest.raises(error, match="options"):
        CooperativeGridWorldEnv().reset(options=options)


def test_a_partial_start_leaves_the_other_on_the_start_cell_and_other_keys_are_ignored():
    env = CooperativeGridWorldEnv()
    assert env.reset(options={"states": {B: 7}, "other": 1})[0] == {A: 24, B: 7}


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"size": 1}, ValueError),
        ({"size": 3.0}, TypeError),
        ({"size": 1000}, ValueError),
        ({"max_steps": 0}, ValueError),
        ({"max_steps": "5"}, TypeError),
        ({"render_mode": "human"}, ValueError),
    ],
)
def test_bad_arguments_are_refused(kwargs, error):
    with pytest.raises(error):
        CooperativeGridWorldEnv(**kwargs)


def test_ansi_render_shows_the_reward_cell_and_the_agents():
    env = CooperativeGridWorldEnv(size=3, render_mode="ansi")
    env.reset(options={"states": {A: 4}})
    assert env.render() == "R . .\n. 0 .\n. . 1\n"
    env.reset()
    assert env.render() == "R . .\n. . .\n. . B\n"
    assert CooperativeGridWorldEnv(size=3).render() is None


def _trajectory(env, seed, steps=250):
    """Observations, rewards and ends of ``steps`` steps of seeded random joint actions."""
    actions = np.random.default_rng(99).integers(0, 4, size=(steps, 2))
    out, observations = [], env.reset(seed=seed)[0]
    for a0, a1 in actions.tolist():
        observations, rewards, _, truncated, _ = env.step({A: a0, B: a1})
        out.append((observations, rewards, truncated))
        if not env.agents:
            observations = env.reset()[0]
    return out


def test_the_same_seed_and_actions_give_the_same_episode_delays_included():
    plain = _trajectory(CooperativeGridWorldEnv(max_steps=60), 1)
    assert plain == _trajectory(CooperativeGridWorldEnv(max_steps=60), 1)
    assert plain == _trajectory(CooperativeGridWorldEnv(max_steps=60), 2)  # nothing random
    assert any(step[1][A] < 0 for step in plain)  # walls: the delays have rewards to move

    def delayed(seed):
        return _trajectory(ParallelRewardDelay(CooperativeGridWorldEnv(max_steps=60), 3), seed)

    assert delayed(1) == delayed(1) != delayed(2)  # the agents' delays follow the seed


def test_a_flushed_reward_delay_gives_each_agent_the_teams_return():
    env = ParallelRewardDelay(CooperativeGridWorldEnv(max_steps=40), Poisson(5))
    env.reset(seed=0, options={"states": {A: 0, B: 0}})
    delivered, undelayed = {A: 0.0, B: 0.0}, 0.0
    step = 0
    while env.agents:
        actions = {A: (step % 4), B: (step * 3 % 4)}
        _, rewards, _, _, infos = env.step(actions)
        for agent in rewards:
            delivered[agent] += rewards[agent]
        undelayed += infos[A]["undelayed_reward"]
        assert infos[A]["undelayed_reward"] == infos[B]["undelayed_reward"]
        step += 1
    assert undelayed != 0 and delivered == {A: undelayed, B: undelayed}


def test_pettingzoos_parallel_api_and_seed_tests_pass():
    from pettingzoo.test import parallel_api_test, parallel_seed_test

    parallel_api_test(CooperativeGridWorldEnv(max_steps=50), num_cycles=120)
    parallel_api_test(ParallelRewardDelay(CooperativeGridWorldEnv(max_steps=50), 4))
    parallel_seed_test(lambda: CooperativeGridWorldEnv(max_steps=50))

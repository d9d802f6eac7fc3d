"""GridWorldEnv: the thesis dynamics cell by cell, continuing task, optimal average reward."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.envs.gridworld import DOWN, LEFT, RIGHT, UP, GridWorldEnv

SIZES = [3, 5, 9]


def expected_transition(size: int, state: int, action: int) -> tuple[int, float]:
    """The thesis dynamics, written independently of the env's tables."""
    if state == 0:  # the reward cell: any action pays +10 and warps to the start
        return size * size - 1, 10.0
    row, col = divmod(state, size)
    d_row, d_col = {UP: (-1, 0), RIGHT: (0, 1), DOWN: (1, 0), LEFT: (0, -1)}[action]
    row2, col2 = row + d_row, col + d_col
    if not (0 <= row2 < size and 0 <= col2 < size):
        return state, -1.0  # a wall: penalised, stays
    return row2 * size + col2, 0.0


@pytest.mark.parametrize("size", SIZES)
def test_dynamics_cell_by_cell(size: int) -> None:
    env = GridWorldEnv(size=size)
    assert env.observation_space == gym.spaces.Discrete(size * size)
    assert env.action_space == gym.spaces.Discrete(4)
    for state in range(size * size):
        for action in range(4):
            obs, info = env.reset(options={"state": state})
            assert obs == state
            obs, reward, terminated, truncated, info = env.step(action)
            assert (obs, reward) == expected_transition(size, state, action), (state, action)
            assert terminated is False and truncated is False
            assert env.P[state][action] == [(1.0, obs, reward, False)]


def test_row_major_numbering_and_walls_3x3() -> None:
    env = GridWorldEnv(size=3)
    assert env.reset(seed=0)[0] == 8  # bottom-right start
    # from the start: right and down hit walls, up goes to 5, left to 7
    table = {(8, RIGHT): (8, -1.0), (8, DOWN): (8, -1.0), (8, UP): (5, 0.0), (8, LEFT): (7, 0.0)}
    table |= {(1, UP): (1, -1.0), (3, LEFT): (3, -1.0), (1, LEFT): (0, 0.0), (3, UP): (0, 0.0)}
    table |= {(4, UP): (1, 0.0), (4, RIGHT): (5, 0.0), (4, DOWN): (7, 0.0), (4, LEFT): (3, 0.0)}
    table |= {(0, a): (8, 10.0) for a in range(4)}
    for (state, action), outcome in table.items():
        env.reset(options={"state": state})
        assert env.step(action)[:2] == outcome, (state, action)


@pytest.mark.parametrize("size", SIZES)
def test_up_left_policy_achieves_the_optimal_average_reward(size: int) -> None:
    env = GridWorldEnv(size=size)
    state, _ = env.reset(seed=0)
    cycle = 2 * (size - 1) + 1
    steps = cycle * 200
    total = 0.0
    for _ in range(steps):
        row, _col = divmod(state, size)
        state, reward, terminated, truncated, _ = env.step(UP if row > 0 else LEFT)
        total += reward
        assert not (terminated or truncated)
    assert total / steps == pytest.approx(10.0 / cycle, rel=1e-12)
    assert env.optimal_average_reward == pytest.approx(10.0 / cycle)
    if size == 9:
        assert env.optimal_average_reward == pytest.approx(0.588, abs=5e-4)


def test_never_terminates_by_default() -> None:
    env = GridWorldEnv(size=5)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(5000):
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        assert not terminated and not truncated


@pytest.mark.parametrize("max_steps", [1, 7, 30])
def test_max_steps_truncates(max_steps: int) -> None:
    env = GridWorldEnv(size=3, max_steps=max_steps)
    for _ in range(2):
        env.reset()
        for t in range(1, max_steps + 1):
            *_, terminated, truncated, _ = env.step(UP)
            assert terminated is False and truncated == (t == max_steps)


@pytest.mark.parametrize(
    "env_id",
    ["delayed_rl/GridWorld-3x3-v0", "delayed_rl/GridWorld-5x5-v0", "delayed_rl/GridWorld-9x9-v0"],
)
def test_check_env_registered(env_id: str) -> None:
    env = gym.make(env_id)
    check_env(env.unwrapped)
    assert env.unwrapped.size == int(env_id.split("-")[1].split("x")[0])


def test_check_env_generic_id_with_size() -> None:
    env = gym.make("delayed_rl/GridWorld-v0", size=4)
    check_env(env.unwrapped)
    assert env.observation_space == gym.spaces.Discrete(16)
    assert gym.make("delayed_rl/GridWorld-v0").unwrapped.size == 9


def test_seeded_determinism_with_reward_delay() -> None:
    def run(seed):
        env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=3.0)
        env.reset(seed=seed)
        env.action_space.seed(seed)
        return [
            env.step(env.action_space.sample())[1:2] + (env.unwrapped.state,) for _ in range(300)
        ]

    assert run(1) == run(1)
    assert run(1) != run(2)


def test_pickle_round_trip_mid_episode() -> None:
    env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=6, max_steps=200)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(40):
        env.step(env.action_space.sample())
    clone = pickle.loads(pickle.dumps(env))
    actions = [env.action_space.sample() for _ in range(200)]
    a = [env.step(x) for x in actions]
    b = [clone.step(x) for x in actions]
    assert a == b
    assert a[-1][3] is True  # reached the truncation with the rest flushed
    assert sum(x[4]["drawn_reward_delay"] for x in a) > 0


def test_render_ansi() -> None:
    env = GridWorldEnv(size=3, render_mode="ansi")
    env.reset()
    assert env.render() == "R . .\n. . .\n. . A\n"
    assert GridWorldEnv(size=3).render() is None


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"size": 1}, ValueError, "size"),
        ({"size": 3.0}, TypeError, "size"),
        ({"size": True}, TypeError, "size"),
        ({"max_steps": 0}, ValueError, "max_steps"),
        ({"max_steps": 2.5}, TypeError, "max_steps"),
        ({"render_mode": "human"}, ValueError, "render_mode"),
    ],
)
def test_invalid_arguments(kwargs, exc, name) -> None:
    with pytest.raises(exc, match=name):
        GridWorldEnv(**kwargs)


@pytest.mark.parametrize(
    ("name", "wrong_type", "bad_value"),
    [("size", "5", 1), ("max_steps", "5", -1), ("render_mode", 1, "human")],
)
def test_each_argument_refuses_a_wrong_type_and_a_bad_value(name, wrong_type, bad_value) -> None:
    with pytest.raises(TypeError, match=name):
        GridWorldEnv(**{name: wrong_type})
    with pytest.raises(ValueError, match=name):
        GridWorldEnv(**{name: bad_value})


def test_valid_argument_types() -> None:
    env = GridWorldEnv(size=np.int64(3), max_steps=np.int32(4))
    assert (type(env.size), type(env.max_steps)) == (int, int)
    assert env.observation_space.n == 9


def test_invalid_action_and_start_state() -> None:
    env = GridWorldEnv(size=3)
    env.reset()
    with pytest.raises(ValueError, match="action"):
        env.step(4)
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": 9})
    with pytest.raises(TypeError, match="state"):
        env.reset(options={"state": "3"})
    assert env.reset(options={"state": np.int64(4)})[0] == 4
    np.testing.assert_array_equal(env.initial_state_distrib, np.eye(9)[8])

"""ProportionalController: thesis Eqs. 5.8–5.9, predict() semantics, env formats."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.agents.proportional import ProportionalController
from delayed_rl.envs.linefollow.camera import line_centroid
from delayed_rl.envs.linefollow.env import WHEEL_SPEED_ACTIONS, EPuckLineFollowEnv

CONTINUOUS = EPuckLineFollowEnv(action_mode="continuous")


@pytest.mark.parametrize(
    ("m", "left", "right"),
    [
        (20, 300, 300),  # centred: full speed
        (25, 300, 240),  # line right of centre: slow the right wheel, turn right
        (15, 240, 300),  # line left of centre: slow the left wheel, turn left
        (40, 300, 60),  # Δ = 20: the extreme
        (1, 72, 300),  # Δ = −19
    ],
)
def test_equations_5_8_and_5_9(m, left, right):
    ctrl = ProportionalController(CONTINUOUS)
    assert ctrl.wheel_speeds(m).tolist() == [left, right]
    action, state = ctrl.predict(m)
    assert action.dtype == np.float32 and action.shape == (2,)
    assert action.tolist() == pytest.approx([left / 300, right / 300])
    assert np.array_equal(state, action)


def test_gain_and_base_speed():
    ctrl = ProportionalController(CONTINUOUS, k_p=2.0, base_speed=200)
    assert ctrl.wheel_speeds(30).tolist() == [200, 160]
    assert ctrl.predict(20)[0].tolist() == pytest.approx([2 / 3, 2 / 3])


def test_batched_predict_matches_single_predicts():
    ctrl = ProportionalController(CONTINUOUS)
    obs = np.arange(1, 41)
    actions, states = ctrl.predict(obs)
    assert actions.shape == (40, 2) and states.shape == (40, 2)
    for m, action in zip(obs, actions, strict=True):
        assert np.array_equal(ctrl.predict(int(m))[0], action)


def test_unseen_line_repeats_the_last_command_from_the_state():
    ctrl = ProportionalController(CONTINUOUS)
    action, state = ctrl.predict(0)  # no state: straight ahead at base speed
    assert action.tolist() == [1.0, 1.0]
    _, state = ctrl.predict(35)
    action, state2 = ctrl.predict(0, state=state)
    assert np.array_equal(action, state) and np.array_equal(state2, state)
    action, _ = ctrl.predict(0, state=state, episode_start=True)
    assert action.tolist() == [1.0, 1.0]
    # Batched: only the unseen rows use the state; episode starts reset per row.
    _, states = ctrl.predict(np.array([5, 35, 30]))
    actions, _ = ctrl.predict(np.array([0, 0, 20]), state=states, episode_start=[False, True, True])
    assert np.array_equal(actions[0], states[0])
    assert actions[1].tolist() == [1.0, 1.0]
    assert actions[2].tolist() == [1.0, 1.0]


def test_discrete_env_gets_the_nearest_table_5_2_action():
    env = EPuckLineFollowEnv(action_mode="discrete")
    ctrl = ProportionalController(env=env)
    assert ctrl.predict(20)[0] == 3  # (300, 300)
    assert ctrl.predict(40)[0] == 5  # (300, 60) → (300, 100)
    assert ctrl.predict(1)[0] == 1  # (72, 300) → (100, 300)
    actions, _ = ctrl.predict(np.arange(1, 41))
    assert actions.shape == (40,)
    table = np.asarray(WHEEL_SPEED_ACTIONS)
    speeds = ctrl.wheel_speeds(np.arange(1, 41))
    for a, v in zip(actions, speeds, strict=True):
        distance = ((table - v) ** 2).sum(axis=1)
        assert distance[a] == distance.min()
    assert env.action_space.contains(int(actions[0]))


def test_pixel_env_predicts_from_the_pixels():
    env = EPuckLineFollowEnv(observation_mode="pixels", action_mode="continuous")
    ctrl = ProportionalController(env=env)
    obs, info = env.reset(seed=0)
    action, _ = ctrl.predict(obs)
    assert np.array_equal(action, ProportionalController(CONTINUOUS).predict(info["centroid"])[0])
    rows = np.stack([obs, np.zeros(40, np.float32)])
    actions, _ = ctrl.predict(rows)
    assert actions.shape == (2, 2) and line_centroid(rows).tolist() == [info["centroid"], 0]


def test_env_id_and_wrapped_envs_are_accepted():
    ctrl = ProportionalController(env="delayed_rl/EPuckLineFollow-v0")
    assert ctrl.discrete_actions and not ctrl.pixel_observations
    wrapped = gym.make("delayed_rl/EPuckLineFollow-v0", action_mode="continuous")
    ctrl = ProportionalController(env=wrapped)
    assert not ctrl.discrete_actions and ctrl.get_env() is wrapped


def test_predict_on_the_env_turns_towards_the_line():
    # The line right of centre (m > 20) → the robot turns right (clockwise, heading decreases).
    env = EPuckLineFollowEnv(track="oval", action_mode="continuous", max_steps=None)
    obs, info = env.reset(seed=0, options={"pose": (0.75 - 0.012, 0.0, np.pi / 2)})  # inside
    assert obs > 20
    action, _ = ProportionalController(env=env).predict(obs)
    assert action[0] > action[1]
    heading = info["pose"][2]
    assert env.step(action)[4]["pose"][2] < heading  # clockwise


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"k_p": -1.0}, ValueError, r"k_p must be a number >= 0, got -1.0"),
        ({"k_p": float("nan")}, ValueError, r"k_p must be a number >= 0, got nan"),
        ({"k_p": "6"}, TypeError, r"k_p must be a number >= 0, got '6' \(str\)"),
        ({"base_speed": 0}, ValueError, r"base_speed must be a number in \(0, 300\] steps/s, got 0"),
        ({"base_speed": 301}, ValueError, r"base_speed must be a number in \(0, 300\]"),
        ({"base_speed": None}, TypeError, r"base_speed must be a number in"),
        ({"env": 6.0}, TypeError, r"env must be .* got 6.0 \(since 0.2 the env is the first"),
        ({"env": [1]}, TypeError, r"env must be an EPuckLineFollow env, its id or None"),
    ],
)  # fmt: skip
def test_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match) as raised:
        ProportionalController(**kwargs)
    assert type(raised.value) is error


def test_env_first_like_every_agent_and_default_formats_match_the_registered_env():
    """``ProportionalController(env)`` takes the env first, like every agent.

    With no env it speaks the registered env's default formats (discrete actions, centroid
    observations).
    """
    env = gym.make("delayed_rl/EPuckLineFollow-v0")
    positional = ProportionalController(env, 6.0, 300.0)
    assert positional.get_env() is env and positional.discrete_actions
    default = ProportionalController()
    obs, _ = env.reset(seed=1)
    for _ in range(20):
        action, _ = default.predict(obs)
        assert env.action_space.contains(action)
        assert action == positional.predict(obs)[0]
        obs, *_ = env.step(action)
    assert ProportionalController.predict.__defaults__[-1] is False  # deterministic=False


def test_incompatible_env_is_rejected():
    with pytest.raises(ValueError, match=r"action space must be Discrete\(7\) or Box"):
        ProportionalController(env=gym.make("CartPole-v1"))
    env = gym.make("delayed_rl/GridWorld-3x3-v0")
    with pytest.raises(ValueError, match="action space"):
        ProportionalController(env=env)


@pytest.mark.parametrize("obs", [41, -1, [[1, 2]]])
def test_bad_observations_are_rejected(obs):
    with pytest.raises(ValueError, match=r"observation must be line centroids in 0\.\.40"):
        ProportionalController().predict(obs)


def test_exported_from_agents():
    from delayed_rl.agents import ProportionalController as Exported

    assert Exported is ProportionalController


@pytest.mark.parametrize(
    ("state", "error", "match"),
    [
        ([float("nan"), 0.0], ValueError, r"state must be .*finite"),
        ([float("inf"), 0.0], ValueError, r"state must be .*finite"),
        ([1.0, 0.5, 0.2], ValueError, r"state must have shape"),
        ([[1.0, 0.5], [0.2, 0.1]], ValueError, r"state must have shape"),
        ("fast", TypeError, r"state must be"),
        ([None, 1.0], TypeError, r"state must be"),
    ],
)
def test_bad_states_are_rejected(state, error, match):
    with pytest.raises(error, match=match) as raised:
        ProportionalController().predict(0, state=state)
    assert type(raised.value) is error


def test_batched_states_must_match_the_batch():
    ctrl = ProportionalController()
    action, state = ctrl.predict(np.array([0, 20]), state=np.array([[1.0, 0.2], [0.5, 0.5]]))
    assert state.shape == (2, 2) and np.isfinite(state).all()
    with pytest.raises(ValueError, match=r"state must have shape"):
        ctrl.predict(np.array([0, 20]), state=np.ones((3, 2)))
    with pytest.raises(ValueError, match=r"state must be .*finite"):
        ctrl.predict(np.array([0, 20]), state=np.array([[1.0, 0.2], [np.nan, 0.5]]))

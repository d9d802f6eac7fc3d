"""Registration: ids, ``gym.make(id, reward_delay=..., ...)`` and ``gym.make(env.spec)``."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from support import layers

from delayed_rl.delays import Constant, Geometric, Poisson, Uniform
from delayed_rl.envs import env_ids, register_envs
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.envs.roulette import RouletteEnv
from delayed_rl.wrappers import (
    ActionDelay,
    ObservationDelay,
    PoissonRewardDelay,
    RewardDelay,
    wrap_delays,
)

IDS = {
    "delayed_rl/GridWorld-3x3-v0": {},
    "delayed_rl/GridWorld-5x5-v0": {},
    "delayed_rl/GridWorld-9x9-v0": {},
    "delayed_rl/GridWorld-v0": {"size": 6},
    "delayed_rl/Roulette-v0": {},
}


def find(env: gym.Env, cls: type) -> gym.Env | None:
    layer = env
    while True:
        if isinstance(layer, cls):
            return layer
        if not isinstance(layer, gym.Wrapper):
            return None
        layer = layer.env


def test_ids_are_registered_on_import() -> None:
    ids = env_ids()
    assert set(IDS) <= set(ids)
    assert ids == sorted(ids)
    register_envs()  # idempotent
    assert env_ids() == ids


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_every_registered_id(env_id: str) -> None:
    env = gym.make(env_id, **IDS[env_id])
    assert isinstance(env.unwrapped, GridWorldEnv | RouletteEnv)
    assert find(env, RewardDelay) is None  # no delay unless asked for
    check_env(env.unwrapped)


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("lam", [0, 2.5, 13])
def test_make_with_reward_delay_wraps(env_id: str, lam: float) -> None:
    env = gym.make(env_id, reward_delay=lam, **IDS[env_id])
    wrapper = find(env, PoissonRewardDelay)
    assert wrapper is not None and wrapper.lam == lam
    assert env.spec.kwargs["reward_delay"] == lam
    _, info = env.reset(seed=0)
    assert info["pending_reward"] == 0.0
    *_, info = env.step(env.action_space.sample())
    assert {"undelayed_reward", "drawn_reward_delay", "pending_reward"} <= set(info)


def test_make_with_a_delay_distribution() -> None:
    env = gym.make("delayed_rl/Roulette-v0", reward_delay=Geometric(0.25))
    wrapper = find(env, RewardDelay)
    assert type(wrapper) is RewardDelay and wrapper.delay == Geometric(0.25)


def reward_row(obs, reward, terminated, truncated, info):
    """What a reward-delayed step shows."""
    return reward, info["drawn_reward_delay"], info["undelayed_reward"], terminated, truncated


def trajectory(env: gym.Env, seed: int, n: int = 300, row=reward_row):
    """``row(*step)`` of ``n`` seeded random steps of ``env`` (reset at episode ends)."""
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        step = env.step(int(rng.integers(env.action_space.n)))
        out.append(row(*step))
        if step[2] or step[3]:
            env.reset()
    return out


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("delayed_rl/GridWorld-5x5-v0", {"reward_delay": 4.5, "max_steps": 40}),
        ("delayed_rl/GridWorld-v0", {"size": 4, "reward_delay": Uniform(1, 7)}),
        ("delayed_rl/Roulette-v0", {"reward_delay": 13.7, "max_steps": 60}),
    ],
)
def test_make_from_spec_rebuilds_an_equivalent_stack(env_id: str, kwargs: dict) -> None:
    env = gym.make(env_id, **kwargs)
    rebuilt = gym.make(env.spec)
    assert type(find(rebuilt, RewardDelay)) is type(find(env, RewardDelay))
    assert find(rebuilt, RewardDelay).delay == find(env, RewardDelay).delay
    assert rebuilt.unwrapped.max_steps == env.unwrapped.max_steps
    a, b = trajectory(env, 11), trajectory(rebuilt, 11)
    assert a == b
    assert len({x[1] for x in a}) > 1  # the delays varied
    assert trajectory(rebuilt, 12) != a


def test_outer_wrapper_spec_round_trip() -> None:
    env = PoissonRewardDelay(
        gym.make("delayed_rl/GridWorld-3x3-v0", max_steps=20), 3, on_episode_end="carry"
    )
    rebuilt = gym.make(env.spec)
    wrapper = find(rebuilt, PoissonRewardDelay)
    assert wrapper is not None and (wrapper.lam, wrapper.on_episode_end) == (3, "carry")
    assert trajectory(env, 5) == trajectory(rebuilt, 5)


@pytest.mark.parametrize(
    ("bad", "exc"),
    [
        ("5", TypeError),
        (True, TypeError),
        (np.bool_(True), TypeError),
        ([1, 2], TypeError),
        (-1, ValueError),
        (float("nan"), ValueError),
        (float("inf"), ValueError),
        (np.float32(-2.0), ValueError),
        (10**400, ValueError),
        (1e300, ValueError),
        ({"type": "Poisson", "lam": -1}, ValueError),
        ({"type": "Constant", "k": 2.5}, TypeError),
        ({"type": "Empirical", "pmf": [0.5, 0.6]}, ValueError),
        ({"type": "Constant"}, ValueError),
    ],
    ids=repr,
)
@pytest.mark.parametrize("kwarg", ["reward_delay", "observation_delay", "action_delay"])
@pytest.mark.parametrize("env_id", ["delayed_rl/GridWorld-3x3-v0", "delayed_rl/Roulette-v0"])
def test_make_rejects_a_bad_delay_naming_its_argument(env_id: str, kwarg: str, bad, exc) -> None:
    with pytest.raises(exc, match=f"^{kwarg}( must be|: )"):
        gym.make(env_id, **{kwarg: bad})
    with pytest.raises(exc, match=f"^{kwarg}( must be|: )"):
        wrap_delays(gym.make(env_id), **{kwarg: bad})


# ---------------------------------------------------------------------- the three delays
@pytest.mark.parametrize("env_id", [*IDS, "delayed_rl/EPuckLineFollow-v0"])
def test_every_id_takes_the_three_delays_in_the_documented_order(env_id: str) -> None:
    kwargs = IDS.get(env_id, {})
    env = gym.make(env_id, action_delay=2, observation_delay=Constant(1), reward_delay=3, **kwargs)
    assert layers(env) == ["PoissonRewardDelay", "ObservationDelay", "ActionDelay"]
    assert find(env, ActionDelay).delay == Poisson(2) and find(
        env, ObservationDelay
    ).delay == Constant(1)
    env.reset(seed=0)
    *_, info = env.step(env.action_space.sample())
    assert {
        "executed_action",
        "drawn_action_delay",
        "observation_age",
        "drawn_reward_delay",
    } <= set(info)
    only_actions = gym.make(env_id, action_delay=Geometric(0.5), **kwargs)
    assert layers(only_actions) == ["ActionDelay"]


def action_row(obs, reward, terminated, truncated, info):
    """What a step under all three delays shows."""
    return obs, reward, info["executed_action"], info["observation_age"], truncated


@pytest.mark.parametrize("through_json", [False, True])
def test_the_delays_round_trip_through_the_spec(through_json: bool) -> None:
    env = gym.make(
        "delayed_rl/GridWorld-5x5-v0", max_steps=30, reward_delay=Geometric(0.2),
        observation_delay=Uniform(0, 3), action_delay=1.5,
    )  # fmt: skip
    spec = env.spec
    assert spec.kwargs["observation_delay"] == {"type": "Uniform", "low": 0, "high": 3}
    if through_json:
        spec = gym.envs.registration.EnvSpec.from_json(spec.to_json())
    rebuilt = gym.make(spec)
    assert layers(rebuilt) == ["RewardDelay", "ObservationDelay", "ActionDelay"]
    assert find(rebuilt, ObservationDelay).delay == Uniform(0, 3)
    assert find(rebuilt, ActionDelay).delay == Poisson(1.5)
    assert trajectory(env, 3, 200, action_row) == trajectory(rebuilt, 3, 200, action_row)


@pytest.mark.parametrize("name", ["action_delay", "observation_delay"])
@pytest.mark.parametrize(
    ("bad", "exc"),
    [("5", TypeError), (True, TypeError), (-1, ValueError), ({"type": "X"}, ValueError)],
)
def test_bad_delays_are_refused_naming_the_argument(name: str, bad, exc) -> None:
    with pytest.raises(exc, match=name):
        gym.make("delayed_rl/GridWorld-3x3-v0", **{name: bad})

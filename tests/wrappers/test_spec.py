"""Env specs of the delay wrappers: their arguments recorded as JSON (``record_arguments``)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from delayed_rl.delays import Constant
from delayed_rl.wrappers import (
    ActionDelay,
    ObservationDelay,
    PoissonRewardDelay,
    RewardDelay,
    VectorActionDelay,
    VectorObservationDelay,
    VectorRewardDelay,
)

NINE = np.int64(9)


@pytest.mark.parametrize(
    "make",
    [
        lambda env: RewardDelay(env, np.float32(2.0), NINE, record_arrivals=np.bool_(True)),
        lambda env: PoissonRewardDelay(env, np.float64(2.0), max_delay=NINE),
        lambda env: ActionDelay(env, {"type": "Constant", "k": np.int64(1)}, max_delay=NINE),
        lambda env: ObservationDelay(env, Constant(1), max_delay=NINE),
    ],
)
def test_numpy_arguments_are_recorded_as_json_and_the_spec_makes_the_same_env(make):
    env = make(gym.make("CartPole-v1"))
    text = env.spec.to_json()
    assert '"max_delay": 9' in text
    assert gym.make(gym.envs.registration.EnvSpec.from_json(text)).spec.to_json() == text


@pytest.mark.parametrize("wrapper", [VectorRewardDelay, VectorActionDelay, VectorObservationDelay])
def test_a_vector_wrapper_records_numpy_arguments_as_json(wrapper):
    env = wrapper(gym.make_vec("CartPole-v1", num_envs=2), np.float64(2.0), max_delay=NINE)
    recorded = json.loads(json.dumps(env._saved_kwargs))
    assert recorded["delay"] == 2.0 and type(env._saved_kwargs["delay"]) is float
    assert recorded["max_delay"] == 9 and type(env._saved_kwargs["max_delay"]) is int

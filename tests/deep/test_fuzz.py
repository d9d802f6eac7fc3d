"""Fuzzing the reward models' new surfaces: seeds, n-step buffers, mappings and Dict steps.

- **Seeds**: for any algorithm seed, the model's derived seed is in ``0..2**63 − 1``, the same
  each time, and differs between seeds; a buffer built inside a seeded algorithm uses it.
- **n-step buffers**: random ``n_steps`` and ``gamma``, good or bad: a good pair builds a buffer
  whose sampled rewards are the discounted sums of ``R̂`` over the steps (checked against a plain
  loop); a bad one is refused with ``TypeError`` or ``ValueError`` naming the setting.
- **Mappings**: random settings of wrong types or values are refused by name, never dropped.
- **Dict steps**: random Dict spaces, and steps whose keys, shapes or values are wrong: a refused
  step leaves the history as it was; a good one is stored exactly.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import examples, torch_on_one_thread  # noqa: F401  (the fixture)

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

FUZZ = settings(
    max_examples=examples(100),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
FEW = settings(
    max_examples=examples(25),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
SPEC = {"type": "DeconvolutionRewardModel", "delay": 2, "window": 4, "batch_size": 8}


# ---------------------------------------------------------------------- seeds
@FUZZ
@given(st.integers(0, 2**64), st.integers(0, 2**64))
def test_derived_seeds_are_in_range_repeatable_and_distinct(seed, other):
    from delayed_rl.deep.binding import reward_model_seed

    derived = reward_model_seed(seed)
    assert 0 <= derived < 2**63 and derived == reward_model_seed(seed)
    if other != seed:
        assert reward_model_seed(other) != derived


@FEW
@given(st.integers(0, 2**32 - 1))
def test_a_seeded_algorithm_seeds_the_buffers_model(seed):
    from stable_baselines3 import SAC

    from delayed_rl.deep import RelabelingReplayBuffer
    from delayed_rl.deep.binding import reward_model_seed

    agent = SAC(
        "MlpPolicy",
        gym.make("Pendulum-v1"),
        buffer_size=64,
        policy_kwargs={"net_arch": [4]},
        replay_buffer_class=RelabelingReplayBuffer,
        replay_buffer_kwargs={"reward_model": dict(SPEC)},
        seed=seed,
        device="cpu",
    )
    model = agent.replay_buffer.reward_model
    assert model.seed == reward_model_seed(seed) and not model.takes_algorithm_seed


# ---------------------------------------------------------------------- n-step buffers
BAD_N_STEPS = st.one_of(
    st.integers(max_value=0), st.floats(allow_nan=True), st.text(max_size=3), st.booleans()
)
BAD_GAMMA = st.one_of(
    st.floats(min_value=1.0, exclude_min=True),
    st.floats(max_value=0.0, exclude_max=True),
    st.just(math.nan),
    st.text(max_size=3),
)


@FUZZ
@given(st.data())
def test_bad_n_step_settings_are_refused_by_name(data):
    from delayed_rl.deep import RelabelingNStepReplayBuffer

    env = gym.make("Pendulum-v1")
    name = data.draw(st.sampled_from(["n_steps", "gamma"]))
    value = data.draw(BAD_N_STEPS if name == "n_steps" else BAD_GAMMA)
    with pytest.raises((TypeError, ValueError), match=name):
        RelabelingNStepReplayBuffer(
            16, env.observation_space, env.action_space, reward_model=dict(SPEC), **{name: value}
        )


@FEW
@given(
    n_steps=st.integers(1, 6),
    gamma=st.floats(0.0, 1.0),
    ends=st.lists(st.booleans(), min_size=12, max_size=12),
    seed=st.integers(0, 2**16),
)
def test_n_step_rewards_are_discounted_sums_of_r_hat(n_steps, gamma, ends, seed):
    from delayed_rl.deep import RelabelingNStepReplayBuffer

    observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    buffer = RelabelingNStepReplayBuffer(
        32,
        observation_space,
        action_space,
        reward_model={**SPEC, "warmup_updates": 1, "seed": 0},
        n_steps=n_steps,
        gamma=gamma,
    )
    rng = np.random.default_rng(seed)
    obs = rng.uniform(-1, 1, (12, 1, 2)).astype(np.float32)
    actions = rng.uniform(-1, 1, (12, 1, 1)).astype(np.float32)
    ends[-1] = True
    for t in range(12):
        infos = [{"TimeLimit.truncated": False}]
        buffer.add(obs[t], obs[t], actions[t], np.array([1.0]), np.array([ends[t]]), infos)
    model = buffer.reward_model
    model.train_on_schedule()
    assert model.ready
    inds = np.arange(12)
    batch = buffer._get_samples(inds)
    rewards = model.predict(obs[:, 0], actions[:, 0]).astype(np.float64)
    expected = []
    for i in inds:
        total, discount = 0.0, 1.0
        for k in range(n_steps):
            total += discount * rewards[i + k]
            discount *= gamma
            if ends[i + k] or i + k + 1 >= 12:
                break
        expected.append(total)
    np.testing.assert_allclose(batch.rewards.numpy().ravel(), expected, rtol=1e-5, atol=1e-5)


# ---------------------------------------------------------------------- mappings
SETTINGS = {
    "hidden_sizes": st.one_of(
        st.integers(), st.text(max_size=2), st.lists(st.integers(-2, 0), min_size=1)
    ),
    "learning_rate": st.one_of(st.floats(max_value=0.0), st.text(max_size=2), st.none()),
    "batch_size": st.one_of(st.integers(max_value=0), st.floats(), st.text(max_size=2)),
    "updates_per_step": st.one_of(st.floats(max_value=-1e-9), st.text(max_size=2), st.none()),
    "warmup_updates": st.one_of(st.integers(max_value=-1), st.floats(), st.booleans()),
    "capacity": st.one_of(st.integers(max_value=0), st.text(max_size=2)),
    "seed": st.one_of(st.integers(max_value=-1), st.integers(min_value=2**63), st.floats()),
    "window": st.one_of(st.integers(max_value=0), st.text(max_size=2)),
    "max_delay_estimate": st.one_of(st.integers(max_value=-1), st.text(max_size=2)),
}


@FUZZ
@given(st.data())
def test_a_mappings_bad_setting_is_refused_by_name(data):
    from delayed_rl.deep import RelabelingReplayBuffer

    env = gym.make("Pendulum-v1")
    name = data.draw(st.sampled_from(sorted(SETTINGS) + ["unknown_setting"]))
    value = data.draw(SETTINGS.get(name, st.integers()))
    with pytest.raises((TypeError, ValueError), match=name):
        RelabelingReplayBuffer(
            16, env.observation_space, env.action_space, reward_model={**SPEC, name: value}
        )


# ---------------------------------------------------------------------- Dict steps
LEAVES = st.one_of(
    st.builds(lambda n: spaces.Box(-1.0, 1.0, (n,), np.float32), st.integers(1, 3)),
    st.builds(lambda n, s: spaces.Discrete(n, start=s), st.integers(1, 4), st.integers(-2, 2)),
    st.builds(
        lambda v: spaces.MultiDiscrete(v), st.lists(st.integers(1, 3), min_size=1, max_size=3)
    ),
    st.builds(lambda n: spaces.MultiBinary(n), st.integers(1, 3)),
)
DICTS = st.dictionaries(st.text("abcxyz", min_size=1, max_size=3), LEAVES, min_size=1, max_size=4)


@FUZZ
@given(DICTS, st.data())
def test_a_refused_dict_step_leaves_the_history_as_it_was(parts, data):
    from delayed_rl.deep import DeconvolutionRewardModel

    space = spaces.Dict(parts)
    space.seed(data.draw(st.integers(0, 2**16)))
    model = DeconvolutionRewardModel(
        space, spaces.Discrete(2), delay=1, window=2, batch_size=4, seed=0
    )
    good = space.sample()
    model.add({key: value[None] for key, value in good.items()}, [1], [0.5], [False])
    for key, value in good.items():
        np.testing.assert_array_equal(model.history.obs[key][0, 0], np.reshape(value, -1))
    key = data.draw(st.sampled_from(sorted(parts)))
    broken = {k: np.asarray(v)[None] for k, v in space.sample().items()}
    how = data.draw(st.sampled_from(["missing", "shape", "value", "type", "extra"]))
    if how == "missing":
        del broken[key]
    elif how == "shape":
        broken[key] = np.concatenate([broken[key].reshape(-1), [0]])
    elif how == "value":  # a Box's NaN, or an integer outside the space
        bad = np.nan if isinstance(parts[key], spaces.Box) else 10**6
        broken[key] = np.full(broken[key].shape, bad)
    elif how == "type":
        broken[key] = np.array(["x"] * broken[key].size)
    else:
        broken["not a key"] = np.zeros(1)
    snapshot = {k: v.copy() for k, v in model.history.obs.items()}
    with pytest.raises((TypeError, ValueError)):
        model.add(broken, [1], [0.5], [False])
    assert model.history.steps_added == 1
    for k, v in snapshot.items():
        np.testing.assert_array_equal(model.history.obs[k], v)

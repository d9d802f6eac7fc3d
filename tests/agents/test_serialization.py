"""Saving and loading agents: round trips, resumed training, and files that must be refused."""

from __future__ import annotations

import json
import zipfile

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import (
    FixedDelayQLearning,
    LinearSchedule,
    MultipleModelQLearning,
    QLearning,
    TabularAgent,
    load_agent,
)

GRID5 = "delayed_rl/GridWorld-5x5-v0"


def trained_mmq(seed=0, steps=2_000):
    env = gym.make(GRID5, reward_delay=2)
    return MultipleModelQLearning(env, max_delay_estimate=5, q_init=10.0, seed=seed).learn(steps)


def test_round_trip_predicts_identically(tmp_path):
    agent = trained_mmq()
    path = agent.save(tmp_path / "model")
    assert path == tmp_path / "model.npz" and path.exists()
    for loaded in (
        MultipleModelQLearning.load(path),
        MultipleModelQLearning.load(tmp_path / "model"),
        load_agent(path),
    ):
        assert type(loaded) is MultipleModelQLearning and loaded.env is None
        np.testing.assert_array_equal(loaded.q_table, agent.q_table)
        assert loaded.delay_estimates == agent.delay_estimates
        assert loaded.num_timesteps == agent.num_timesteps == 2_000
        assert (loaded.gamma, loaded.q_init, loaded.seed) == (0.9, 10.0, 0)
        states = np.arange(25)
        np.testing.assert_array_equal(
            loaded.predict(states, deterministic=True)[0],
            agent.predict(states, deterministic=True)[0],
        )
        np.testing.assert_array_equal(loaded.preferred_delay(states), agent.preferred_delay(states))
    # the exploring predict draws from a saved stream too
    a, b = MultipleModelQLearning.load(path), MultipleModelQLearning.load(path)
    np.testing.assert_array_equal(a.predict(states)[0], b.predict(states)[0])


def test_every_class_round_trips(tmp_path):
    for agent in (
        QLearning(GRID5, q_init=3.0, seed=1).learn(500),
        FixedDelayQLearning(GRID5, delay_estimate=4, seed=2).learn(500),
    ):
        path = agent.save(tmp_path / type(agent).__name__)
        loaded = type(agent).load(path)
        assert type(loaded) is type(agent)
        np.testing.assert_array_equal(loaded.q_table, agent.q_table)
        assert loaded.delay_estimates == agent.delay_estimates
    assert FixedDelayQLearning.load(tmp_path / "FixedDelayQLearning").delay_estimate == 4
    assert type(TabularAgent.load(tmp_path / "QLearning.npz")) is QLearning
    assert QLearning.load(tmp_path / "QLearning.npz").learning_rate == 0.1
    # a QLearning file claiming several delay models is refused
    path = tmp_path / "QLearning.npz"
    with np.load(path) as data:
        metadata = json.loads(str(data["metadata"]))
    metadata["hyperparameters"]["delay_estimates"] = [0, 1]
    rewrite(path, tmp_path / "bad.npz", metadata=np.array(json.dumps(metadata)))
    with pytest.raises(
        ValueError, match=r"invalid hyper-parameters: QLearning has delay_estimates"
    ):
        QLearning.load(tmp_path / "bad.npz")


def test_resumed_training_continues_where_it_stopped(tmp_path):
    """Saved after 2000 steps, loaded into a fresh env, trained 1000 more: identical to the original.

    The original is trained 1000 more after being handed a fresh env the same way.
    """
    original = trained_mmq(seed=5)
    path = original.save(tmp_path / "checkpoint")
    resumed = MultipleModelQLearning.load(path, env=gym.make(GRID5, reward_delay=2))
    original.set_env(gym.make(GRID5, reward_delay=2))
    for agent in (original, resumed):
        agent.learn(1_000, reset_num_timesteps=False)
        assert agent.num_timesteps == 3_000
    np.testing.assert_array_equal(resumed.q_table, original.q_table)
    np.testing.assert_array_equal(resumed.acting_delay_share, original.acting_delay_share)


def test_learning_rate_schedules_round_trip(tmp_path):
    env = gym.make(GRID5)
    linear = QLearning(env, learning_rate=LinearSchedule(0.5, 0.1, 0.5)).learn(100)
    loaded = QLearning.load(linear.save(tmp_path / "linear"))
    assert isinstance(loaded.lr_schedule, LinearSchedule)
    assert loaded.lr_schedule(0.2) == linear.lr_schedule(0.2)

    custom = QLearning(env, learning_rate=lambda p: 0.05 + 0.1 * p).learn(100)
    path = custom.save(tmp_path / "custom")
    assert QLearning.load(path).current_learning_rate == pytest.approx(custom.current_learning_rate)
    restored = QLearning.load(path, custom_objects={"learning_rate": lambda p: 0.3})
    assert restored.lr_schedule(0.9) == 0.3
    with pytest.raises(ValueError, match="custom_objects may override"):
        QLearning.load(path, custom_objects={"policy": 1})


def test_checkpoint_style_names_are_kept(tmp_path):
    agent = QLearning(GRID5).learn(10)
    path = agent.save(tmp_path / "rl_model_10_steps.zip")
    assert path.name == "rl_model_10_steps.zip" and zipfile.is_zipfile(path)
    assert QLearning.load(path).num_timesteps == 10


def test_loading_into_env_with_other_spaces(tmp_path):
    path = trained_mmq(steps=10).save(tmp_path / "m")
    with pytest.raises(ValueError, match=r"m.npz into this env: the env's observation_space"):
        MultipleModelQLearning.load(path, env=gym.make("delayed_rl/GridWorld-3x3-v0"))
    with pytest.raises(ValueError, match="observation_space is Discrete.1."):
        MultipleModelQLearning.load(path, env="delayed_rl/Roulette-v0")
    agent = MultipleModelQLearning.load(path)
    with pytest.raises(ValueError, match="no env to learn from"):
        agent.learn(10)
    agent.set_env(GRID5)
    assert agent.learn(10, reset_num_timesteps=False).num_timesteps == 20


def test_wrong_class_and_missing_file(tmp_path):
    path = trained_mmq(steps=10).save(tmp_path / "m")
    with pytest.raises(ValueError, match="holds a MultipleModelQLearning model, not a QLearning"):
        QLearning.load(path)
    with pytest.raises(FileNotFoundError, match="no model file"):
        MultipleModelQLearning.load(tmp_path / "absent")


def rewrite(path, target, **changes):
    """Copy the archive at ``path`` to ``target`` with some arrays replaced (None: dropped)."""
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    for key, value in changes.items():
        if value is None:
            arrays.pop(key)
        else:
            arrays[key] = value
    with open(target, "wb") as file:
        np.savez(file, **arrays)
    return target


def metadata_with(path, **changes):
    with np.load(path) as data:
        metadata = json.loads(str(data["metadata"]))
    metadata.update(changes)
    return np.array(json.dumps(metadata))


@pytest.mark.parametrize(
    ("make_file", "message"),
    [
        (lambda p, t: t.write_bytes(b"not a model at all") and t, "not a readable delayed-rl"),
        (lambda p, t: t.write_bytes(p.read_bytes()[:200]) and t, "not a readable delayed-rl"),
        (
            lambda p, t: np.save(t.with_suffix(".npy"), np.arange(3)) or t.with_suffix(".npy"),
            "single .npy array",
        ),
        (lambda p, t: rewrite(p, t, metadata=None), "no metadata string"),
        (lambda p, t: rewrite(p, t, metadata=np.array("{oops")), "not valid JSON"),
        (
            lambda p, t: rewrite(p, t, metadata=metadata_with(p, format="sb3")),
            "lacks format='delayed_rl.agent'",
        ),
        (
            lambda p, t: rewrite(p, t, metadata=metadata_with(p, format_version=99)),
            "format version 99",
        ),
        (
            lambda p, t: rewrite(p, t, q_table=np.zeros((25, 6, 3))),
            "q_table must be a float64 array of shape",
        ),
        (lambda p, t: rewrite(p, t, q_table=np.full((25, 6, 4), np.nan)), "non-finite"),
        (
            lambda p, t: rewrite(p, t, delay_estimates=np.arange(1, 7)),
            "does not match the metadata",
        ),
        (lambda p, t: rewrite(p, t, rng_block=None), "rng_block must be .*, got missing"),
        (
            lambda p, t: rewrite(
                p, t, metadata=metadata_with(p, observation_space={"type": "Box"})
            ),
            "malformed observation_space",
        ),
        (
            lambda p, t: rewrite(p, t, metadata=metadata_with(p, **{"class": "PPO"})),
            "holds an unknown agent class 'PPO': import the module that defines it",
        ),
    ],
)
def test_corrupt_or_foreign_files_are_refused(tmp_path, make_file, message):
    good = trained_mmq(steps=10).save(tmp_path / "good")
    bad = make_file(good, tmp_path / "bad.npz")
    with pytest.raises(ValueError, match=message):
        MultipleModelQLearning.load(bad)


def test_bad_hyperparameters_in_file(tmp_path):
    good = trained_mmq(steps=10).save(tmp_path / "good")
    with np.load(good) as data:
        metadata = json.loads(str(data["metadata"]))
    metadata["hyperparameters"]["gamma"] = 5.0
    bad = rewrite(good, tmp_path / "bad.npz", metadata=np.array(json.dumps(metadata)))
    with pytest.raises(ValueError, match=r"bad.npz: invalid hyper-parameters: gamma must be"):
        MultipleModelQLearning.load(bad)


def test_pickled_arrays_are_never_loaded(tmp_path):
    """An archive smuggling an object array is refused (allow_pickle=False), never unpickled."""
    good = trained_mmq(steps=10).save(tmp_path / "good")
    with np.load(good) as data:
        arrays = {key: data[key] for key in data.files}
    arrays["q_table"] = np.array([{"payload": 1}], dtype=object)
    target = tmp_path / "pickled.npz"
    with open(target, "wb") as file:
        np.savez(file, **arrays)
    with pytest.raises(ValueError, match="allow_pickle=False"):
        MultipleModelQLearning.load(target)


@pytest.mark.sb3
def test_sb3_eval_callback_best_model_loads_by_its_sb3_name(tmp_path):
    """EvalCallback saves ``best_model`` (written ``best_model.npz``); ``.zip`` finds it.

    SB3 users load ``best_model.zip``; ``best_model`` works too.
    """
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.monitor import Monitor

    from delayed_rl.envs.gridworld import GridWorldEnv

    agent = QLearning(GridWorldEnv(size=3, max_steps=30), q_init=20.0, seed=0)
    callback = EvalCallback(
        Monitor(GridWorldEnv(size=3, max_steps=30)),
        eval_freq=200,
        n_eval_episodes=1,
        best_model_save_path=str(tmp_path),
        verbose=0,
    )
    agent.learn(600, callback=callback)
    assert [p.name for p in tmp_path.iterdir()] == ["best_model.npz"]
    for name in ("best_model.zip", "best_model", "best_model.npz"):
        assert QLearning.load(tmp_path / name).num_timesteps in (200, 400, 600)

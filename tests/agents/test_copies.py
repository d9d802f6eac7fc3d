"""Copied, pickled and saved agents: each predicts from its own table and resumes exactly."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import MultipleModelQLearning, QLearning
from delayed_rl.agents.common.q_table import greedy_actions
from delayed_rl.agents.registry import REGISTRY, agent_class
from delayed_rl.wrappers import RewardDelay

GRID5 = "delayed_rl/GridWorld-5x5-v0"
STATES = np.arange(25)


def make(cls=QLearning, **options):
    """A ``cls`` on the 5×5 grid under a delay of 2 steps, built as its registry entry says."""
    name = next(name for name, entry in REGISTRY.items() if entry.class_name == cls.__name__)
    entry = REGISTRY[name]
    if entry.needs_arrivals:
        env = RewardDelay(gym.make(GRID5), 2, record_arrivals=True)
    else:
        env = gym.make(GRID5, reward_delay=2)
    if cls is MultipleModelQLearning:
        options.setdefault("max_delay_estimate", 4)
    return cls(env, q_init=5.0, seed=0, **{**entry.example_arguments, **options})


#: Every registered agent class, for the tests that hold for each.
CLASSES = [agent_class(name) for name in REGISTRY]


def pickled(agent):
    return pickle.loads(pickle.dumps(agent))


def assert_predicts_from_its_own_table(agent):
    """The greedy policy, the exploring one at ε = 0 and λ̂* all read the agent's ``q_table``."""
    q = agent.q_table
    np.testing.assert_array_equal(agent.predict(STATES, deterministic=True)[0], greedy_actions(q))
    saved_eps, agent.exploration_rate = agent.exploration_rate, 0.0
    try:
        actions = agent.predict(STATES)[0]
    finally:
        agent.exploration_rate = saved_eps
    best = q.reshape(25, -1).max(axis=1)
    for s, a in zip(STATES, actions, strict=True):
        assert q[s, :, a].max() == best[s], (s, a)
    models = agent.preferred_delay(STATES)
    np.testing.assert_array_equal(
        models, np.asarray(agent.delay_estimates)[q.reshape(25, -1).argmax(axis=1) // 4]
    )


@pytest.mark.parametrize("cls", CLASSES, ids=lambda cls: cls.__name__)
@pytest.mark.parametrize("duplicate", [copy.deepcopy, pickled], ids=["deepcopy", "pickle"])
@pytest.mark.parametrize("compiled", [False, None], ids=["python", "default"])
def test_a_copy_learns_into_the_table_it_predicts_from(cls, duplicate, compiled):
    original = make(cls).learn(300, compiled=compiled)
    twin = duplicate(original)
    assert not np.shares_memory(twin.q_table, original.q_table)
    twin.learn(3_000, compiled=compiled, reset_num_timesteps=False)
    assert not np.array_equal(twin.q_table, original.q_table)  # it learned
    assert_predicts_from_its_own_table(twin)
    assert_predicts_from_its_own_table(original)


@pytest.mark.parametrize("cls", CLASSES, ids=lambda cls: cls.__name__)
@pytest.mark.parametrize("duplicate", [copy.deepcopy, pickled], ids=["deepcopy", "pickle"])
@pytest.mark.parametrize("compiled", [False, None], ids=["python", "default"])
@pytest.mark.parametrize("restart", [False, True], ids=["continue", "restart"])
def test_a_copy_continues_exactly_as_the_original(cls, duplicate, compiled, restart):
    """Same seed, same history: the copy's next ``learn()`` equals the original's.

    ``restart=False`` continues the episode, the pending rewards and, on the default path, the
    compiled run (with its own generator) of the first ``learn()``.
    """
    original = make(cls).learn(700, compiled=compiled)
    twin = duplicate(original)
    for agent in (original, twin):
        agent.learn(2_000, compiled=compiled, reset_num_timesteps=restart)
        # and the transitions a user drives, from the same state (nothing arrives with them)
        agent.update(3, 1, 1.0, 4, info={"reward_arrivals": []})
    np.testing.assert_array_equal(twin.q_table, original.q_table)
    assert twin.num_timesteps == original.num_timesteps
    np.testing.assert_array_equal(twin.acting_delay_share, original.acting_delay_share)
    np.testing.assert_array_equal(twin.predict(STATES)[0], original.predict(STATES)[0])
    assert twin.exploration_rate == original.exploration_rate


@pytest.mark.parametrize("compiled", [False, None], ids=["python", "default"])
def test_a_saved_agent_continues_exactly_as_the_original(tmp_path, compiled):
    original = make(MultipleModelQLearning).learn(700, compiled=compiled)
    loaded = MultipleModelQLearning.load(
        original.save(tmp_path / "m"), env=gym.make(GRID5, reward_delay=2)
    )
    assert_predicts_from_its_own_table(loaded)
    original.set_env(gym.make(GRID5, reward_delay=2))  # a fresh env, as the loaded agent's
    for agent in (original, loaded):
        agent.learn(2_000, compiled=compiled, reset_num_timesteps=False)
    np.testing.assert_array_equal(loaded.q_table, original.q_table)
    assert_predicts_from_its_own_table(loaded)


def test_a_deep_copy_before_any_training_learns_on_its_own():
    """The case of the bug report: copy a fresh agent, train the copy."""
    original = QLearning(gym.make(GRID5), seed=0)
    twin = copy.deepcopy(original)
    twin.learn(5_000)
    twin.learn(1_000, compiled=False)  # the Python path on the copy's tables
    assert np.all(original.q_table == 0.0) and np.any(twin.q_table != 0.0)
    assert_predicts_from_its_own_table(twin)


def test_a_shallow_copy_shares_the_tables():
    """``copy.copy`` shares the arrays, the env and the run: it predicts from the shared table."""
    original = make(MultipleModelQLearning).learn(500)
    twin = copy.copy(original)
    assert np.shares_memory(twin.q_table, original.q_table) and twin.env is original.env
    twin.learn(1_000, compiled=False, reset_num_timesteps=False)
    np.testing.assert_array_equal(twin.q_table, original.q_table)
    assert_predicts_from_its_own_table(twin)
    assert_predicts_from_its_own_table(original)


class Unpicklable(gym.Wrapper):
    """An env that refuses to be copied (as one holding a window or a socket would)."""

    def __reduce_ex__(self, protocol):
        raise TypeError("cannot pickle this env")


def test_what_cannot_be_copied_is_dropped_and_said():
    """An env that does not copy: the copy has none (a warning says so) and can be given one."""
    agent = QLearning(Unpicklable(gym.make(GRID5)), seed=0).learn(200)
    for duplicate in (copy.deepcopy, pickled):
        with pytest.warns(UserWarning, match="cannot be copied.*set_env"):
            twin = duplicate(agent)
        assert twin.env is None and twin._compiled is None
        np.testing.assert_array_equal(twin.q_table, agent.q_table)
        twin.set_env(gym.make(GRID5))
        twin.learn(100, reset_num_timesteps=False)
        assert twin.num_timesteps == 300


@pytest.mark.sb3
def test_a_logger_that_cannot_be_copied_is_replaced(tmp_path):
    from stable_baselines3.common.logger import configure

    agent = make(QLearning)
    agent.set_logger(configure(str(tmp_path / "log"), ["csv"]))
    agent.learn(100)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the logger is dropped without a warning (documented)
        twin = copy.deepcopy(agent)
    assert twin.logger is not agent.logger and hasattr(twin.logger, "dumps")
    twin.learn(100)

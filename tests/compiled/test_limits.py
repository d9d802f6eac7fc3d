"""The compiled path checks its tables and keeps its memory to what a run needs."""

from __future__ import annotations

import tracemalloc

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.agents import QLearning
from delayed_rl.compiled import CompiledRun, NotCompilable
from delayed_rl.compiled.run import RING_LIMIT
from delayed_rl.delays import Uniform
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import RewardDelay


def _frozen_lake_with(change):
    env = gym.make("FrozenLake-v1").unwrapped
    change(env.P)
    return env


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda P: P[5].__setitem__(1, [(1.0, 5, float("nan"), True)]), r"P\[5\]\[1\]\[0\] holds a non-finite reward"),
        (lambda P: P[2].__setitem__(0, [(1.0, 3, float("inf"), False)]), "non-finite reward"),
        (lambda P: P[0].__setitem__(3, [(1.0, 16, 0.0, False)]), r"a next state outside 0\.\.15"),
        (lambda P: P[0].__setitem__(3, [(0.7, 1, 0.0, False)]), r"P\[0\]\[3\]'s probabilities sum to 0\.7"),
        (lambda P: P[0].__setitem__(3, [(-0.5, 1, 0.0, False), (1.5, 2, 0.0, False)]), "outside"),
    ],
)  # fmt: skip
def test_bad_tables_are_refused_before_training(change, message):
    """A NaN reward in P poisoned the Q-table on the compiled path; now it is refused at once."""
    agent = QLearning(_frozen_lake_with(change), seed=0)
    with pytest.raises(ValueError, match=message):
        agent.learn(1_000)
    assert np.all(agent.q_table == 0.0)


def test_the_step_log_stays_small_however_long_the_run():
    """2M compiled steps without a record: a few MiB at the peak, not 42 bytes a step (84 MB)."""
    agent = QLearning(gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2), seed=0)
    agent.learn(1_000, log_interval=None)
    tracemalloc.start()
    agent.learn(2_000_000, log_interval=None)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert agent.last_learn_path == "compiled"
    assert peak < 16 * 2**20, peak


def test_a_delay_that_could_outrun_the_ring_limit_runs_on_the_python_path():
    """``Uniform(0, 2**27)`` on a continuing env: 1 GiB of ring compiled; the Python path instead."""
    env = RewardDelay(GridWorldEnv(size=3), Uniform(0, 2**27))
    with pytest.raises(NotCompilable, match=r"can reach 134217728 steps.*limit is 4194304 slots"):
        CompiledRun(env, np.array([0]), seed=0)
    agent = QLearning(env, seed=0)
    tracemalloc.start()
    agent.learn(20_000, log_interval=None)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert agent.last_learn_path == "python" and peak < 32 * 2**20
    assert RING_LIMIT == 1 << 22


def test_episodes_that_end_bound_the_ring_without_changing_what_is_delivered():
    """50-step episodes, delays up to 2**27: every delay past the episode's end is clipped at 50.

    Each episode's delivered rewards still sum to its undelayed rewards (flush).
    """
    env = RewardDelay(GridWorldEnv(size=3, max_steps=50), Uniform(0, 2**27))
    run = CompiledRun(env, np.array([0]), seed=1)
    assert run.delay_clip == 50
    q = np.zeros((9, 1, 4))
    flat = q.reshape(9, -1)
    log = run.run(
        q, flat.max(axis=1), np.arange(9) * 4 + flat.argmax(axis=1), 5_000, start_step=0,
        learning_rate=0.1, gamma=0.9, eps_initial=1.0, eps_final=1.0, eps_steps=1,
    )  # fmt: skip
    assert run.ring.size <= 64
    ends = np.flatnonzero(log.episode_end) + 1
    assert ends.size == 100
    for delivered, emitted in zip(np.split(log.reward, ends)[:-1], np.split(log.undelayed_reward, ends)[:-1], strict=True):  # fmt: skip
        assert delivered.sum() == pytest.approx(emitted.sum(), abs=1e-9)

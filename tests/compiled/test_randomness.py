"""The compiled path owns its randomness: a run's generator, not numba's process-global one."""

from __future__ import annotations

import copy
import threading

import gymnasium as gym
import numba
import numpy as np
import pytest
from support import ALPHA, binned_chisquare

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.agents import MultipleModelQLearning, QLearning
from delayed_rl.compiled import CompiledRun
from delayed_rl.compiled.kernel import generator_state, next_uniform
from delayed_rl.delays import Poisson
from delayed_rl.wrappers import RewardDelay

MASK = (1 << 64) - 1


def _reference_xoshiro256ss(state: list[int], n: int) -> list[float]:
    """xoshiro256** written plainly from its published definition, in Python integers."""
    s = list(state)
    out = []
    for _ in range(n):
        result = (((s[1] * 5) << 7 | (s[1] * 5 & MASK) >> 57) & MASK) * 9 & MASK
        t = s[1] << 17 & MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = (s[3] << 45 | s[3] >> 19) & MASK
        out.append((result >> 11) * 2.0**-53)
    return out


@numba.njit
def _draws(rng, n):
    out = np.empty(n)
    for i in range(n):
        out[i] = next_uniform(rng)
    return out


def test_the_generator_is_xoshiro256ss_and_advances_its_own_state():
    state = generator_state(np.random.SeedSequence(12345))
    expected = _reference_xoshiro256ss([int(word) for word in state], 1000)
    drawn = _draws(state.copy(), 1000)
    np.testing.assert_array_equal(drawn, expected)
    first, second = state.copy(), state.copy()
    _draws(first, 10)
    np.testing.assert_array_equal(_draws(first, 5), _draws(second, 15)[10:])


def test_draws_are_uniform():
    """200k draws in 100 equal bins: a chi-square test at the 1e-4 level (a fixed seed)."""
    draws = _draws(generator_state(np.random.SeedSequence(7)), 200_000)
    assert draws.min() >= 0.0 and draws.max() < 1.0
    counts = np.bincount((draws * 100).astype(np.int64), minlength=100)
    from scipy import stats

    assert stats.chisquare(counts).pvalue > 1e-4
    assert abs(np.corrcoef(draws[:-1], draws[1:])[0, 1]) < 5 / np.sqrt(draws.size)


def _grid():
    return gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=3)


def _two_part_run(seed: int, between=None) -> np.ndarray:
    """An MMQ agent trained 20k steps, then 20k more; ``between`` runs in between."""
    agent = MultipleModelQLearning(_grid(), max_delay_estimate=6, q_init=20.0, seed=seed)
    agent.learn(20_000)
    if between is not None:
        between()
    agent.learn(20_000, reset_num_timesteps=False)
    assert agent.last_learn_path == "compiled"
    return agent.q_table.copy()


def test_a_run_continues_the_same_whatever_trains_in_between():
    """Another agent's compiled training between two learn() calls leaves the first's run alone."""
    alone = _two_part_run(3)
    other = QLearning(_grid(), q_init=5.0, seed=99)
    interleaved = _two_part_run(3, between=lambda: other.learn(30_000))
    np.testing.assert_array_equal(alone, interleaved)


def test_runs_in_threads_match_runs_alone():
    alone = {seed: _two_part_run(seed) for seed in (1, 2)}
    results: dict[int, np.ndarray] = {}
    threads = [
        threading.Thread(target=lambda seed=seed: results.__setitem__(seed, _two_part_run(seed)))
        for seed in (1, 2)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for seed in (1, 2):
        np.testing.assert_array_equal(results[seed], alone[seed])


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda run: copy.deepcopy(copy.deepcopy(run))])
def test_a_copied_run_continues_exactly_like_the_original(copier):
    env = _grid()
    run = CompiledRun(env, np.arange(4), seed=5)
    q = np.full((25, 4, 4), 10.0)
    flat = q.reshape(25, -1)
    cache = [flat.max(axis=1), np.arange(25) * 16 + flat.argmax(axis=1)]
    rule = {"learning_rate": 0.1, "gamma": 0.9, "eps_initial": 0.1, "eps_final": 0.1}
    run.run(q, *cache, 5_000, start_step=0, eps_steps=1, **rule)
    twin, twin_q = copier(run), q.copy()
    twin_cache = [c.copy() for c in cache]
    logs = [
        r.run(table, *c, 5_000, start_step=5_000, eps_steps=1, **rule)
        for r, table, c in ((run, q, cache), (twin, twin_q, twin_cache))
    ]
    for field in logs[0]._fields:
        np.testing.assert_array_equal(getattr(logs[0], field), getattr(logs[1], field))
    np.testing.assert_array_equal(q, twin_q)


def test_same_seed_same_compiled_run_and_other_seeds_differ():
    first, again, other = (_two_part_run(seed) for seed in (4, 4, 5))
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_how_learn_splits_a_run_changes_nothing():
    """Chunks (log_interval, the chunk cap) do not change a seeded compiled run."""
    tables = []
    for log_interval in (None, 777, 10_000):
        agent = MultipleModelQLearning(_grid(), max_delay_estimate=6, q_init=20.0, seed=8)
        agent.learn(150_000, log_interval=log_interval)
        assert agent.last_learn_path == "compiled"
        tables.append(agent.q_table.copy())
    for table in tables[1:]:
        np.testing.assert_array_equal(tables[0], table)


@pytest.mark.parametrize("max_delay", [None, 6])
def test_compiled_run_draws_poisson_delays(max_delay):
    """The compiled run's delays are Poisson(λ), capped like the wrapper's (the tail at the cap)."""
    env = RewardDelay(gym.make("delayed_rl/GridWorld-3x3-v0").unwrapped, 9.0, max_delay=max_delay)
    run = CompiledRun(env, np.array([0]), seed=4)
    draws = np.concatenate([run._draw_delays(10_000) for _ in range(5)])
    pmf = Poisson(9.0).pmf(np.arange(60))
    if max_delay is not None:
        assert draws.max() == max_delay
        pmf[max_delay] = 1.0 - pmf[:max_delay].sum()
        pmf[max_delay + 1 :] = 0.0
    assert binned_chisquare(draws, lambda k: pmf[k]) > ALPHA

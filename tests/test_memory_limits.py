"""Bounded memory: what the wrappers and envs allocate stays proportional to what they need.

Each test measures with ``tracemalloc`` (numpy reports its buffers to it): either the peak stays
under a small bound, or a request that truly needs more than a stated limit fails at construction,
before anything large is allocated, with an error naming the argument and the size it would take.
"""

from __future__ import annotations

import re
import tracemalloc
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from support import NeverEndingEnv

from delayed_rl.delays import Constant, Geometric, Poisson
from delayed_rl.envs.gridworld import MAX_STATES, GridWorldEnv
from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv
from delayed_rl.envs.linefollow.track import (
    MAX_TRACK_VERTICES,
    SAMPLE_SPACING,
    Track,
    make_track,
    random_track,
)
from delayed_rl.wrappers import ObservationDelay, RewardDelay, VectorRewardDelay
from delayed_rl.wrappers.pending_rewards import MAX_RING_ENTRIES

MB = 1 << 20


def peak_of(make):
    """``(result, peak bytes)`` of calling ``make`` under tracemalloc."""
    tracemalloc.start()
    try:
        result = make()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def peak_of_error(make, exc, match):
    """The peak bytes allocated before ``make`` raises ``exc`` matching ``match``."""
    tracemalloc.start()
    try:
        with pytest.raises(exc, match=match):
            make()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def circle(radius: float, n: int = 2000) -> np.ndarray:
    theta = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    points = np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])
    return np.vstack([points, points[:1]])


# --- delay rings -----------------------------------------------------------------------------


@pytest.mark.large
@pytest.mark.parametrize("delay", [Poisson(1e9), Constant(2**63 - 1), Geometric(1e-9)], ids=repr)
def test_vector_rings_start_small_and_hold_only_what_is_pending(delay) -> None:
    def run():
        vec = SyncVectorEnv(
            [NeverEndingEnv, NeverEndingEnv], autoreset_mode=AutoresetMode.NEXT_STEP
        )
        env = VectorRewardDelay(vec, delay)
        env.reset(seed=0)
        for _ in range(2000):
            *_, info = env.step(np.zeros(2, dtype=int))
        return env, info

    (env, info), peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    np.testing.assert_array_equal(info["pending_reward"], [2000.0, 2000.0])  # nothing lost


def test_vector_ring_grows_with_the_delays_drawn_and_stops_at_its_limit() -> None:
    vec = SyncVectorEnv([NeverEndingEnv] * 4, autoreset_mode=AutoresetMode.NEXT_STEP)
    env = VectorRewardDelay(vec, Poisson(1e6))
    env.reset(seed=0)
    assert env.pending_rewards.ring.size <= 4 * 64  # small at first
    for _ in range(50):
        env.step(np.zeros(4, dtype=int))
    assert env.pending_rewards.ring.size <= MAX_RING_ENTRIES
    np.testing.assert_array_equal(env.pending_rewards.pending, [50.0] * 4)


@pytest.mark.sb3
def test_sb3_rings_start_small() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    def run():
        env = VecRewardDelay(DummyVecEnv([NeverEndingEnv, NeverEndingEnv]), Poisson(1e9), seed=0)
        env.reset()
        for _ in range(500):
            *_, infos = env.step(np.zeros(2, dtype=int))
        return infos

    infos, peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    assert [info["pending_reward"] for info in infos] == [500.0, 500.0]


@pytest.mark.parametrize("delay", [Poisson(1e9), Constant(2**63 - 1)], ids=repr)
def test_single_env_wrappers_hold_only_what_is_pending(delay) -> None:
    def run():
        env = ObservationDelay(RewardDelay(NeverEndingEnv(), delay), delay)
        env.reset(seed=0)
        for _ in range(2000):
            info = env.step(0)[4]
        return info

    info, peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    assert info["pending_reward"] == 2000.0


# --- the grid world ----------------------------------------------------------------------------


def test_gridworld_too_large_fails_before_allocating() -> None:
    peak = peak_of_error(
        lambda: GridWorldEnv(size=1000), ValueError, r"size=1000 would build tables of 1,000,000"
    )
    assert peak < MB
    peak = peak_of_error(
        lambda: gym.make("delayed_rl/GridWorld-v0", size=1000), ValueError, r"size=1000"
    )
    assert peak < 4 * MB


@pytest.mark.parametrize("size", [10**12, 10**400, 10**5000], ids=["1e12", "1e400", "1e5000"])
def test_gridworld_sizes_far_too_large_get_a_readable_message(size: int) -> None:
    with pytest.raises(ValueError, match=r"size=.* would build tables of .* states .*the limit"):
        GridWorldEnv(size=size)


def test_gridworld_error_states_the_limit() -> None:
    side = int(MAX_STATES**0.5)
    with pytest.raises(ValueError, match=rf"the limit is {MAX_STATES:,} states \(size <= {side}\)"):
        GridWorldEnv(size=side + 1)


@pytest.mark.parametrize("size", [3, 5, 9, 50])
def test_realistic_gridworlds_are_small(size: int) -> None:
    env, peak = peak_of(lambda: GridWorldEnv(size=size))
    assert env.n_states == size * size
    assert peak < 2 * MB + 1200 * size * size


@pytest.mark.large
def test_the_largest_gridworld_allowed_builds() -> None:
    side = int(MAX_STATES**0.5)
    env, peak = peak_of(lambda: GridWorldEnv(size=side))
    assert env.n_states == MAX_STATES
    assert peak < 200 * MB


# --- tracks -----------------------------------------------------------------------------------


def test_a_track_of_radius_1000_m_fails_before_allocating() -> None:
    points = circle(1000.0)
    peak = peak_of_error(lambda: Track.from_polyline(points), ValueError, r"points.*vertices")
    assert peak < 2 * MB
    peak = peak_of_error(lambda: Track(points[:-1]), ValueError, r"points.*vertices")
    assert peak < 2 * MB
    peak = peak_of_error(lambda: EPuckLineFollowEnv(track=points), ValueError, r"track")
    assert peak < 4 * MB


def test_the_track_error_names_the_size_and_the_limit() -> None:
    with pytest.raises(ValueError, match=rf"the limit is {MAX_TRACK_VERTICES:,} vertices") as e:
        Track.from_polyline(circle(1000.0))
    assert re.search(r"6,283 m long and would need 1,25\d,\d{3} vertices", str(e.value))


def test_random_track_with_a_huge_mean_radius_fails_at_once(monkeypatch) -> None:
    from delayed_rl.envs.linefollow import track as track_module

    def never(*args, **kwargs):
        raise AssertionError("a track was drawn before the size was checked")

    monkeypatch.setattr(track_module, "_smooth_track", never)
    monkeypatch.setattr(track_module.np.random, "default_rng", never)
    peak = peak_of_error(lambda: random_track(0, mean_radius=50), ValueError, r"mean_radius=50")
    assert peak < 8 * MB


def test_tracks_of_a_few_metres_are_small() -> None:
    for name in ("oval", "racetrack", "figure8"):
        track = make_track(name)
        assert len(track.points) < 2000
    track, peak = peak_of(lambda: Track.from_polyline(circle(3.0)))
    assert track.length == pytest.approx(2 * np.pi * 3.0, rel=1e-3)
    assert peak < 16 * MB


@pytest.mark.large
def test_the_longest_tracks_allowed_build_in_seconds() -> None:
    radius = 0.95 * MAX_TRACK_VERTICES * SAMPLE_SPACING / (2 * np.pi)
    track, peak = peak_of(lambda: Track.from_polyline(circle(radius, 8000)))
    assert len(track.points) <= MAX_TRACK_VERTICES
    assert track.clearance(0.5) < 0.6
    assert peak < 100 * MB
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        track = random_track(1, mean_radius=10.0)
    assert track.length > 50


# --- the agents' tables ------------------------------------------------------------------------


def test_deconvq_tables_too_large_fail_before_allocating() -> None:
    from delayed_rl.agents import DeconvolutionQLearning

    env = GridWorldEnv(size=200)  # 160,000 pairs: 1025 reward sums each would take 1.2 GiB
    peak = peak_of_error(
        lambda: DeconvolutionQLearning(env, max_delay_estimate=1024),
        ValueError,
        r"DeconvolutionQLearning\(max_delay_estimate=1024\) on an env of 40000 states and 4 actions needs "
        r"1.\d+ GiB of tables .*over MAX_TABLE_BYTES = 1 GiB",
    )
    assert peak < MB
    peak = peak_of_error(
        lambda: DeconvolutionQLearning(env, max_delay_estimate=10**9),
        ValueError,
        "max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024",
    )
    assert peak < MB


def test_deconvq_statistics_a_file_declares_are_checked_before_they_are_read(
    tmp_path, monkeypatch
) -> None:
    from delayed_rl.agents import DeconvolutionQLearning
    from delayed_rl.agents.common import save_util
    from delayed_rl.agents.deconvolution import agent as deconvolution

    path = (
        DeconvolutionQLearning(GridWorldEnv(size=3), max_delay_estimate=5, seed=0)
        .learn(50)
        .save(tmp_path / "d")
    )
    monkeypatch.setattr(deconvolution, "STATISTICS_LIMIT", 2**10)  # its counts take 7.8 KiB

    def never(*args, **kwargs):
        raise AssertionError("an array was read before the sizes were checked")

    monkeypatch.setattr(save_util.ModelFile, "read", never)
    with pytest.raises(
        ValueError, match=r"regression_cooc and regression_keys declare 0 MiB, more"
    ):
        DeconvolutionQLearning.load(path)

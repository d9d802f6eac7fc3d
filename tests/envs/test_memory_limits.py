"""Bounded memory: the grid world's and the line-following tracks' sizes, checked before allocating.

Each test measures with ``tracemalloc`` (numpy reports its buffers to it): either the peak stays
under a small bound, or a request that truly needs more than a stated limit fails at construction,
before anything large is allocated, with an error naming the argument and the size it would take.
"""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from support import MB, peak_of, peak_of_error

from delayed_rl.envs.gridworld import MAX_STATES, GridWorldEnv
from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv
from delayed_rl.envs.linefollow.track import (
    MAX_TRACK_VERTICES,
    SAMPLE_SPACING,
    Track,
    make_track,
    random_track,
)


def circle(radius: float, n: int = 2000) -> np.ndarray:
    theta = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    points = np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])
    return np.vstack([points, points[:1]])


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

"""The compiled track queries, camera reading and physics equal their Python references bit for bit.

``delayed_rl.envs.linefollow._kernels`` (track and camera) and ``_chipmunk`` (the robot's
sub-steps) replace numpy and pymunk-wrapper code that stays as their reference and fallback.
Here both run on the same random queries, including awkward ones (points on vertices, exact
axis headings, far from the track, across a figure-eight's crossing), and must give the same
bits; ``test_linefollow_trajectories.py`` does the same for whole episodes.
"""

from __future__ import annotations

import math
import platform
import sys

import numpy as np
import pytest

from delayed_rl import _portable_math as portable_math
from delayed_rl.envs.linefollow import _chipmunk, _kernels
from delayed_rl.envs.linefollow.camera import Camera, line_centroid
from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv
from delayed_rl.envs.linefollow.robot import EPuckRobot
from delayed_rl.envs.linefollow.track import Track, make_track, random_track

needs_kernels = pytest.mark.skipif(not _kernels.enabled(), reason="compiled kernels not in use")
needs_drive = pytest.mark.skipif(not _chipmunk.enabled(), reason="compiled physics not in use")


def tracks() -> list[Track]:
    square = [(0.0, 0.0), (0.6, 0.0), (0.6, 0.6), (0.0, 0.6), (0.0, 0.0)]  # coarse, sharp corners
    return [
        make_track("racetrack"),
        make_track("oval"),
        make_track("figure8"),
        random_track(4),
        Track.from_polyline(square, min_turn_radius=0.0, max_corner_angle=90.0),
    ]


TRACKS = tracks()


def poses(track: Track, rng: np.random.Generator, n: int) -> list[tuple[float, float, float]]:
    """Poses near the track (most), on its vertices, far from it, with exact axis headings."""
    out = []
    for _ in range(n):
        x, y, heading = track.point_at(rng.uniform(0.0, track.length))
        scale = rng.choice([0.0, 0.005, 0.03, 0.3])
        out.append((x + rng.normal(0.0, scale), y + rng.normal(0.0, scale), heading))
    out += [(float(x), float(y), 0.0) for x, y in track.points[:: max(1, len(track.points) // 8)]]
    for heading in (0.0, -0.0, math.pi / 2, -math.pi / 2, math.pi, 2.5 * math.pi):
        x, y, _ = track.point_at(0.3 * track.length)
        out.append((x, y, heading))
    out.append((5.0, -4.0, 1.0))  # far away: the whole track is searched
    return out


def same(a, b) -> bool:
    """Equal values of equal types, floats bit for bit (repr tells −0.0 from 0.0)."""
    return repr(a) == repr(b) and [type(v) for v in a] == [type(v) for v in b]


@needs_kernels
@pytest.mark.parametrize("track", TRACKS, ids=lambda t: t.name)
def test_locate_equals_the_numpy_reference(track):
    rng = np.random.default_rng(1)
    for x, y, _ in poses(track, rng, 300):
        assert same(track.locate(x, y), track._locate_numpy(x, y, None))
        _, _, seg = track._locate_numpy(x, y, None)
        for hint in (seg, (seg + 7) % len(track.points), int(rng.integers(len(track.points)))):
            assert same(track.locate(x, y, hint), track._locate_numpy(x, y, hint)), (x, y, hint)


@needs_kernels
@pytest.mark.parametrize("track", TRACKS, ids=lambda t: t.name)
def test_camera_read_equals_the_numpy_reference(track):
    rng = np.random.default_rng(2)
    camera, seen = Camera(), 0
    for x, y, heading in poses(track, rng, 300):
        for h in (heading, heading + rng.normal(0.0, 0.6)):
            compiled, reference = camera.read(track, x, y, h), camera._read_numpy(track, x, y, h)
            assert compiled.dtype == reference.dtype == np.bool_
            assert np.array_equal(compiled, reference), (x, y, h)
            seen += bool(reference.any())
    assert seen > 200  # most readings see the line: the comparison is not of empty rows


@needs_kernels
def test_near_line_equals_the_numpy_reference_for_any_points():
    track, rng = make_track("racetrack"), np.random.default_rng(3)
    for x, y, _ in poses(track, rng, 200):
        xs, ys = x + rng.normal(0.0, 0.01, 30), y + rng.normal(0.0, 0.01, 30)
        compiled = track.near_line(xs + 1j * ys, 0.005, complex(x, y))
        assert np.array_equal(compiled, track._near_line_numpy(xs, ys, 0.005, x, y))


@needs_kernels
def test_the_env_reads_through_observe_without_its_dispatch():
    env = EPuckLineFollowEnv(track="figure8", camera_noise=0.1, line_contrast=0.8)
    env.reset(seed=3)
    arguments = env._reading_arguments()
    draws, out = arguments[-2], arguments[-1]
    assert env._observe is not None and env._observe is not _kernels.observe
    rng = np.random.default_rng(2)
    for x, y, heading in poses(env.track, rng, 40):
        draws[:] = rng.random(draws.shape)
        hint = int(rng.integers(0, 5))
        sin, cos = portable_math.sincos(heading)
        pose = (x, y, cos, sin, hint, 0.8, 0.1)
        direct = env._observe(*pose, *arguments)
        direct_pixels = out.copy()
        assert same(direct, _kernels.observe(*pose, *arguments))
        assert np.array_equal(direct_pixels, out)


@needs_kernels
def test_an_interrupted_first_reading_is_made_again_at_the_next(monkeypatch):
    from delayed_rl.envs.linefollow import env as env_module

    real, calls = env_module.entry_point, []

    def interrupted_once(*args):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt  # e.g. Ctrl-C during a first compilation
        return real(*args)

    monkeypatch.setattr(env_module, "entry_point", interrupted_once)
    env = EPuckLineFollowEnv(track="oval")
    with pytest.raises(KeyboardInterrupt):
        env.reset(seed=4)
    obs, _ = env.reset(seed=4)
    fresh = EPuckLineFollowEnv(track="oval")
    assert (obs, env.step(2)[:4]) == (fresh.reset(seed=4)[0], fresh.step(2)[:4])


@needs_kernels
def test_the_compiled_centroid_is_line_centroid():
    rng = np.random.default_rng(4)
    for row in rng.random((500, 40)) < rng.random((500, 1)):
        assert _kernels.centroid(row) == line_centroid(row)


def test_the_queries_refuse_bad_arguments():
    track = make_track("oval")
    with pytest.raises(ValueError, match=r"hint must be None or a segment in 0\.\.\d+, got -1"):
        track.locate(0.0, 0.0, -1)
    with pytest.raises(ValueError, match="hint"):
        track.locate(0.0, 0.0, len(track.points))
    with pytest.raises(ValueError, match="hint"):
        track.locate(0.0, 0.0, 2.5)
    if _kernels.enabled():
        with pytest.raises(ValueError, match=r"points must be a \(k,\) array"):
            track.near_line(np.zeros((2, 2), dtype=complex), 0.005, 0j)


def test_a_camera_is_immutable():
    camera = Camera()
    with pytest.raises(AttributeError):
        camera.look_ahead = 0.06
    with pytest.raises(ValueError):
        camera.offsets[0] = 0.0


@pytest.mark.skipif(
    not (sys.platform == "linux" and platform.machine() in ("x86_64", "aarch64")),
    reason="the compiled paths are known to apply on Linux x86-64 and aarch64",
)
def test_the_compiled_paths_are_in_use_here():
    assert _kernels.enabled() and _chipmunk.enabled()


# ---------------------------------------------------------------------- physics
def robots(motor_lag: float, physics_dt: float) -> tuple[EPuckRobot, EPuckRobot]:
    """Two robots in the same state, one stepping compiled, one from Python."""
    compiled, python = EPuckRobot(physics_dt, motor_lag), EPuckRobot(physics_dt, motor_lag)
    for robot in (compiled, python):
        robot.reset(0.2, -0.1, 2.0)
    assert compiled._driver[0] is _chipmunk.drive_entry()
    python._driver = (_chipmunk.drive_python, python._calls)
    return compiled, python


@needs_drive
@pytest.mark.parametrize(("motor_lag", "physics_dt"), [(0.0, 0.016), (0.05, 0.2 / 13)])
def test_the_compiled_sub_steps_equal_the_python_ones(motor_lag, physics_dt):
    compiled, python = robots(motor_lag, physics_dt)
    rng = np.random.default_rng(5)
    for _ in range(300):
        left, right = (float(v) for v in rng.choice([-300.0, 0.0, 100.0, 300.0], 2))
        substeps = int(rng.integers(1, 14))
        slip = (float(rng.uniform(0.9, 1.0)), float(rng.uniform(0.9, 1.0)))
        pose = compiled.step(left, right, substeps, slip)
        assert same(pose, python.step(left, right, substeps, slip))
        assert same(compiled.wheel_speeds, python.wheel_speeds)
    assert repr(compiled._state()) == repr(python._state())
    assert same(compiled.pose, compiled.step(0.0, 0.0, 0))


def test_step_returns_the_pose_after_it():
    robot = EPuckRobot()
    robot.reset(0.0, 0.0, 0.0)
    assert robot.step(300.0, 200.0, 4) == robot.pose != (0.0, 0.0, 0.0)

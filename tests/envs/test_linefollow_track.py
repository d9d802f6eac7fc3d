"""Track geometry: built-in and random tracks, user polylines, nearest-point queries."""

from __future__ import annotations

import math

import numpy as np
import pytest

from delayed_rl.envs.linefollow.track import (
    MIN_TURN_RADIUS,
    SAMPLE_SPACING,
    TRACK_NAMES,
    Track,
    corner_angles,
    make_track,
    random_track,
    self_intersections,
    turn_radii,
)


def circle(radius: float, n: int, centre=(0.0, 0.0), closed: bool = True) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pts = np.column_stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)])
    return np.vstack([pts, pts[:1]]) if closed else pts


def stadium(half_straight: float = 1.0, radius: float = 0.5, n_arc: int = 64) -> np.ndarray:
    """A closed stadium-shaped polyline, driven counter-clockwise.

    The straight y = 0 from x = −half to x = +half (towards +x), then a half circle, the straight
    y = 2r back, and another half circle.
    """
    a = np.linspace(-np.pi / 2, np.pi / 2, n_arc + 1)
    right = np.column_stack([half_straight + radius * np.cos(a), radius + radius * np.sin(a)])
    left = np.column_stack(
        [-half_straight - radius * np.cos(a), radius - radius * np.sin(a)]
    )  # from top to bottom
    pts = np.vstack([right, left])
    return np.vstack([pts, pts[:1]])


def assert_valid_track(track: Track, min_radius: float) -> None:
    p = track.points
    assert np.all(np.isfinite(p))
    # Closed: the implied closing segment is as short as every other one.
    assert np.linalg.norm(p[0] - p[-1]) <= SAMPLE_SPACING + 1e-12
    seg = np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1)
    assert seg.max() <= SAMPLE_SPACING + 1e-12
    assert math.isclose(track.length, seg.sum(), rel_tol=1e-12)
    # Smooth: the heading turns by at most (segment length / min radius) per vertex.
    heading = np.angle(np.diff(np.vstack([p, p[:1], p[1:2]]), axis=0) @ [1, 1j])
    turn = np.abs(np.angle(np.exp(1j * np.diff(heading))))
    assert turn.max() <= 1.01 * seg.max() / min_radius
    assert turn_radii(p).min() >= min_radius * (1 - 1e-9)
    assert track.min_turn_radius >= min_radius * (1 - 1e-9)


@pytest.mark.parametrize("name", ["oval", "racetrack"])
def test_named_tracks_are_valid_and_simple(name):
    track = make_track(name)
    assert_valid_track(track, MIN_TURN_RADIUS)
    assert self_intersections(track.points) == []
    assert track.clearance(0.5) > 0.2


def test_racetrack_has_long_turns_and_a_lap_of_about_1700_steps():
    track = make_track("racetrack")
    radii = turn_radii(track.points)
    assert 0.2 <= track.min_turn_radius <= 0.3
    # Long turns: more than a third of the lap is curved (radius < 1 m) ...
    assert (radii < 1.0).mean() > 1 / 3
    # ... and the rest is nearly straight.
    assert (radii > 2.0).mean() > 0.15
    assert 4.0 < track.length < 6.0


def test_figure8_crosses_itself_once_at_the_origin():
    track = make_track("figure8")
    assert track.allow_crossings
    assert_valid_track(track, MIN_TURN_RADIUS)
    crossings = self_intersections(track.points)
    assert 1 <= len(crossings) <= 2  # one crossing point (maybe hit by two segments pairs)
    for i, j in crossings:
        for k in (i, j):
            assert np.linalg.norm(track.points[k]) < 2 * SAMPLE_SPACING


@pytest.mark.parametrize("seed", range(12))
def test_random_tracks_are_closed_smooth_simple_and_followable(seed):
    track = make_track("random", seed)
    assert_valid_track(track, 0.2)
    assert self_intersections(track.points) == []
    assert track.clearance(0.5) >= 0.15


def test_random_tracks_depend_on_the_seed_only():
    a, b = random_track(3), random_track(3)
    assert np.array_equal(a.points, b.points)
    assert not np.array_equal(random_track(4).points[:10], a.points[:10])
    gen = random_track(np.random.default_rng(3))
    assert np.array_equal(gen.points, a.points)
    assert make_track("random", 3) is make_track("random", 3)  # int seeds are cached


def test_make_track_rejects_unknown_names():
    with pytest.raises(ValueError, match=r"name must be one of \('oval'.*got 'ovl'"):
        make_track("ovl")
    with pytest.raises(TypeError, match="name"):
        make_track(None)
    assert set(TRACK_NAMES) == {"oval", "racetrack", "figure8", "random"}


def test_random_track_argument_checks():
    with pytest.raises(ValueError, match="min_turn_radius"):
        random_track(0, min_turn_radius=0.01)
    with pytest.raises(ValueError, match="mean_radius"):
        random_track(0, mean_radius=0.1)
    with pytest.raises(ValueError, match="harmonics"):
        random_track(0, harmonics=1)


@pytest.mark.parametrize(
    ("name", "wrong_type", "bad_value"),
    [
        ("seed", "3", -3),
        ("min_turn_radius", "0.2", 0.05),
        ("clearance", None, -0.1),
        ("mean_radius", "1", 0.3),
        ("harmonics", 5.0, 1),
        ("max_tries", True, 0),
    ],
)
def test_random_track_arguments_refuse_a_wrong_type_and_a_bad_value(name, wrong_type, bad_value):
    with pytest.raises(TypeError, match=name):
        random_track(**{name: wrong_type})
    with pytest.raises(ValueError, match=name):
        random_track(**{name: bad_value})


def test_make_track_checks_the_random_seed():
    with pytest.raises(TypeError, match="seed"):
        make_track("random", 1.5)
    with pytest.raises(ValueError, match="seed"):
        make_track("random", -1)
    assert make_track("random", np.int64(3)) is make_track("random", 3)


def test_turn_radii_of_a_circle_is_its_radius():
    assert np.allclose(turn_radii(circle(0.7, 100, closed=False)), 0.7)
    square_line = np.array([[0, 0], [1, 0], [2, 0], [1, 1]], dtype=float)
    assert math.isinf(turn_radii(square_line)[1])  # collinear vertex


def test_self_intersections_finds_a_bow_tie():
    bow = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], dtype=float)
    assert self_intersections(bow) == [(0, 2)]
    assert self_intersections(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)) == []


def test_from_polyline_accepts_a_closed_smooth_polygon_and_keeps_its_vertices():
    pts = circle(0.5, 48)
    track = Track.from_polyline(pts, name="mine")
    assert track.name == "mine"
    assert math.isclose(track.min_turn_radius, 0.5, rel_tol=1e-9)
    perimeter = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert math.isclose(track.length, perimeter, rel_tol=1e-12)
    # every given vertex is on the dense polyline
    d = np.linalg.norm(track.points[:, None, :] - pts[None, :-1, :], axis=2).min(axis=0)
    assert d.max() < 1e-12
    assert np.linalg.norm(np.diff(track.points, axis=0), axis=1).max() <= SAMPLE_SPACING + 1e-12


@pytest.mark.parametrize(
    ("points", "error", "match"),
    [
        (circle(0.5, 48)[:-1], ValueError, r"must be closed.*repeat the first point"),
        ([[0, 0], [1, 0], [0, 0]], ValueError, r"at least 3 distinct points"),
        (
            np.vstack([circle(0.5, 48)[:5], [[np.nan, 0]], circle(0.5, 48)[5:]]),
            ValueError,
            "finite",
        ),
        ([[0, 0, 0], [1, 0, 0]], ValueError, r"shape \(n, 2\)"),
        ("not points", TypeError, "array-like of"),
        ([[0, 0], ["a", 1]], TypeError, "array-like of"),
        (
            np.array([[0, 0], [1, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float),
            ValueError,
            "repeated consecutive points",
        ),
        (
            np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float),
            ValueError,
            r"kinks by 90° at point \d.*> max_corner_angle 60",
        ),
        (
            0.05 * circle(1.0, 48),
            ValueError,
            r"turns too sharply at point \d+.*turning radius 0.05 m < min_turn_radius 0.1",
        ),
    ],
)
def test_from_polyline_rejects_bad_polylines(points, error, match):
    with pytest.raises(error, match=match):
        Track.from_polyline(points)


def test_from_polyline_rejects_self_intersection_unless_allowed():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    eight = np.column_stack([np.sin(t), 0.4 * np.sin(2 * t)])
    eight = np.vstack([eight, eight[:1]])
    with pytest.raises(ValueError, match=r"crosses itself.*allow_crossings=True"):
        Track.from_polyline(eight)
    assert Track.from_polyline(eight, allow_crossings=True).allow_crossings


@pytest.mark.parametrize(
    ("name", "wrong_type", "bad_value"),
    [
        ("points", 5, [[0.0, 0.0, 0.0]]),
        ("min_turn_radius", "0.1", -1.0),
        ("max_corner_angle", None, 181.0),
        ("allow_crossings", 1, None),  # any bool is allowed: no bad value of the right type
    ],
)
def test_from_polyline_arguments_refuse_a_wrong_type_and_a_bad_value(name, wrong_type, bad_value):
    kwargs = {"points": circle(0.5, 48)}
    with pytest.raises(TypeError, match=name):
        Track.from_polyline(**{**kwargs, name: wrong_type})
    if bad_value is not None:
        with pytest.raises(ValueError, match=name if name != "points" else r"shape \(n, 2\)"):
            Track.from_polyline(**{**kwargs, name: bad_value})


def test_track_constructor_checks_its_arguments():
    points = circle(0.5, 48)[:-1]
    with pytest.raises(TypeError, match="min_turn_radius"):
        Track(points, min_turn_radius="0.1")
    with pytest.raises(ValueError, match="min_turn_radius"):
        Track(points, min_turn_radius=-0.1)
    with pytest.raises(TypeError, match="allow_crossings"):
        Track(points, allow_crossings="yes")
    with pytest.raises(TypeError, match="points"):
        Track(None)
    with pytest.raises(ValueError, match="points"):
        Track(np.zeros((4, 3)))


def test_from_polyline_checks_its_own_arguments():
    with pytest.raises(ValueError, match="min_turn_radius"):
        Track.from_polyline(circle(0.5, 48), min_turn_radius=-1.0)
    with pytest.raises(ValueError, match="max_corner_angle"):
        Track.from_polyline(circle(0.5, 48), max_corner_angle=0.0)
    hexagon = circle(0.8, 6)
    with pytest.raises(ValueError, match="kinks by 60"):
        Track.from_polyline(hexagon, max_corner_angle=59.0)
    assert corner_angles(hexagon[:-1]) == pytest.approx([60.0] * 6)
    assert Track.from_polyline(hexagon).length == pytest.approx(6 * 0.8)
    # A smaller min_turn_radius lets a tighter polygon through.
    small = circle(0.05, 48)
    with pytest.raises(ValueError, match="turns too sharply"):
        Track.from_polyline(small)
    assert Track.from_polyline(small, min_turn_radius=0.04).min_turn_radius == pytest.approx(0.05)


def test_locate_and_point_at_on_a_counter_clockwise_circle():
    track = Track.from_polyline(circle(0.5, 720))
    for s in (0.0, 0.3, 1.7, track.length - 0.01):
        x, y, heading = track.point_at(s)
        assert math.isclose(math.hypot(x, y), 0.5, rel_tol=1e-4)
        # counter-clockwise: heading is the radius direction + 90°
        assert math.isclose(math.cos(heading - math.atan2(y, x) - math.pi / 2), 1.0, abs_tol=1e-4)
        s2, lateral, _ = track.locate(x, y)
        assert math.isclose(s2, s, abs_tol=1e-9) or math.isclose(abs(s2 - s), track.length)
        assert abs(lateral) < 1e-9
    # Inside a counter-clockwise loop is to the left of the direction of travel.
    _, lateral_in, _ = track.locate(0.45, 0.0)
    _, lateral_out, _ = track.locate(0.56, 0.0)
    assert lateral_in == pytest.approx(0.05, abs=1e-4)
    assert lateral_out == pytest.approx(-0.06, abs=1e-4)
    # Far from the track the global nearest point is still found.
    s_far, lateral_far, _ = track.locate(3.0, 0.0)
    assert lateral_far == pytest.approx(-2.5, abs=1e-4)
    assert min(s_far, track.length - s_far) < 1e-3


def test_locate_with_a_hint_stays_on_its_branch_of_the_figure8():
    track = make_track("figure8")
    # Both branches pass through the origin; approach it along the branch through s ≈ 0.
    s_start, _, seg = track.locate(*track.point_at(track.length - 0.05)[:2])
    on_branch = []
    for s in np.linspace(track.length - 0.05, track.length + 0.05, 41):
        x, y, _ = track.point_at(s)
        found, lateral, seg = track.locate(x + 1e-4, y, seg)
        on_branch.append(
            min(abs(found - s % track.length), track.length - abs(found - s % track.length))
        )
    assert max(on_branch) < 1e-3
    assert s_start == pytest.approx(track.length - 0.05, abs=1e-6)


def test_near_line_marks_points_within_half_width():
    track = Track.from_polyline(stadium())
    xs = np.linspace(-0.5, 0.5, 11)
    points = xs * 0 + 1j * np.array([0.0, 0.004, -0.004, 0.006, -0.006, 0.0049, 0.0051, 0, 0, 0, 0])
    points = points + xs
    near = track.near_line(points, 0.005, complex(0.0, 0.0) + 0.0)
    # only points whose |y| ≤ 0.005 and that lie within CELL_SIZE of the lookup centre count
    expected = (np.abs(points.imag) <= 0.005) & (np.abs(points - 0.0) <= 0.036)
    assert np.array_equal(near, expected)


def test_coarse_points_are_densified_for_the_index():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    track = Track(square)  # unvalidated, but still indexed correctly
    assert len(track.points) == 800
    assert track.length == pytest.approx(4.0)
    # The middle of a 1 m side is found by the spatial index.
    assert track.near_line(np.array([0.5 + 0.001j]), 0.005, 0.5 + 0.0j).tolist() == [True]
    assert track.locate(0.5, 0.01, None)[:2] == pytest.approx((0.5, 0.01))


def _brute_force_clearance(track: Track, exclude_arc: float) -> float:
    """Every pair of vertices compared: the definition of :meth:`Track.clearance`."""
    p, s = track.points, track._s0
    d2 = ((p[:, None, :] - p[None, :, :]) ** 2).sum(axis=2)
    ds = np.abs(s[:, None] - s[None, :])
    far = np.minimum(ds, track.length - ds) > exclude_arc
    return float(np.sqrt(d2[far].min())) if far.any() else math.inf


@pytest.mark.parametrize("name", ["oval", "racetrack", "figure8", "stadium", "random"])
@pytest.mark.parametrize("exclude_arc", [0.0, 0.01, 0.3, 0.5, 1.2, 2.6, 100.0])
def test_clearance_equals_the_all_pairs_definition(name, exclude_arc):
    if name == "stadium":
        track = Track.from_polyline(stadium())
    elif name == "random":
        track = random_track(3)
    else:
        track = make_track(name)
    assert track.clearance(exclude_arc) == _brute_force_clearance(track, exclude_arc)


def test_the_spatial_index_stores_only_the_cells_near_the_line():
    small, large = Track.from_polyline(circle(0.5, 400)), Track.from_polyline(circle(8.0, 4000))
    # 16 times the length, 256 times the bounding box: the index grows with the length
    assert len(large._cells) < 20 * len(small._cells)
    assert len(large._cells) < 0.1 * large._nx * large._ny

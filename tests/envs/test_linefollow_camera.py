"""The 1×40 line camera: centroid rounding (thesis Eq. 5.6) and scanline geometry."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from delayed_rl.envs.linefollow.camera import (
    CENTRE_PIXEL,
    FIELD_WIDTH,
    LINE_WIDTH,
    LOOK_AHEAD,
    N_PIXELS,
    Camera,
    line_centroid,
)
from delayed_rl.envs.linefollow.track import Track


def row(*seen: int) -> np.ndarray:
    """A scanline with the given 1-based pixels seeing the line."""
    pixels = np.zeros(N_PIXELS, dtype=bool)
    pixels[np.asarray(seen, dtype=int) - 1] = True
    return pixels


def stadium() -> np.ndarray:
    """Closed polyline whose bottom side is the straight y = 0, x ∈ [−1, 1], driven towards +x."""
    a = np.linspace(-np.pi / 2, np.pi / 2, 65)
    right = np.column_stack([1.0 + 0.5 * np.cos(a), 0.5 + 0.5 * np.sin(a)])
    left = np.column_stack([-1.0 - 0.5 * np.cos(a), 0.5 - 0.5 * np.sin(a)])
    pts = np.vstack([right, left])
    return np.vstack([pts, pts[:1]])


@pytest.fixture(scope="module")
def straight() -> Track:
    return Track.from_polyline(stadium())


def seen_pixels(camera: Camera, track: Track, x: float, y: float, heading: float) -> list[int]:
    return (np.flatnonzero(camera.read(track, x, y, heading)) + 1).tolist()


def test_thesis_example_pixels_18_to_23_give_state_20():
    assert line_centroid(row(*range(18, 24))) == 20


@pytest.mark.parametrize(
    ("seen", "expected"),
    [
        (range(17, 23), 19),  # 19.5 → 19 (half-down; Python's round gives 20)
        (range(19, 25), 21),  # 21.5 → 21 (Python's round gives 22)
        (range(18, 25), 21),  # 21.0
        ([1], 1),
        ([40], 40),
        ([1, 40], 20),  # 20.5 → 20
        ([1, 2, 40], 14),  # 43 / 3 = 14.33
        ([38, 39, 40], 39),
        (range(1, 41), 20),
    ],
)
def test_centroid_rounds_to_nearest_with_ties_down(seen, expected):
    assert line_centroid(row(*seen)) == expected


def test_centroid_is_zero_without_line_and_batches():
    assert line_centroid(np.zeros(N_PIXELS)) == 0
    batch = np.stack([row(*range(18, 24)), np.zeros(N_PIXELS, bool), row(40)]).astype(np.float32)
    out = line_centroid(batch)
    assert out.dtype == np.int64
    assert out.tolist() == [20, 0, 40]
    # Every possible contiguous run: batched and single answers agree, all in 1..40.
    runs = np.array([row(*range(a, b + 1)) for a in range(1, 41) for b in range(a, 41)])
    batched = line_centroid(runs)
    assert batched.tolist() == [line_centroid(r) for r in runs]
    assert batched.min() == 1 and batched.max() == 40


def test_centroid_rejects_wrong_shapes():
    with pytest.raises(ValueError, match="40 values"):
        line_centroid(np.zeros(39))
    with pytest.raises(ValueError, match="40 values"):
        line_centroid(5)


def test_documented_geometry_constants():
    camera = Camera()
    assert (camera.look_ahead, camera.field_width, camera.line_width) == (0.05, 0.064, 0.010)
    assert (LOOK_AHEAD, FIELD_WIDTH, LINE_WIDTH, CENTRE_PIXEL) == (0.05, 0.064, 0.010, 20)
    assert camera.pixel_width == pytest.approx(0.0016)


def test_pixel_one_is_on_the_left_and_the_scanline_is_ahead():
    camera = Camera()
    pts = camera.sample_points(0.0, 0.0, 0.0)  # facing +x: left is +y
    assert np.allclose(pts[:, 0], LOOK_AHEAD)
    assert pts[0, 1] == pytest.approx(19.5 * 0.0016)
    assert pts[-1, 1] == pytest.approx(-19.5 * 0.0016)
    assert np.all(np.diff(pts[:, 1]) < 0)
    # Facing +y, left is −x and "ahead" is +y.
    pts = camera.sample_points(1.0, 2.0, math.pi / 2)
    assert np.allclose(pts[:, 1], 2.0 + LOOK_AHEAD)
    assert pts[0, 0] < 1.0 < pts[-1, 0]


def test_centred_on_a_straight_line_reads_the_centre(straight):
    # Line half-width 5 mm = 3.125 pixels around the scanline's centre, which lies between
    # pixels 20 and 21 (offset 20.5): pixels 18..23 see it, centroid 20.5 → 20 = p_centre.
    camera = Camera()
    assert seen_pixels(camera, straight, 0.0, 0.0, 0.0) == list(range(18, 24))
    assert line_centroid(camera.read(straight, 0.0, 0.0, 0.0)) == CENTRE_PIXEL


@pytest.mark.parametrize("shift_px", [-12, -8, -3, 3, 8, 12])
def test_a_lateral_offset_moves_the_centroid_by_the_expected_pixels(straight, shift_px):
    # The robot at y = d (left of the line when d > 0, facing +x) sees the line at lateral
    # offset −d, i.e. shifted d / pixel_width pixels towards pixel 40 (its right).
    camera = Camera()
    d = shift_px * FIELD_WIDTH / N_PIXELS
    expected = [i for i in range(1, 41) if abs((20.5 - i) * 0.0016 + d) <= LINE_WIDTH / 2]
    assert expected == list(range(18 + shift_px, 24 + shift_px))
    assert seen_pixels(camera, straight, 0.3, d, 0.0) == expected
    assert line_centroid(camera.read(straight, 0.3, d, 0.0)) == CENTRE_PIXEL + shift_px


def test_the_same_offset_reads_mirrored_when_driving_the_other_way(straight):
    camera = Camera()
    d = 5 * 0.0016  # robot 8 mm above the line, now facing −x: the line is on its left
    assert line_centroid(camera.read(straight, 0.3, d, math.pi)) == CENTRE_PIXEL - 5


def test_look_ahead_distance(straight):
    # Facing the straight line at right angles, the scanline lies along it when the body centre
    # is exactly LOOK_AHEAD behind it: all 40 pixels see it; 6 mm further back none do.
    camera = Camera()
    assert seen_pixels(camera, straight, 0.0, -LOOK_AHEAD, math.pi / 2) == list(range(1, 41))
    assert seen_pixels(camera, straight, 0.0, -LOOK_AHEAD - 0.0049, math.pi / 2) == list(
        range(1, 41)
    )
    assert seen_pixels(camera, straight, 0.0, -LOOK_AHEAD - 0.006, math.pi / 2) == []


def test_off_the_track_sees_nothing(straight):
    camera = Camera()
    assert seen_pixels(camera, straight, 0.0, -0.3, 0.0) == []
    assert seen_pixels(camera, straight, 50.0, 50.0, 1.0) == []
    assert line_centroid(camera.read(straight, 0.0, -0.3, 0.0)) == 0


def test_a_tilted_line_is_seen_wider(straight):
    # Heading 30° off the line, the scanline crosses it at 60° and covers
    # LINE_WIDTH / sin(60°) of it; the robot is placed so the crossing is at the scanline's centre.
    camera = Camera()
    heading = math.radians(30)
    pixels = camera.read(straight, 0.0, -LOOK_AHEAD * math.sin(heading), heading)
    width = np.count_nonzero(pixels) * camera.pixel_width
    assert width == pytest.approx(LINE_WIDTH / math.sin(math.radians(60)), abs=camera.pixel_width)
    assert line_centroid(pixels) in (20, 21)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"look_ahead": 0.0}, r"look_ahead must be a number > 0 \(m\), got 0.0"),
        ({"field_width": float("nan")}, "field_width"),
        ({"line_width": -1.0}, "line_width"),
        ({"field_width": 0.2}, "track index's reach"),
    ],
)
def test_camera_rejects_bad_geometry(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Camera(**kwargs)


@pytest.mark.parametrize("name", ["look_ahead", "field_width", "line_width"])
def test_camera_arguments_refuse_a_wrong_type_and_a_bad_value(name):
    with pytest.raises(TypeError, match=name):
        Camera(**{name: "0.01"})
    with pytest.raises(TypeError, match=name):
        Camera(**{name: True})
    with pytest.raises(ValueError, match=name):
        Camera(**{name: -0.01})


@given(st.lists(st.booleans(), min_size=N_PIXELS, max_size=N_PIXELS))
def test_centroid_matches_exact_rational_rounding(pixels):
    seen = [i for i, p in enumerate(pixels, start=1) if p]
    if not seen:
        assert line_centroid(pixels) == 0
        return
    c = Fraction(sum(seen), len(seen))
    expected = math.floor(c) + (1 if c - math.floor(c) > Fraction(1, 2) else 0)  # ties down
    assert line_centroid(pixels) == expected
    assert abs(line_centroid(pixels) - c) <= Fraction(1, 2)

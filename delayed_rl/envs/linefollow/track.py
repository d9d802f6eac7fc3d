"""Track geometry for the e-puck line-following task.

A :class:`Track` is a closed centreline with a spatial grid that answers the env's two
questions every step (:meth:`Track.near_line`, :meth:`Track.locate`), compiled where numba is
installed (:mod:`~delayed_rl.envs.linefollow._kernels`) to the same bits. :func:`make_track`
builds ``"oval"``, ``"racetrack"``, ``"figure8"`` and ``"random"``; :meth:`Track.from_polyline`
validates a user's own. The turning-radius, corner and size limits and why: the docs'
environments page (``docs/envs.md``, "The tracks").
"""

from __future__ import annotations

import functools
import math
import numbers
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from delayed_rl import _portable_math as portable_math
from delayed_rl._validation import check_bool, check_choice, check_int, check_real
from delayed_rl.envs.linefollow import _kernels

__all__ = [
    "BYTES_PER_VERTEX",
    "MAX_CORNER_ANGLE",
    "MAX_TRACK_VERTICES",
    "MIN_TURN_RADIUS",
    "SAMPLE_SPACING",
    "TRACK_NAMES",
    "Track",
    "figure8_track",
    "make_track",
    "oval_track",
    "racetrack_track",
    "random_track",
]

#: Smallest turning radius (m) any track may have.
MIN_TURN_RADIUS = 0.1
#: Largest kink (degrees) allowed at a vertex of a user's polyline. The drawn line has a corner
#: there; the proportional controller follows 72° kinks without losing the line, loses it
#: briefly at 90° and needs recoveries at 120°, so 60° leaves a margin.
MAX_CORNER_ANGLE = 60.0
#: Longest segment (m) of a track's dense polyline.
SAMPLE_SPACING = 0.005
#: Side (m) of the spatial grid's cells. A query returns every segment within this distance of
#: the query point, which covers the camera's scanline (3.12 cm half-length + 0.5 cm line
#: half-width from its centre) and one dense segment.
CELL_SIZE = 0.04
#: Segments either side of the previous answer that :meth:`Track.locate` searches first
#: (20 × 5 mm = 10 cm, far more than the robot moves in one step).
LOCAL_WINDOW = 20
#: Names accepted by :func:`make_track`.
TRACK_NAMES = ("oval", "racetrack", "figure8", "random")
#: The most vertices a track's dense centreline may have: 200 m of line at
#: :data:`SAMPLE_SPACING`. A 2000-step episode drives at most 4.9 m (300 steps/s ≈ 3.9 cm/s for
#: 128 s) and the thesis's track is 5.1 m long, so every realistic track is far below it; at the
#: limit a track still builds and checks in seconds (``benchmarks/SPEED.md``).
MAX_TRACK_VERTICES = 40_000
#: About what one dense vertex costs (its geometry, its nine entries in the spatial grid, its
#: window for hinted lookups and the compiled queries' copy of its geometry and grid entries).
BYTES_PER_VERTEX = 760
#: Candidate pairs examined at once by :meth:`Track.clearance` (bounds its temporary arrays).
_PAIR_CHUNK = 1 << 21

FloatArray = NDArray[np.float64]
_EMPTY = slice(0, 0)


def _norms(v: FloatArray) -> FloatArray:
    """The length of each row ``(x, y)`` of ``v``, ``sqrt(x·x + y·y)`` (no BLAS, no ``hypot``)."""
    return np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])


def _as_points(points: ArrayLike, name: str = "points") -> FloatArray:
    """``points`` as an ``(n, 2)`` float array.

    Raises:
        TypeError: ``points`` is not an array-like of numbers (a single number included).
        ValueError: it is, but not of shape ``(n, 2)``.
    """
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name} must be an array-like of (x, y) points in metres, got {points!r}"
        ) from exc
    if arr.ndim == 0:  # a number (or None, which numpy reads as NaN) is no polyline
        raise TypeError(
            f"{name} must be an array-like of (x, y) points in metres, got {points!r} "
            f"({type(points).__name__})"
        )
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(
            f"{name} must have shape (n, 2) (a polyline of (x, y) points), got shape {arr.shape}"
        )
    return arr


def turn_radii(points: ArrayLike) -> FloatArray:
    """Turning radius (m) at every vertex of a closed polyline.

    The radius at vertex i is that of the circle through vertices i−1, i and i+1 (the inverse
    of the Menger curvature); it equals R exactly for points on a circle of radius R and is
    ``inf`` where three vertices are collinear.

    Args:
        points: ``(n, 2)`` vertices of a closed polyline (the closing segment is implied).

    Returns:
        ``(n,)`` radii.
    """
    p = _as_points(points)
    a = p - np.roll(p, 1, axis=0)
    b = np.roll(p, -1, axis=0) - p
    c = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    cross = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    lengths = _norms(a) * _norms(b) * _norms(c)
    with np.errstate(divide="ignore", invalid="ignore"):
        radii = lengths / (2.0 * cross)
    return np.where(cross > 0.0, radii, np.inf)


def corner_angles(points: ArrayLike) -> FloatArray:
    """The kink (degrees, 0 = straight on) at every vertex of a closed polyline.

    Args:
        points: ``(n, 2)`` vertices of a closed polyline (the closing segment is implied).
    """
    p = _as_points(points)
    d = np.roll(p, -1, axis=0) - p
    before = np.roll(d, 1, axis=0)
    cross = before[:, 0] * d[:, 1] - before[:, 1] * d[:, 0]
    dot = before[:, 0] * d[:, 0] + before[:, 1] * d[:, 1]
    return np.degrees(np.abs(portable_math.atan2_array(cross, dot)))


def _segment_crossings(a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray) -> Any:
    """Whether segments a0–a1 and b0–b1 (broadcast arrays of points) properly intersect or touch."""

    def orient(p: FloatArray, q: FloatArray, r: FloatArray) -> FloatArray:
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0]
        )

    d1 = orient(b0, b1, a0)
    d2 = orient(b0, b1, a1)
    d3 = orient(a0, a1, b0)
    d4 = orient(a0, a1, b1)
    return (d1 * d2 <= 0.0) & (d3 * d4 <= 0.0)


def self_intersections(points: ArrayLike) -> list[tuple[int, int]]:
    """Pairs of non-adjacent segments of a closed polyline that intersect or touch.

    Segment i joins vertex i to vertex i+1 (mod n). Adjacent segments (sharing a vertex) are not
    compared.

    Args:
        points: ``(n, 2)`` vertices of a closed polyline (the closing segment is implied).

    Returns:
        Sorted ``(i, j)`` pairs with ``i < j``; empty for a simple polygon.
    """
    p = _as_points(points)
    n = len(p)
    q = np.roll(p, -1, axis=0)
    lo = np.minimum(p, q)
    hi = np.maximum(p, q)
    pairs: list[tuple[int, int]] = []
    chunk = max(1, 2_000_000 // max(n, 1))
    idx = np.arange(n)
    for start in range(0, n, chunk):
        i = idx[start : start + chunk, None]
        j = idx[None, :]
        # Bounding boxes overlap, j > i, and the segments are not neighbours (mod n).
        cand = (
            (j > i)
            & (j != i + 1)
            & ~((i == 0) & (j == n - 1))
            & (lo[i, 0] <= hi[j, 0])
            & (lo[j, 0] <= hi[i, 0])
            & (lo[i, 1] <= hi[j, 1])
            & (lo[j, 1] <= hi[i, 1])
        )
        ii, jj = np.nonzero(cand)
        if ii.size == 0:
            continue
        ii = ii + start
        hit = _segment_crossings(p[ii], q[ii], p[jj], q[jj])
        pairs.extend(zip(ii[hit].tolist(), jj[hit].tolist(), strict=True))
    return sorted(pairs)


def _dense_vertices(points: FloatArray) -> tuple[int, float]:
    """``(vertices, length)`` of the closed polyline ``points`` once densified for a track."""
    lengths = _norms(np.roll(points, -1, axis=0) - points)
    length = float(lengths.sum())
    if lengths.max(initial=0.0) <= SAMPLE_SPACING * (1 + 1e-9):
        return len(points), length
    pieces = np.maximum(1.0, np.ceil(lengths / SAMPLE_SPACING - 1e-9))
    return int(pieces.sum()), length


def _check_size(points: FloatArray, name: str = "points") -> None:
    """Refuse a polyline whose dense track would pass :data:`MAX_TRACK_VERTICES`.

    Raises:
        ValueError: naming ``name``, the track's length, the vertices it would need and the limit.
    """
    vertices, length = _dense_vertices(points)
    if vertices > MAX_TRACK_VERTICES:
        raise ValueError(
            f"{name}: the track is {length:,.0f} m long and would need {vertices:,} vertices of "
            f"at most {SAMPLE_SPACING * 1000:g} mm (about {vertices * BYTES_PER_VERTEX / 1e6:,.0f}"
            f" MB); the limit is {MAX_TRACK_VERTICES:,} vertices "
            f"({MAX_TRACK_VERTICES * SAMPLE_SPACING:g} m of track, MAX_TRACK_VERTICES)"
        )


def _polyline_vertices(points: ArrayLike) -> FloatArray:
    """The vertices of a user's closed polyline, its closing point (a repeat of the first) cut.

    Raises:
        TypeError: ``points`` is not an array-like of numbers.
        ValueError: the polyline is not of shape ``(n + 1, 2)``, holds non-finite values, has
            fewer than 4 points or is not closed (last == first, within 1 µm).
    """
    p = _as_points(points)
    if not np.all(np.isfinite(p)):
        bad = np.argwhere(~np.isfinite(p))[0, 0]
        raise ValueError(f"track polyline must be finite, got point {bad} = {p[bad].tolist()}")
    if len(p) < 4:
        raise ValueError(
            f"track polyline needs at least 3 distinct points plus the closing point "
            f"(last == first), got {len(p)} points"
        )
    if _norms(p[-1:] - p[:1])[0] > 1e-6:
        raise ValueError(
            f"track polyline must be closed: its last point {p[-1].tolist()} must equal its "
            f"first point {p[0].tolist()} (repeat the first point at the end)"
        )
    return p[:-1]


def _check_segments(p: FloatArray) -> None:
    """Refuse a closed polyline ``p`` with a segment of no length (a repeated vertex).

    Raises:
        ValueError: naming the first repeated vertex.
    """
    seg = _norms(np.roll(p, -1, axis=0) - p)
    if np.any(seg <= 1e-9):
        bad = int(np.argmax(seg <= 1e-9))
        raise ValueError(
            f"track polyline has repeated consecutive points at index {bad}: "
            f"{p[bad].tolist()}; every segment must have a positive length"
        )


def _tightest_turn(p: FloatArray, min_turn_radius: float) -> float:
    """The smallest turning radius (m) at a vertex of the closed polyline ``p``.

    Raises:
        ValueError: it is below ``min_turn_radius`` (naming the vertex).
    """
    radii = turn_radii(p)
    worst = int(np.argmin(radii))
    if radii[worst] < min_turn_radius:
        raise ValueError(
            f"track polyline turns too sharply at point {worst} {p[worst].tolist()}: turning "
            f"radius {radii[worst]:.4g} m < min_turn_radius {min_turn_radius} m (the robot "
            f"cannot follow it); smooth the corner or pass a smaller min_turn_radius"
        )
    return float(radii[worst])


def _check_corners(p: FloatArray, max_corner_angle: float) -> None:
    """Refuse a closed polyline ``p`` that kinks by more than ``max_corner_angle`` degrees.

    Raises:
        ValueError: naming the sharpest vertex.
    """
    angles = corner_angles(p)
    sharpest = int(np.argmax(angles))
    if angles[sharpest] > max_corner_angle + 1e-9:
        raise ValueError(
            f"track polyline kinks by {angles[sharpest]:.4g}° at point {sharpest} "
            f"{p[sharpest].tolist()} > max_corner_angle {max_corner_angle}° (the camera loses "
            f"the line at sharp corners); add vertices to round the corner"
        )


def _check_crossings(p: FloatArray) -> None:
    """Refuse a closed polyline ``p`` that crosses itself.

    Raises:
        ValueError: naming the first two segments that meet, and how many crossings there are.
    """
    crossings = self_intersections(p)
    if crossings:
        i, j = crossings[0]
        raise ValueError(
            f"track polyline crosses itself: segment {i} {p[i].tolist()}→"
            f"{p[(i + 1) % len(p)].tolist()} meets segment {j} {p[j].tolist()}→"
            f"{p[(j + 1) % len(p)].tolist()} ({len(crossings)} crossing(s)); pass "
            f"allow_crossings=True for a figure-eight"
        )


def _resample(points: FloatArray, spacing: float) -> FloatArray:
    """A closed polyline through every vertex of ``points`` with segments at most ``spacing``."""
    q = np.roll(points, -1, axis=0)
    lengths = _norms(q - points)
    pieces = np.maximum(1, np.ceil(lengths / spacing - 1e-9).astype(np.int64))
    seg = np.repeat(np.arange(len(points)), pieces)
    frac = (np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)) / np.repeat(
        pieces, pieces
    )
    return points[seg] + frac[:, None] * (q[seg] - points[seg])


def _uniform_resample(points: FloatArray, spacing: float) -> FloatArray:
    """Resample a densely evaluated smooth closed curve at (nearly) uniform arc length."""
    closed = np.vstack([points, points[:1]])
    s = np.concatenate([[0.0], np.cumsum(_norms(np.diff(closed, axis=0)))])
    n = max(3, int(np.ceil(s[-1] / spacing)))
    targets = np.arange(n) * (s[-1] / n)
    return np.column_stack(
        [np.interp(targets, s, closed[:, 0]), np.interp(targets, s, closed[:, 1])]
    )


def _offsets(x: Any, y: Any, a: NDArray, d: NDArray, inv: FloatArray) -> tuple[Any, Any, Any]:
    """``(t, er, ei)``: the projections of (x, y) on segments ``a → a + d`` and the offsets from them.

    ``t = clip((wr·dr + wi·di) · inv, 0, 1)`` with ``w = (x, y) − a`` (0 for −0.0 too, NaN
    stays), ``e = w − t·d``: real operations only, in the order of ``_kernels._offset_from_segment``,
    so the numpy reference and the compiled queries agree to the bit on every CPU. ``x`` and
    ``y`` broadcast against the segments.
    """
    dr, di = d.real, d.imag
    wr, wi = x - a.real, y - a.imag
    t = (wr * dr + wi * di) * inv
    t = np.where(t <= 0.0, 0.0, t)
    t = np.where(t > 1.0, 1.0, t)
    return t, wr - t * dr, wi - t * di


class Track:
    """A closed line on the floor: a dense centreline polyline plus a spatial index.

    Build one with :meth:`from_polyline` (validated) or :func:`make_track`. Tracks are immutable
    and safe to share between envs.

    Attributes:
        name: a label (``"oval"``, ``"custom"``, ``"random-<seed>"``...).
        points: ``(n, 2)`` dense centreline vertices (m), no two consecutive ones more than
            :data:`SAMPLE_SPACING` apart (coarser input is densified); the closing segment is
            implied.
        length: the centreline's length (m).
        min_turn_radius: the smallest turning radius (m) of the track as given (before
            densification).
        allow_crossings: whether the track may cross itself (the figure-eight).

    The constructor takes ``points`` and the attributes above as keyword arguments; it does not
    validate the geometry (:meth:`from_polyline` does), but refuses points that are not a finite
    ``(n, 2)`` array (``TypeError``/``ValueError``) or would need more than
    :data:`MAX_TRACK_VERTICES` dense vertices (``ValueError``), a ``min_turn_radius`` that is not
    a number ``>= 0`` and an ``allow_crossings`` that is not a bool.
    """

    def __init__(
        self,
        points: ArrayLike,
        *,
        name: str = "custom",
        min_turn_radius: float | None = None,
        allow_crossings: bool = False,
    ):
        min_turn_radius = check_real("min_turn_radius", min_turn_radius, 0.0, optional=True)
        allow_crossings = check_bool("allow_crossings", allow_crossings)
        p = _as_points(points)
        if len(p) == 0 or not np.all(np.isfinite(p)):
            raise ValueError(f"points must be a non-empty array of finite (x, y) points, got {p}")
        _check_size(p)
        if _norms(np.roll(p, -1, axis=0) - p).max() > SAMPLE_SPACING * (1 + 1e-9):
            p = _resample(p, SAMPLE_SPACING)  # the spatial index relies on short segments
        self.name = name
        self.allow_crossings = allow_crossings
        self.points = p
        z = np.empty(len(p), dtype=np.complex128)  # complex storage; the queries use its parts
        z.real, z.imag = p[:, 0], p[:, 1]
        d = np.roll(z, -1) - z
        seg_len = np.sqrt(d.real * d.real + d.imag * d.imag)
        self._a = z  # segment i runs from _a[i] to _a[i] + _d[i]
        self._d = d
        self._seg_len = seg_len
        self._inv_len2 = 1.0 / np.maximum(seg_len * seg_len, 1e-300)
        self._s0 = np.concatenate([[0.0], np.cumsum(seg_len)[:-1]])
        self.length = float(seg_len.sum())
        self.min_turn_radius = (
            float(turn_radii(p).min()) if min_turn_radius is None else float(min_turn_radius)
        )
        self.bounds = (p.min(axis=0), p.max(axis=0))
        self._build_index()
        for arr in (self.points, self._a, self._d, self._seg_len, self._inv_len2, self._s0):
            arr.setflags(write=False)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_polyline(
        cls,
        points: ArrayLike,
        *,
        name: str = "custom",
        min_turn_radius: float = MIN_TURN_RADIUS,
        max_corner_angle: float = MAX_CORNER_ANGLE,
        allow_crossings: bool = False,
    ) -> Track:
        """Validate a user's closed polyline and build a track from it.

        The polyline must be closed explicitly: its last point equals its first (within 1 µm).
        Between consecutive vertices the line is straight (the track is densified so that no
        segment is longer than :data:`SAMPLE_SPACING`, keeping every given vertex).

        Args:
            points: ``(n + 1, 2)`` vertices in metres, ``points[-1] == points[0]``, n ≥ 3.
            name: a label for the track.
            min_turn_radius: the smallest allowed turning radius (m) at any vertex (the radius of
                the circle through it and its two neighbours).
            max_corner_angle: the largest allowed kink (degrees) at any vertex: the line is
                drawn straight between vertices, so a coarse polygon has sharp corners even when
                the circle through its vertices is large.
            allow_crossings: allow the line to cross itself (as a figure-eight does).

        Raises:
            TypeError: if ``points`` is not an array-like of numbers, ``min_turn_radius`` or
                ``max_corner_angle`` is not a number or ``allow_crossings`` is not a bool.
            ValueError: if the polyline is not of shape ``(n + 1, 2)``, is not closed, has fewer
                than 3 distinct vertices, holds non-finite values or repeated consecutive
                vertices, crosses itself (unless ``allow_crossings``), turns more tightly than
                ``min_turn_radius``, kinks by more than ``max_corner_angle`` or would need more
                than :data:`MAX_TRACK_VERTICES` dense vertices (checked first, before any
                costly check); if ``min_turn_radius`` is negative or ``max_corner_angle``
                outside ``(0, 180]``.
        """
        min_turn_radius = check_real("min_turn_radius", min_turn_radius, 0.0)
        max_corner_angle = check_real(
            "max_corner_angle", max_corner_angle, 0.0, 180.0, low_open=True, note=" (degrees)"
        )
        allow_crossings = check_bool("allow_crossings", allow_crossings)
        p = _polyline_vertices(points)
        _check_size(p)
        _check_segments(p)
        radius = _tightest_turn(p, min_turn_radius)
        _check_corners(p, max_corner_angle)
        if not allow_crossings:
            _check_crossings(p)
        return cls(p, name=name, min_turn_radius=radius, allow_crossings=allow_crossings)

    def _build_index(self) -> None:
        """Build the spatial grid and the padded segment windows behind the queries.

        Each segment is registered (by its midpoint's cell) in that cell's 3×3 neighbourhood; per
        cell, its segments' data are stored contiguously (CSR), so a query is a slice, found in a
        dict holding only the cells the line passes near (memory follows the track's length, not
        the area it spans). A window of
        :data:`LOCAL_WINDOW` segments either side of each segment, stored contiguously too
        (wrapping round the track), serves hinted :meth:`locate` queries. The compiled queries
        (:mod:`~delayed_rl.envs.linefollow._kernels`) read the same grid from ``_packed``: the
        sorted cell keys, each cell's start in the CSR arrays, and the segments' geometry.
        """
        n = len(self._a)
        mid = self._a + 0.5 * self._d
        self._origin = (mid.real.min() - 2 * CELL_SIZE, mid.imag.min() - 2 * CELL_SIZE)
        self._nx = int(np.ceil((mid.real.max() + 2 * CELL_SIZE - self._origin[0]) / CELL_SIZE)) + 1
        self._ny = int(np.ceil((mid.imag.max() + 2 * CELL_SIZE - self._origin[1]) / CELL_SIZE)) + 1
        cx = np.floor((mid.real - self._origin[0]) / CELL_SIZE).astype(np.int64)
        cy = np.floor((mid.imag - self._origin[1]) / CELL_SIZE).astype(np.int64)
        offsets = [(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)]
        keys = np.concatenate([(cx + dx) * self._ny + (cy + dy) for dx, dy in offsets])
        segs = np.tile(np.arange(n), len(offsets))
        order = np.argsort(keys, kind="stable")
        keys, segs = keys[order], segs[order]
        cells, starts = np.unique(keys, return_index=True)
        stops = np.append(starts[1:], len(keys))
        self._cells = {
            key: slice(start, stop)
            for key, start, stop in zip(
                cells.tolist(), starts.tolist(), stops.tolist(), strict=True
            )
        }
        self._cell_segs = segs
        self._cell_a = self._a[segs]
        self._cell_d = self._d[segs]
        self._cell_inv = self._inv_len2[segs]
        w = np.arange(-LOCAL_WINDOW, n + LOCAL_WINDOW) % n  # padded: window of i = [i, i + 2W]
        self._pad_a = self._a[w]
        self._pad_d = self._d[w]
        self._pad_inv = self._inv_len2[w]
        # The geometry and the grid as the compiled queries (and the env) take them.
        self._packed = _kernels.pack_track(
            self._a,
            self._d,
            self._inv_len2,
            self._s0,
            self._seg_len,
            cell_keys=cells,  # the grid of _cells, searched by bisection
            cell_starts=np.append(starts, len(keys)),
            cell_segs=segs,
            origin=(float(self._origin[0]), float(self._origin[1])),
            shape=(self._nx, self._ny),
            cell_size=CELL_SIZE,
            length=self.length,
            window=LOCAL_WINDOW,
        )

    # ------------------------------------------------------------------ queries
    def _cell(self, x: float, y: float) -> slice:
        """The slice of the CSR arrays holding the segments registered in (x, y)'s cell."""
        ix = int((x - self._origin[0]) // CELL_SIZE)
        iy = int((y - self._origin[1]) // CELL_SIZE)
        if not (0 <= ix < self._nx and 0 <= iy < self._ny):
            return _EMPTY
        return self._cells.get(ix * self._ny + iy, _EMPTY)

    def near_line(self, points: NDArray[np.complex128], half_width: float, centre: complex) -> Any:
        """Which ``points`` lie within ``half_width`` of the centreline.

        Args:
            points: ``(k,)`` query points as complex numbers x + iy, all within
                ``CELL_SIZE − half_width`` of ``centre``.
            half_width: half the line's width (m).
            centre: a point (x + iy) for the spatial-index lookup (the camera's scanline centre).

        Returns:
            ``(k,)`` booleans.
        """
        points = np.asarray(points, dtype=np.complex128)
        if points.ndim != 1:
            raise ValueError(f"points must be a (k,) array of x + iy, got shape {points.shape}")
        centre = complex(centre)
        xs, ys = np.ascontiguousarray(points.real), np.ascontiguousarray(points.imag)
        if not _kernels.enabled():
            return self._near_line_numpy(xs, ys, half_width, centre.real, centre.imag)
        out = np.empty(len(points), dtype=bool)
        _kernels.near_line(xs, ys, float(half_width), centre.real, centre.imag, *self._packed, out)
        return out

    def _near_line_numpy(
        self, xs: FloatArray, ys: FloatArray, half_width: float, cx: float, cy: float
    ) -> Any:
        """:meth:`near_line` in numpy, on the points' coordinates and the centre's: the reference."""
        cell = self._cell(cx, cy)
        if cell.start == cell.stop:
            return np.zeros(len(xs), dtype=bool)
        _, er, ei = _offsets(
            xs[:, None], ys[:, None], self._cell_a[cell], self._cell_d[cell], self._cell_inv[cell]
        )
        return (np.sqrt(er * er + ei * ei) <= half_width).any(axis=1)

    def _nearest(
        self, x: float, y: float, a: NDArray, d: NDArray, inv: NDArray
    ) -> tuple[int, float, float, float]:
        """``(k, t, er, ei)``: the first nearest of the segments, as ``_kernels._nearest``."""
        t, er, ei = _offsets(x, y, a, d, inv)
        k = int(np.argmin(er * er + ei * ei))
        return k, float(t[k]), float(er[k]), float(ei[k])

    def locate(self, x: float, y: float, hint: int | None = None) -> tuple[float, float, int]:
        """The nearest centreline point to (x, y).

        Args:
            x: the query point's x (m).
            y: the query point's y (m).
            hint: the segment of the previous answer. When given, the nearest point among the
                :data:`LOCAL_WINDOW` segments either side of it is used if it is inside that
                window and within :data:`CELL_SIZE` of (x, y), so a robot crossing a
                figure-eight stays on its own branch; otherwise the global nearest point.

        Returns:
            ``(s, lateral, segment)``: the arc length (m, in ``[0, length)``) of the nearest
            point, the signed distance (m) of (x, y) from it (positive to the left of the
            direction of travel), and its segment (the next call's ``hint``).

        Raises:
            ValueError: ``hint`` is not a segment of the track (an int in ``[0, n)``).
        """
        n = len(self._a)
        if hint is not None and not (isinstance(hint, numbers.Integral) and 0 <= hint < n):
            raise ValueError(f"hint must be None or a segment in 0..{n - 1}, got {hint!r}")
        if not _kernels.enabled():
            return self._locate_numpy(float(x), float(y), hint)
        hint = -1 if hint is None else int(hint)
        return _kernels.locate(float(x), float(y), hint, *self._packed)

    def _locate_numpy(self, x: float, y: float, hint: int | None) -> tuple[float, float, int]:
        """:meth:`locate` in numpy: the reference the compiled version mirrors."""
        n = len(self._a)
        seg = -1
        if hint is not None:
            window = slice(hint, hint + 2 * LOCAL_WINDOW + 1)
            k, t, er, ei = self._nearest(
                x, y, self._pad_a[window], self._pad_d[window], self._pad_inv[window]
            )
            if 0 < k < 2 * LOCAL_WINDOW and math.sqrt(er * er + ei * ei) <= CELL_SIZE:
                seg = (hint + k - LOCAL_WINDOW) % n
        if seg < 0:
            cell = self._cell(x, y)
            if cell.start == cell.stop:
                k, t, er, ei = self._nearest(x, y, self._a, self._d, self._inv_len2)
                seg = k
            else:
                k, t, er, ei = self._nearest(
                    x, y, self._cell_a[cell], self._cell_d[cell], self._cell_inv[cell]
                )
                seg = int(self._cell_segs[cell][k])
        d = self._d[seg]
        cross = d.real * ei - d.imag * er
        length = math.sqrt(er * er + ei * ei)
        lateral = length if cross > 0 else -length if cross < 0 else 0.0
        s = (float(self._s0[seg]) + t * float(self._seg_len[seg])) % self.length
        return s, lateral, seg

    def point_at(self, s: float) -> tuple[float, float, float]:
        """The centreline point at arc length ``s`` (mod length): ``(x, y, heading)``."""
        s = float(s) % self.length
        seg = int(np.searchsorted(self._s0, s, side="right") - 1)
        a, d = complex(self._a[seg]), complex(self._d[seg])
        f = (s - float(self._s0[seg])) / float(self._seg_len[seg])
        return a.real + f * d.real, a.imag + f * d.imag, portable_math.atan2(d.imag, d.real)

    def clearance(self, exclude_arc: float) -> float:
        """Smallest distance between two vertices more than ``exclude_arc`` apart along the track.

        A measure of how close distinct parts of the track come to each other (the camera sees
        only one line while this exceeds its field width); ``inf`` if no two vertices are that
        far apart. Pairs are found with a grid whose cells double until the closest pair found is
        within one cell (so it is the closest of all): the cost follows the track's length times
        the vertices near each vertex, not the square of the vertex count.

        Args:
            exclude_arc: the arc length (m, ``>= 0``) within which pairs are not compared.

        Raises:
            TypeError: ``exclude_arc`` is not a number.
            ValueError: ``exclude_arc`` is negative, NaN or infinite.
        """
        exclude_arc = check_real("exclude_arc", exclude_arc, 0.0, note=" (m)")
        p = self.points
        span = float((p.max(axis=0) - p.min(axis=0)).max())
        cell = CELL_SIZE
        while True:
            best = self._closest_far_pair(cell, exclude_arc)
            if best <= cell * cell or cell > 2.0 * span:  # the grid then pairs every vertex
                return float(np.sqrt(best))
            cell *= 2.0

    def _closest_far_pair(self, cell: float, exclude_arc: float) -> float:
        """The smallest squared distance of the pairs more than ``exclude_arc`` apart in arc.

        Only pairs in neighbouring cells of a grid of side ``cell`` are compared: every pair
        closer than ``cell`` is among them.
        """
        p, s, length = self.points, self._s0, self.length
        cx = np.floor((p[:, 0] - p[:, 0].min()) / cell).astype(np.int64)
        cy = np.floor((p[:, 1] - p[:, 1].min()) / cell).astype(np.int64) + 1
        ny = int(cy.max()) + 2  # a free row either side: cy ± 1 never wraps to the next column
        keys = cx * ny + cy
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        best = np.inf
        for dx, dy in ((0, 0), (0, 1), (1, -1), (1, 0), (1, 1)):  # each neighbour pair once
            target = keys + (dx * ny + dy)
            lo = np.searchsorted(sorted_keys, target, side="left")
            counts = np.searchsorted(sorted_keys, target, side="right") - lo
            ends = np.cumsum(counts)
            start = 0
            while start < len(p):
                base = int(ends[start - 1]) if start else 0
                stop = max(start + 1, int(np.searchsorted(ends, base + _PAIR_CHUNK, "right")))
                chunk_counts = counts[start:stop]
                total = int(chunk_counts.sum())
                if total:
                    i = np.repeat(np.arange(start, stop), chunk_counts)
                    offset = np.arange(total) - np.repeat(
                        ends[start:stop] - chunk_counts - base, chunk_counts
                    )
                    j = order[np.repeat(lo[start:stop], chunk_counts) + offset]
                    d2 = ((p[i] - p[j]) ** 2).sum(axis=1)
                    ds = np.abs(s[i] - s[j])
                    far = np.minimum(ds, length - ds) > exclude_arc
                    if far.any():
                        best = min(best, float(d2[far].min()))
                start = stop
        return best

    def __repr__(self) -> str:
        return (
            f"Track(name={self.name!r}, length={self.length:.3f} m, "
            f"min_turn_radius={self.min_turn_radius:.3f} m, vertices={len(self.points)})"
        )


# ---------------------------------------------------------------------- built-in tracks
def _bspline_closed(control: ArrayLike, samples_per_span: int = 2000) -> FloatArray:
    """A closed uniform cubic B-spline (C² smooth) through-ish the control polygon."""
    c = np.asarray(control, dtype=np.float64)
    u = np.arange(samples_per_span) / samples_per_span
    u2, v = u * u, 1 - u
    u3 = u2 * u  # products, not np.power (a CPU-dependent SIMD loop)
    b0 = v * v * v / 6
    b1 = (3 * u3 - 6 * u2 + 4) / 6
    b2 = (-3 * u3 + 3 * u2 + 3 * u + 1) / 6
    b3 = u3 / 6
    spans = [
        b0[:, None] * c[j - 1]
        + b1[:, None] * c[j]
        + b2[:, None] * c[(j + 1) % len(c)]
        + b3[:, None] * c[(j + 2) % len(c)]
        for j in range(len(c))
    ]
    return np.vstack(spans)


def _smooth_track(curve: FloatArray, name: str, allow_crossings: bool = False) -> Track:
    dense = _uniform_resample(curve, SAMPLE_SPACING)
    return Track(dense, name=name, allow_crossings=allow_crossings)


@functools.cache
def oval_track() -> Track:
    """An ellipse with semi-axes 0.75 m × 0.45 m (length 3.8 m, tightest radius 0.27 m)."""
    t = np.linspace(0.0, 2 * np.pi, 16384, endpoint=False)
    curve = np.column_stack([0.75 * portable_math.cos_array(t), 0.45 * portable_math.sin_array(t)])
    return _smooth_track(curve, "oval")


#: Control polygon (m) of the racetrack's B-spline: long straights joined by long sweeping turns,
#: in the spirit of thesis Fig. 5.18.
RACETRACK_CONTROL = (
    (-0.6, -0.55),
    (0.3, -0.55),
    (0.85, -0.5),
    (1.0, -0.1),
    (0.8, 0.25),
    (0.35, 0.2),
    (0.1, 0.35),
    (0.05, 0.6),
    (-0.4, 0.65),
    (-0.85, 0.45),
    (-1.0, 0.0),
    (-0.95, -0.4),
)


@functools.cache
def racetrack_track() -> Track:
    """A race circuit of long sweeping turns and straights (see :data:`RACETRACK_CONTROL`)."""
    return _smooth_track(_bspline_closed(RACETRACK_CONTROL), "racetrack")


@functools.cache
def figure8_track() -> Track:
    """A figure-eight x = sin t, y = 0.4 sin 2t (m): 2 m wide, crossing itself at the origin."""
    t = np.linspace(0.0, 2 * np.pi, 16384, endpoint=False)
    curve = np.column_stack([portable_math.sin_array(t), 0.4 * portable_math.sin_array(2 * t)])
    return _smooth_track(curve, "figure8", allow_crossings=True)


def random_track(
    seed: int | np.random.Generator | None = None,
    *,
    min_turn_radius: float = 0.2,
    clearance: float = 0.15,
    mean_radius: float = 0.8,
    harmonics: int = 5,
    max_tries: int = 1000,
) -> Track:
    """A seeded random smooth closed track that does not cross itself.

    The centreline is a polar curve r(θ) = R·(1 + Σₖ aₖ cos(kθ + φₖ)), k = 2..``harmonics``, with
    random amplitudes (decaying as 1/k) and phases; r > 0 makes it simple (no self-intersection)
    and the finite Fourier series makes it smooth (C^∞). A draw is rejected until its tightest
    turn is at least ``min_turn_radius`` and distinct parts of the track stay at least
    ``clearance`` apart (so the camera never sees two lines).

    Args:
        seed: an int seed, a ``numpy.random.Generator`` (consumed), or None (fresh entropy).
        min_turn_radius: smallest turning radius (m), at least :data:`MIN_TURN_RADIUS`.
        clearance: smallest distance (m) between parts of the track more than half a metre
            apart along it.
        mean_radius: R, the mean distance (m) from the centre; the track is about 2πR long, so R
            may be at most ``MAX_TRACK_VERTICES * SAMPLE_SPACING / 2π`` (31.8 m); draws longer
            than :data:`MAX_TRACK_VERTICES` vertices are rejected like the others.
        harmonics: the highest harmonic k.
        max_tries: draws before giving up.

    Raises:
        TypeError: for an argument of the wrong type (a seed that is neither an int, a
            generator nor None; a radius or clearance that is not a number; a count that is not
            an int).
        ValueError: for an argument out of range (a negative seed, ``min_turn_radius`` below
            :data:`MIN_TURN_RADIUS`, ``mean_radius`` below ``2 * min_turn_radius`` or so large
            that the track would pass :data:`MAX_TRACK_VERTICES` (checked first, at once), a
            negative ``clearance``, ``harmonics < 2``, ``max_tries < 1``), or if no acceptable
            track was drawn.
    """
    if not isinstance(seed, np.random.Generator):
        seed = check_int("seed", seed, 0, optional=True)
    min_turn_radius = check_real("min_turn_radius", min_turn_radius, MIN_TURN_RADIUS, note=" (m)")
    clearance = check_real("clearance", clearance, 0.0, note=" (m)")
    mean_radius = check_real(
        "mean_radius", mean_radius, 2 * min_turn_radius, note=" (2 * min_turn_radius, m)"
    )
    _check_mean_radius(mean_radius)
    harmonics = check_int("harmonics", harmonics, 2)
    max_tries = check_int("max_tries", max_tries, 1)
    name = "random" if seed is None or isinstance(seed, np.random.Generator) else f"random-{seed}"
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    theta = np.linspace(0.0, 2 * np.pi, 16384, endpoint=False)
    cos_theta, sin_theta = portable_math.cos_array(theta), portable_math.sin_array(theta)
    k = np.arange(2, harmonics + 1)
    for _ in range(max_tries):
        r = _polar_radii(rng, mean_radius, k, theta)
        if r.min() <= 0.2 * mean_radius:
            continue
        curve = np.column_stack([r * cos_theta, r * sin_theta])
        track = _accepted_track(curve, name, min_turn_radius, clearance)
        if track is not None:
            return track
    raise ValueError(
        f"no random track with min_turn_radius={min_turn_radius} and clearance={clearance} "
        f"found in {max_tries} draws; relax them or raise mean_radius"
    )


def _check_mean_radius(mean_radius: float) -> None:
    """Refuse a ``mean_radius`` whose random tracks would pass :data:`MAX_TRACK_VERTICES`.

    Raises:
        ValueError: naming the track's length, its vertices, the limit and the largest radius.
    """
    circumference = 2 * np.pi * mean_radius
    if circumference / SAMPLE_SPACING > MAX_TRACK_VERTICES:
        largest = MAX_TRACK_VERTICES * SAMPLE_SPACING / (2 * np.pi)
        raise ValueError(
            f"mean_radius={mean_radius:g} would draw a track about {circumference:,.0f} m long "
            f"({circumference / SAMPLE_SPACING:,.0f} vertices of {SAMPLE_SPACING * 1000:g} mm); "
            f"the limit is {MAX_TRACK_VERTICES:,} vertices (MAX_TRACK_VERTICES): mean_radius "
            f"must be at most {largest:.3g} m"
        )


def _polar_radii(
    rng: np.random.Generator, mean_radius: float, k: NDArray, theta: FloatArray
) -> FloatArray:
    """One draw of :func:`random_track`'s r(θ) = R·(1 + Σₖ aₖ cos(kθ + φₖ)) at the angles ``theta``.

    The amplitudes first (uniform in [0, 0.35), divided by k − 1), then the phases.
    """
    amp = rng.uniform(0.0, 0.35, size=k.size) / (k - 1)
    phase = rng.uniform(0.0, 2 * np.pi, size=k.size)
    return mean_radius * (
        1.0 + (amp[:, None] * portable_math.cos_array(k[:, None] * theta + phase[:, None])).sum(0)
    )


def _accepted_track(
    curve: FloatArray, name: str, min_turn_radius: float, clearance: float
) -> Track | None:
    """The track of a drawn ``curve`` if :func:`random_track` accepts it, else ``None``.

    Accepted: its tightest turn is at least ``min_turn_radius`` (as drawn and once resampled),
    it needs at most :data:`MAX_TRACK_VERTICES` dense vertices, and parts of it more than half a
    metre apart along it stay at least ``clearance`` apart.
    """
    if turn_radii(curve).min() < min_turn_radius:
        return None
    if _dense_vertices(curve)[1] / SAMPLE_SPACING > MAX_TRACK_VERTICES:
        return None  # too long a track (only near the largest mean_radius)
    track = _smooth_track(curve, name)
    if track.min_turn_radius >= min_turn_radius and track.clearance(0.5) >= clearance:
        return track
    return None


@functools.lru_cache(maxsize=64)
def _seeded_random_track(seed: int) -> Track:
    """``random_track(seed)``, cached (drawing and checking a track is the costly part)."""
    return random_track(seed)


def make_track(name: str, seed: int | np.random.Generator | None = None) -> Track:
    """A built-in track by name.

    Args:
        name: one of :data:`TRACK_NAMES`.
        seed: for ``"random"`` only: an int ``>= 0`` (the track is cached), a generator, or
            None.

    Raises:
        TypeError: ``name`` is not a string, or (for ``"random"``) ``seed`` is neither an int,
            a generator nor None.
        ValueError: ``name`` is not one of :data:`TRACK_NAMES`, or ``seed`` is negative.
    """
    check_choice("name", name, TRACK_NAMES)
    if name == "random":
        if isinstance(seed, np.random.Generator):
            return random_track(seed)
        seed = check_int("seed", seed, 0, optional=True)
        return random_track() if seed is None else _seeded_random_track(seed)
    builders = {"oval": oval_track, "racetrack": racetrack_track, "figure8": figure8_track}
    return builders[name]()

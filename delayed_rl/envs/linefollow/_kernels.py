"""Compiled (numba) twins of the track queries and the camera reading, equal to the last bit.

The numpy code in :mod:`~delayed_rl.envs.linefollow.track` and
:mod:`~delayed_rl.envs.linefollow.camera` is the reference; the functions here compute the same
results element by element, with the same operations in the same order, and only with
operations IEEE 754 rounds the same on every CPU. Without numba they stay plain Python and the
callers use the numpy code. The rules they keep, and the tests: the docs' environments page
(``docs/envs.md``, "Its compiled pieces, equal to the last bit").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from delayed_rl._numba import HAVE_NUMBA, jit

__all__ = [
    "CameraArrays",
    "TrackArrays",
    "centroid",
    "distance",
    "enabled",
    "locate",
    "near_line",
    "observe",
    "pack_camera",
    "pack_track",
    "read_camera",
    "unpack_camera",
    "unpack_track",
]


class TrackArrays(NamedTuple):
    """A track's geometry and spatial grid, as the kernels read them (see ``Track``).

    Segment i runs from ``(a_re[i], a_im[i])`` by ``(d_re[i], d_im[i])``; the grid cell
    ``(ix, iy)`` has the key ``ix * ny + iy`` and holds the segments
    ``cell_segs[cell_starts[c]:cell_starts[c + 1]]`` where ``cell_keys[c]`` is that key
    (``cell_keys`` sorted; cells not listed hold none). A compiled function takes the two
    arrays of :func:`pack_track` (numba passes a few arrays far faster than a tuple) and
    unpacks them into this tuple of views with :func:`unpack_track`.
    """

    a_re: NDArray[np.float64]
    a_im: NDArray[np.float64]
    d_re: NDArray[np.float64]
    d_im: NDArray[np.float64]
    inv_len2: NDArray[np.float64]
    s0: NDArray[np.float64]
    seg_len: NDArray[np.float64]
    cell_keys: NDArray[np.int64]
    cell_starts: NDArray[np.int64]
    cell_segs: NDArray[np.int64]
    origin_x: float
    origin_y: float
    cell_size: float
    length: float
    nx: int
    ny: int
    window: int


class CameraArrays(NamedTuple):
    """A camera's geometry as the kernels read it (``Camera``'s, packed by :func:`pack_camera`)."""

    look_ahead: float
    half_width: float
    offsets: NDArray[np.float64]


#: Scalars heading a packed track's float array (origin x, y, cell size, length); then come
#: its seven per-segment arrays (a.real, a.imag, d.real, d.imag, inv_len2, s0, seg_len).
_FLOAT_HEADER = 4
#: Scalars heading its int array (n, nx, ny, window, K cells, M entries); then come
#: cell_keys (K), cell_starts (K + 1) and cell_segs (M).
_INT_HEADER = 6


def pack_track(
    a: NDArray[np.complex128],
    d: NDArray[np.complex128],
    inv_len2: NDArray[np.float64],
    s0: NDArray[np.float64],
    seg_len: NDArray[np.float64],
    cell_keys: NDArray[np.int64],
    cell_starts: NDArray[np.int64],
    cell_segs: NDArray[np.int64],
    origin: tuple[float, float],
    shape: tuple[int, int],
    cell_size: float,
    length: float,
    window: int,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """A track's geometry in one float64 and its grid in one int64 array (copies).

    The arrays stay writeable, as copies and unpickled arrays are: numba compiles a function
    anew for read-only arrays.

    Args:
        a: ``(n,)`` segment starts (x + iy).
        d: ``(n,)`` segment vectors.
        inv_len2: ``(n,)`` 1 / squared segment lengths.
        s0: ``(n,)`` arc length at each segment's start.
        seg_len: ``(n,)`` segment lengths.
        cell_keys: ``(K,)`` sorted keys of the grid's non-empty cells.
        cell_starts: ``(K + 1,)`` where each cell's segments start in ``cell_segs``.
        cell_segs: the segments registered in each cell, cell after cell.
        origin: the grid's lower-left corner (m).
        shape: the grid's ``(nx, ny)`` cells.
        cell_size: the grid's cell side (m).
        length: the track's length (m).
        window: segments either side of a hint that a hinted ``locate`` searches.
    """
    floats = np.concatenate(
        [[origin[0], origin[1], cell_size, length], a.real, a.imag, d.real, d.imag]
        + [inv_len2, s0, seg_len]
    )
    header = [len(a), shape[0], shape[1], window, len(cell_keys), len(cell_segs)]
    ints = np.concatenate([header, cell_keys, cell_starts, cell_segs]).astype(np.int64)
    return floats, ints


def pack_camera(
    look_ahead: float, half_width: float, offsets: NDArray[np.float64]
) -> NDArray[np.float64]:
    """A camera's geometry in one float64 array (see :class:`CameraArrays`, :func:`pack_track`)."""
    return np.concatenate([[look_ahead, half_width], offsets])


# ---------------------------------------------------------------------- arithmetic
@jit
def distance(x, y):
    """``sqrt(x·x + y·y)``: the length of (x, y), the same bits on every CPU (unlike ``hypot``)."""
    return math.sqrt(x * x + y * y)


# ---------------------------------------------------------------------- unpacking
@jit
def unpack_track(floats, ints):
    """The :class:`TrackArrays` views of :func:`pack_track`'s two arrays."""
    n, nx, ny, window, cells, entries = ints[0], ints[1], ints[2], ints[3], ints[4], ints[5]
    f, i = _FLOAT_HEADER, _INT_HEADER
    return TrackArrays(
        floats[f : f + n],
        floats[f + n : f + 2 * n],
        floats[f + 2 * n : f + 3 * n],
        floats[f + 3 * n : f + 4 * n],
        floats[f + 4 * n : f + 5 * n],
        floats[f + 5 * n : f + 6 * n],
        floats[f + 6 * n : f + 7 * n],
        ints[i : i + cells],
        ints[i + cells : i + 2 * cells + 1],
        ints[i + 2 * cells + 1 : i + 2 * cells + 1 + entries],
        floats[0],
        floats[1],
        floats[2],
        floats[3],
        nx,
        ny,
        window,
    )


@jit
def unpack_camera(packed):
    """The :class:`CameraArrays` view of :func:`pack_camera`'s array."""
    return CameraArrays(packed[0], packed[1], packed[2:])


# ---------------------------------------------------------------------- track queries
@jit
def _cell(x, y, track):
    """``(start, stop)`` of the segments registered in (x, y)'s grid cell (``Track._cell``)."""
    fx = (x - track.origin_x) // track.cell_size
    fy = (y - track.origin_y) // track.cell_size
    if not (0 <= fx < track.nx and 0 <= fy < track.ny):  # also refuses NaN
        return 0, 0
    key = int(fx) * track.ny + int(fy)
    c = np.searchsorted(track.cell_keys, key)
    if c == len(track.cell_keys) or track.cell_keys[c] != key:
        return 0, 0
    return track.cell_starts[c], track.cell_starts[c + 1]


@jit
def _offset_from_segment(zr, zi, seg, track):
    """``(t, er, ei)``: z's projection on segment ``seg`` (t in [0, 1]) and z minus it.

    Mirrors ``Track._nearest``'s numpy code for one segment: ``w = z − a``,
    ``t = clip((wr·dr + wi·di) · inv, 0, 1)`` (0 for −0.0 too; NaN stays), ``e = w − t·d``.
    """
    dr, di = track.d_re[seg], track.d_im[seg]
    wr, wi = zr - track.a_re[seg], zi - track.a_im[seg]
    t = (wr * dr + wi * di) * track.inv_len2[seg]
    if t <= 0.0:
        t = 0.0
    if t > 1.0:
        t = 1.0
    return t, wr - t * dr, wi - t * di


@jit
def _nearest(zr, zi, track, start, stop, mode):
    """The first nearest of candidate segments: ``(k, t, er, ei)`` as ``Track._nearest``.

    ``mode`` 0: segments ``start..stop - 1``; 1: the window of ``Track._pad_a[start:stop]``
    (segment ``(start + k - window) mod n``); 2: ``cell_segs[start:stop]``.
    """
    n = len(track.a_re)
    best, best_k = math.inf, -1
    best_t = best_er = best_ei = 0.0
    for k in range(stop - start):
        if mode == 0:
            seg = start + k
        elif mode == 1:
            seg = (start + k - track.window) % n
        else:
            seg = track.cell_segs[start + k]
        t, er, ei = _offset_from_segment(zr, zi, seg, track)
        dist2 = er * er + ei * ei
        if dist2 < best or best_k < 0:
            best, best_k, best_t, best_er, best_ei = dist2, k, t, er, ei
    return best_k, best_t, best_er, best_ei


@jit
def _locate(x, y, hint, track):
    """``Track.locate(x, y, hint)`` (``hint < 0`` for None): ``(s, lateral, segment)``."""
    n = len(track.a_re)
    seg = -1
    t = er = ei = 0.0
    if hint >= 0:
        k, t, er, ei = _nearest(x, y, track, hint, hint + 2 * track.window + 1, 1)
        if 0 < k < 2 * track.window and distance(er, ei) <= track.cell_size:
            seg = (hint + k - track.window) % n
    if seg < 0:
        start, stop = _cell(x, y, track)
        if start == stop:
            seg, t, er, ei = _nearest(x, y, track, 0, n, 0)
        else:
            k, t, er, ei = _nearest(x, y, track, start, stop, 2)
            seg = track.cell_segs[start + k]
    cross = track.d_re[seg] * ei - track.d_im[seg] * er
    length = distance(er, ei)
    lateral = length if cross > 0 else -length if cross < 0 else 0.0
    s = (track.s0[seg] + t * track.seg_len[seg]) % track.length
    return s, lateral, seg


@jit
def locate(x, y, hint, track_floats, track_ints):
    """``Track.locate(x, y, hint)`` on a packed track (``hint < 0`` for None)."""
    return _locate(x, y, hint, unpack_track(track_floats, track_ints))


@jit
def _within(px, py, seg, half_width, track):
    """Whether (px, py) is within ``half_width`` of segment ``seg``."""
    _, er, ei = _offset_from_segment(px, py, seg, track)
    return distance(er, ei) <= half_width


@jit
def near_line(xs, ys, half_width, centre_x, centre_y, track_floats, track_ints, out):
    """``Track.near_line`` of the points ``(xs[i], ys[i])`` on a packed track, into ``out``."""
    track = unpack_track(track_floats, track_ints)
    start, stop = _cell(centre_x, centre_y, track)
    for i in range(len(xs)):
        out[i] = False
        for k in range(start, stop):
            seg = track.cell_segs[k]
            if _within(xs[i], ys[i], seg, half_width, track):
                out[i] = True
                break


# ---------------------------------------------------------------------- camera
@jit
def _read_camera(x, y, cos_heading, sin_heading, camera, track, out):
    """``Camera.read`` into the bool array ``out``, given the heading's cosine and sine.

    The sample points mirror ``Camera._scanline``: the centre ``(x + look_ahead·cos,
    y + look_ahead·sin)``, then ``centre + offset · (−sin, cos)`` for each pixel. Each pixel is then decided
    as in ``Track.near_line``, but only against the segments that can reach it: a segment whose
    ends lie both more than ``half_width`` ahead of (or behind) the scanline, or whose extent
    along the scanline is more than ``half_width`` from a pixel's offset, is farther than
    ``half_width`` from that pixel. Those bounds are taken with a margin (1e-9 of the
    coordinates' scale, far above their rounding errors), so the pixels come out exactly as if
    every pair had been computed.
    """
    c, s, la = cos_heading, sin_heading, camera.look_ahead
    centre_x, centre_y = x + la * c, y + la * s
    left_x, left_y = -s, c
    offsets, half_width = camera.offsets, camera.half_width
    n = len(offsets)
    px, py = np.empty(n), np.empty(n)
    for i in range(n):
        px[i], py[i] = centre_x + offsets[i] * left_x, centre_y + offsets[i] * left_y
        out[i] = False
    reach = half_width + 1e-9 * (1.0 + abs(centre_x) + abs(centre_y))
    start, stop = _cell(centre_x, centre_y, track)
    for k in range(start, stop):
        seg = track.cell_segs[k]
        ax, ay = track.a_re[seg] - centre_x, track.a_im[seg] - centre_y
        bx, by = ax + track.d_re[seg], ay + track.d_im[seg]
        ahead_a, ahead_b = ax * c + ay * s, bx * c + by * s
        if min(ahead_a, ahead_b) > reach or max(ahead_a, ahead_b) < -reach:
            continue
        along_a, along_b = ax * left_x + ay * left_y, bx * left_x + by * left_y
        low, high = min(along_a, along_b) - reach, max(along_a, along_b) + reach
        for i in range(n):
            if not out[i] and low <= offsets[i] <= high:
                out[i] = _within(px[i], py[i], seg, half_width, track)


@jit
def read_camera(x, y, cos_heading, sin_heading, camera, track_floats, track_ints, out):
    """``Camera.read`` of a packed camera on a packed track, into the bool array ``out``."""
    track = unpack_track(track_floats, track_ints)
    camera_arrays = unpack_camera(camera)
    _read_camera(x, y, cos_heading, sin_heading, camera_arrays, track, out)


@jit
def centroid(pixels):
    """``line_centroid`` of one scanline of bools: m in 0..len(pixels)."""
    count = total = 0
    for i in range(len(pixels)):
        if pixels[i]:
            count += 1
            total += i + 1
    if count == 0:
        return 0
    return -((count - 2 * total) // (2 * count))


@jit
def observe(
    x,
    y,
    cos_heading,
    sin_heading,
    hint,
    line_contrast,
    camera_noise,
    camera,
    track_floats,
    track_ints,
    draws,
    out,
):
    """One env reading: the camera (with its noise) into ``out``, its centroid, the position.

    Takes the heading's cosine and sine, the hint of ``Track.locate`` (the previous segment),
    the env's noise and the packed camera and track. ``draws[0]`` and ``draws[1]`` are uniform draws for each pixel: a pixel over the
    line stays seen where ``draws[0] < line_contrast`` (applied when ``line_contrast < 1``),
    then flips where ``draws[1] < camera_noise`` (when ``camera_noise > 0``), as in the env's
    numpy code.

    Returns:
        ``(m, s, lateral, segment)``: ``line_centroid(out)`` and ``Track.locate(x, y, hint)``.
    """
    track = unpack_track(track_floats, track_ints)
    camera_arrays = unpack_camera(camera)
    _read_camera(x, y, cos_heading, sin_heading, camera_arrays, track, out)
    for i in range(len(out)):
        if line_contrast < 1:
            out[i] = out[i] and draws[0, i] < line_contrast
        if camera_noise > 0:
            out[i] = out[i] != (draws[1, i] < camera_noise)
    s, lateral, seg = _locate(x, y, hint, track)
    return centroid(out), s, lateral, seg


def enabled() -> bool:
    """Whether the compiled functions are in use: numba is installed."""
    return HAVE_NUMBA

"""Compiled (numba) twins of the track queries and the camera reading, equal to the last bit.

The numpy code in :mod:`~delayed_rl.envs.linefollow.track` and
:mod:`~delayed_rl.envs.linefollow.camera` is the reference; it spends most of an env step in
numpy's per-call overhead on arrays of a few dozen elements. The functions here compute the
same results element by element, with the same floating-point operations in the same order,
so their results are identical bit for bit, not merely close:

- complex products round like numpy's: on a CPU with FMA, numpy's SIMD loops compute
  Re(a·b) = fma(a.re, b.re, −a.im·b.im) and Im(a·b) = fma(a.re, b.im, a.im·b.re) (one rounding
  fewer than the textbook formula), elsewhere the textbook formula; :func:`_complex_product`
  does either;
- ``np.abs`` of a complex array rounds like numpy's (its SIMD loops compute
  ``larger · sqrt(fma(q, q, 1))``, ``q = smaller / larger``, not libm's ``hypot``), while
  Python's ``abs(complex)`` and ``math.hypot`` are libm's ``hypot``, as in numba;
- ``np.maximum(t, 0.0)`` turns −0.0 into 0.0 (its SIMD loops return the second operand of
  equal ones);
- Python's float ``//`` and ``%``, which numba mirrors (CPython's ``float_divmod``).

Which rounding numpy uses depends on the CPU and the numpy version, so :func:`numpy_rounding`
finds out once, by comparing numpy's results with each candidate on probe data; when none
matches (or numba is missing), :func:`enabled` is False and the callers keep the numpy code.
``tests/test_linefollow_kernels.py`` checks both paths against each other on random queries and
``tests/test_linefollow_trajectories.py`` checks whole trajectories against stored ones.

Without numba the functions stay plain Python (``_fma`` exact but slow); the callers then do
not use them.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from delayed_rl.fast._numba import HAVE_NUMBA, jit

__all__ = [
    "ABS_HYPOT",
    "ABS_SCALED",
    "ABS_SCALED_FUSED",
    "CameraArrays",
    "Rounding",
    "TrackArrays",
    "centroid",
    "enabled",
    "locate",
    "near_line",
    "numpy_rounding",
    "observe",
    "pack_camera",
    "pack_track",
    "read_camera",
    "unpack_camera",
    "unpack_track",
]

#: ``np.abs(complex)`` as libm's ``hypot``.
ABS_HYPOT = 0
#: ``np.abs(complex)`` as ``larger · sqrt(q·q + 1)`` (numpy's SIMD loop without FMA).
ABS_SCALED = 1
#: ``np.abs(complex)`` as ``larger · sqrt(fma(q, q, 1))`` (numpy's SIMD loop with FMA).
ABS_SCALED_FUSED = 2
_ABS_MODES = (ABS_HYPOT, ABS_SCALED, ABS_SCALED_FUSED)


class Rounding(NamedTuple):
    """How numpy rounds the two operations whose rounding varies between builds and CPUs."""

    #: Whether complex products use fused multiply-adds.
    fused_products: bool
    #: One of ``ABS_HYPOT``, ``ABS_SCALED``, ``ABS_SCALED_FUSED``.
    complex_abs: int


class TrackArrays(NamedTuple):
    """A track's geometry and spatial grid, as the kernels read them (see ``Track``).

    Segment i runs from ``(a_re[i], a_im[i])`` by ``(d_re[i], d_im[i])``; the grid cell
    ``(ix, iy)`` has the key ``ix * ny + iy`` and holds the segments
    ``cell_segs[cell_starts[c]:cell_starts[c + 1]]`` where ``cell_keys[c]`` is that key
    (``cell_keys`` sorted; cells not listed hold none). A compiled function takes the two
    buffers of :func:`pack_track` (numba passes a few arrays far faster than a tuple) and
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


#: Scalars heading a packed track's float buffer (origin x, y, cell size, length); then come
#: its seven per-segment arrays (a.real, a.imag, d.real, d.imag, inv_len2, s0, seg_len).
_FLOAT_HEADER = 4
#: Scalars heading its int buffer (n, nx, ny, window, K cells, M entries); then come
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
    """A track's geometry in one float64 and its grid in one int64 buffer (copies).

    The buffers stay writeable, as copies and unpickled arrays are: numba compiles a function
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
    """A camera's geometry in one float64 buffer (see :class:`CameraArrays`, :func:`pack_track`)."""
    return np.concatenate([[look_ahead, half_width], offsets])


# ---------------------------------------------------------------------- arithmetic
if HAVE_NUMBA:
    from numba import types
    from numba.core.extending import intrinsic

    @intrinsic
    def _fma(typingctx, a, b, c):
        """a·b + c rounded once (LLVM's ``llvm.fma``: the CPU's FMA, else libm's ``fma``)."""
        if not all(isinstance(x, types.Float) for x in (a, b, c)):
            return None
        sig = types.float64(types.float64, types.float64, types.float64)

        def codegen(context, builder, signature, args):
            cast = [
                context.cast(builder, v, t, types.float64)
                for v, t in zip(args, (a, b, c), strict=True)
            ]
            return builder.fma(*cast)

        return sig, codegen

else:  # pragma: no cover - exercised where numba is absent

    def _fma(a: float, b: float, c: float) -> float:
        """a·b + c rounded once, exactly (``math.fma`` needs Python 3.13)."""
        return float(Fraction(a) * Fraction(b) + Fraction(c))


@jit
def _complex_product(ar, ai, br, bi, fused):
    """(ar + i·ai)·(br + i·bi) rounded as numpy rounds it; ``fused``: with FMA."""
    if fused:
        return _fma(ar, br, -(ai * bi)), _fma(ar, bi, ai * br)
    return ar * br - ai * bi, ar * bi + ai * br


@jit
def _complex_abs(re, im, mode):
    """``np.abs(re + i·im)`` rounded as numpy rounds it (``mode``: one of the ``ABS_*``)."""
    if mode == ABS_HYPOT:
        return math.hypot(re, im)
    re, im = abs(re), abs(im)
    if math.isinf(re) or math.isinf(im):
        return math.inf
    if math.isnan(re) or math.isnan(im):
        return math.nan
    larger, smaller = max(re, im), min(re, im)
    if larger == 0.0:
        return 0.0
    q = smaller / larger
    if mode == ABS_SCALED_FUSED:
        return math.sqrt(_fma(q, q, 1.0)) * larger
    return math.sqrt(q * q + 1.0) * larger


# ---------------------------------------------------------------------- unpacking
@jit
def unpack_track(floats, ints):
    """The :class:`TrackArrays` views of :func:`pack_track`'s two buffers."""
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
    """The :class:`CameraArrays` view of :func:`pack_camera`'s buffer."""
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
def _offset_from_segment(zr, zi, seg, track, fused):
    """``(t, er, ei)``: z's projection on segment ``seg`` (t in [0, 1]) and z minus it.

    Mirrors ``Track._nearest``'s numpy code for one segment: ``w = z − a``,
    ``t = clip(Re(w · conj(d)) · inv, 0, 1)``, ``w −= t · d``.
    """
    dr, di = track.d_re[seg], track.d_im[seg]
    wr, wi = zr - track.a_re[seg], zi - track.a_im[seg]
    dot = _complex_product(wr, wi, dr, -di, fused)[0]
    t = dot * track.inv_len2[seg]
    if t <= 0.0:  # np.maximum(t, 0.0): 0.0 for -0.0 too (numpy_rounding checks), NaN stays
        t = 0.0
    if t > 1.0:
        t = 1.0
    pr, pi = _complex_product(t, 0.0, dr, di, fused)
    return t, wr - pr, wi - pi


@jit
def _nearest(zr, zi, track, fused, start, stop, mode):
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
        t, er, ei = _offset_from_segment(zr, zi, seg, track, fused)
        dist2 = er * er + ei * ei
        if dist2 < best or best_k < 0:
            best, best_k, best_t, best_er, best_ei = dist2, k, t, er, ei
    return best_k, best_t, best_er, best_ei


@jit
def _locate(x, y, hint, track, fused):
    """``Track.locate(x, y, hint)`` (``hint < 0`` for None): ``(s, lateral, segment)``."""
    n = len(track.a_re)
    seg = -1
    t = er = ei = 0.0
    if hint >= 0:
        k, t, er, ei = _nearest(x, y, track, fused, hint, hint + 2 * track.window + 1, 1)
        if 0 < k < 2 * track.window and math.hypot(er, ei) <= track.cell_size:
            seg = (hint + k - track.window) % n
    if seg < 0:
        start, stop = _cell(x, y, track)
        if start == stop:
            seg, t, er, ei = _nearest(x, y, track, fused, 0, n, 0)
        else:
            k, t, er, ei = _nearest(x, y, track, fused, start, stop, 2)
            seg = track.cell_segs[start + k]
    cross = track.d_re[seg] * ei - track.d_im[seg] * er
    distance = math.hypot(er, ei)
    lateral = distance if cross > 0 else -distance if cross < 0 else 0.0
    s = (track.s0[seg] + t * track.seg_len[seg]) % track.length
    return s, lateral, seg


@jit
def locate(x, y, hint, track_floats, track_ints, fused):
    """``Track.locate(x, y, hint)`` on a packed track (``hint < 0`` for None)."""
    return _locate(x, y, hint, unpack_track(track_floats, track_ints), fused)


@jit
def _within(px, py, seg, half_width, track, fused, complex_abs):
    """Whether (px, py) is within ``half_width`` of segment ``seg``, rounded as numpy does."""
    _, er, ei = _offset_from_segment(px, py, seg, track, fused)
    return _complex_abs(er, ei, complex_abs) <= half_width


@jit
def near_line(
    points, half_width, centre_x, centre_y, track_floats, track_ints, fused, complex_abs, out
):
    """``Track.near_line(points, half_width, centre)`` on a packed track, into ``out``."""
    track = unpack_track(track_floats, track_ints)
    start, stop = _cell(centre_x, centre_y, track)
    for i in range(len(points)):
        p = points[i]
        out[i] = False
        for k in range(start, stop):
            seg = track.cell_segs[k]
            if _within(p.real, p.imag, seg, half_width, track, fused, complex_abs):
                out[i] = True
                break


# ---------------------------------------------------------------------- camera
@jit
def _read_camera(x, y, cos_heading, sin_heading, camera, track, fused, complex_abs, out):
    """``Camera.read`` into the bool array ``out``, given the heading's cosine and sine.

    The sample points mirror ``Camera._scanline``: ``forward = complex(cos, sin)``,
    ``centre = complex(x, y) + look_ahead · forward`` and ``left = 1j · forward`` in Python's
    complex arithmetic, then ``centre + offsets · left`` in numpy's. Each pixel is then decided
    as in ``Track.near_line``, but only against the segments that can reach it: a segment whose
    ends lie both more than ``half_width`` ahead of (or behind) the scanline, or whose extent
    along the scanline is more than ``half_width`` from a pixel's offset, is farther than
    ``half_width`` from that pixel. Those bounds are taken with a margin (1e-9 of the
    coordinates' scale, far above their rounding errors), so the pixels come out exactly as if
    every pair had been computed.
    """
    c, s, la = cos_heading, sin_heading, camera.look_ahead
    centre_x = x + (la * c - 0.0 * s)
    centre_y = y + (la * s + 0.0 * c)
    left_x, left_y = 0.0 * c - 1.0 * s, 0.0 * s + 1.0 * c
    offsets, half_width = camera.offsets, camera.half_width
    n = len(offsets)
    px, py = np.empty(n), np.empty(n)
    for i in range(n):
        dx, dy = _complex_product(offsets[i], 0.0, left_x, left_y, fused)
        px[i], py[i] = centre_x + dx, centre_y + dy
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
                out[i] = _within(px[i], py[i], seg, half_width, track, fused, complex_abs)


@jit
def read_camera(
    x, y, cos_heading, sin_heading, camera, track_floats, track_ints, fused, complex_abs, out
):
    """``Camera.read`` of a packed camera on a packed track, into the bool array ``out``."""
    track = unpack_track(track_floats, track_ints)
    camera_arrays = unpack_camera(camera)
    _read_camera(x, y, cos_heading, sin_heading, camera_arrays, track, fused, complex_abs, out)


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
    fused,
    complex_abs,
    draws,
    out,
):
    """One env reading: the camera (with its noise) into ``out``, its centroid, the position.

    Takes the heading's cosine and sine, the hint of ``Track.locate`` (the previous segment),
    the env's noise, the packed camera and track and numpy's rounding (:class:`Rounding`,
    unpacked). ``draws[0]`` and ``draws[1]`` are uniform draws for each pixel: a pixel over the
    line stays seen where ``draws[0] < line_contrast`` (applied when ``line_contrast < 1``),
    then flips where ``draws[1] < camera_noise`` (when ``camera_noise > 0``), as in the env's
    numpy code.

    Returns:
        ``(m, s, lateral, segment)``: ``line_centroid(out)`` and ``Track.locate(x, y, hint)``.
    """
    track = unpack_track(track_floats, track_ints)
    camera_arrays = unpack_camera(camera)
    _read_camera(x, y, cos_heading, sin_heading, camera_arrays, track, fused, complex_abs, out)
    for i in range(len(out)):
        if line_contrast < 1:
            out[i] = out[i] and draws[0, i] < line_contrast
        if camera_noise > 0:
            out[i] = out[i] != (draws[1, i] < camera_noise)
    s, lateral, seg = _locate(x, y, hint, track, fused)
    return centroid(out), s, lateral, seg


# ---------------------------------------------------------------------- numpy's rounding
@jit
def _products(a, b, fused, out):
    """Elementwise ``a * b`` of complex arrays with :func:`_complex_product`, into ``out``."""
    for i in range(len(a)):
        re, im = _complex_product(a[i].real, a[i].imag, b[i].real, b[i].imag, fused)
        out[i] = complex(re, im)


@jit
def _absolutes(z, mode, out):
    """Elementwise ``np.abs(z)`` of a complex array with :func:`_complex_abs`, into ``out``."""
    for i in range(len(z)):
        out[i] = _complex_abs(z[i].real, z[i].imag, mode)


def _same_bits(x: NDArray, y: NDArray) -> bool:
    return x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == y.tobytes()


def _probe_data() -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """Complex values of the kernels' sizes: offsets of a few cm, segment steps of a few mm.

    The first few are exact zeros and equal parts (the special cases of ``np.abs``).
    """
    rng = np.random.default_rng(20240611)
    a = (rng.normal(size=96) + 1j * rng.normal(size=96)) * 0.02
    b = (rng.normal(size=96) + 1j * rng.normal(size=96)) * 0.004
    a[:4] = [0.0, 0.003, 0.003j, 0.002 + 0.002j]
    return a, b


def _products_as_numpy(fused: bool) -> bool:
    """Whether :func:`_complex_product` with ``fused`` gives numpy's products bit for bit.

    Tried in the layouts of the reference code: 1-D arrays of 1 to 96 elements, an array times
    a complex scalar, a float array times a complex scalar and a ``(40, k)`` array times a
    broadcast ``(k,)`` row.
    """
    a, b = _probe_data()
    grid = a[:40, None] - b[None, :27]
    cases = [(a[:n], b[:n], a[:n] * b[:n]) for n in (1, 2, 3, 5, 8, 41, 96)]
    cases.append((a, np.full_like(b, b[0]), a * b[0]))
    cases.append((a.real.astype(np.complex128), np.full_like(b, b[1]), a.real * complex(b[1])))
    rows = np.broadcast_to(b[:27], grid.shape)
    cases.append((grid.ravel(), rows.ravel(), (grid * b[:27]).ravel()))
    for x, y, expected in cases:
        ours = np.empty_like(expected)
        _products(np.ascontiguousarray(x), np.ascontiguousarray(y), fused, ours)
        if not _same_bits(ours, expected):
            return False
    return True


def _absolutes_as_numpy(mode: int) -> bool:
    """Whether :func:`_complex_abs` in ``mode`` gives numpy's ``np.abs`` bit for bit.

    Tried on 1-D arrays of 1 to 96 elements and on a ``(40, k)`` array.
    """
    a, b = _probe_data()
    cases = [a[:n] for n in (1, 3, 8, 41, 96)]
    cases.append(a[:40, None] - b[None, :27])
    for z in cases:
        ours = np.empty(z.size)
        _absolutes(z.ravel(), mode, ours)
        if not _same_bits(ours, np.abs(z).ravel()):
            return False
    return True


@functools.cache
def numpy_rounding() -> Rounding | None:
    """How this numpy rounds complex products and absolute values, or None if unrecognised.

    numpy's results are compared bit for bit with each candidate's on probe data (and its
    ``np.maximum(-0.0, 0.0)`` must be 0.0); None (numba is missing, or numpy does something
    else) means the compiled functions must not be used. The answer is cached.
    """
    if not HAVE_NUMBA or np.signbit(np.maximum(np.full(3, -0.0), 0.0)).any():
        return None
    fused = next((f for f in (True, False) if _products_as_numpy(f)), None)
    complex_abs = next((m for m in _ABS_MODES if _absolutes_as_numpy(m)), None)
    if fused is None or complex_abs is None:
        return None
    return Rounding(fused, complex_abs)


def enabled() -> bool:
    """Whether the compiled functions are in use: numba is installed and mirrors numpy."""
    return numpy_rounding() is not None

"""The e-puck's 1×40 line camera and the line-centroid state (thesis Eq. 5.6).

:class:`Camera` reads 40 binary pixels on a scanline ``LOOK_AHEAD`` ahead of the robot, pixel 1
on its left, each seeing the line within half its width; :func:`line_centroid` turns them into
the state m, the centroid rounded half-down (0 when no pixel sees the line). The geometry, the
rounding and where it departs from the thesis's printed Eq. 5.6: the docs' environments page
(``docs/envs.md``, "The camera and the line-centroid state"). :meth:`Camera.read` runs
compiled where numba is installed (:mod:`~delayed_rl.envs.linefollow._kernels`), to the same
pixels.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from delayed_rl import _portable_math as portable_math
from delayed_rl._validation import check_real
from delayed_rl.envs.linefollow import _kernels
from delayed_rl.envs.linefollow.track import CELL_SIZE, Track

__all__ = [
    "CENTRE_PIXEL",
    "FIELD_WIDTH",
    "LINE_WIDTH",
    "LOOK_AHEAD",
    "N_PIXELS",
    "Camera",
    "line_centroid",
]

#: Pixels on the scanline.
N_PIXELS = 40
#: p_centre of Eq. 5.7: the state of a centred line.
CENTRE_PIXEL = 20
#: Distance (m) from the body centre to the scanline.
LOOK_AHEAD = 0.05
#: Width (m) of the floor the scanline covers.
FIELD_WIDTH = 0.064
#: Width (m) of the line (black tape).
LINE_WIDTH = 0.010

_INDICES = np.arange(1, N_PIXELS + 1)


def line_centroid(pixels: ArrayLike) -> int | NDArray[np.int64]:
    """The line-centroid state m of thesis Eq. 5.6, rounded half-down; 0 when nothing is seen.

    Args:
        pixels: ``(..., 40)`` pixel values; nonzero means "sees the line".

    Returns:
        m in 0..40: an int for one scanline, an int64 array for a batch.

    Example:
        >>> line_centroid([0] * 17 + [1] * 6 + [0] * 17)  # pixels 18–23 → 20.5 → 20
        20
    """
    seen = np.asarray(pixels) != 0
    if seen.ndim == 0 or seen.shape[-1] != N_PIXELS:
        raise ValueError(f"pixels must have {N_PIXELS} values on the last axis, got {seen.shape}")
    if seen.ndim == 1:  # the env's per-step path: Python integers
        count = int(np.count_nonzero(seen))
        return _round_half_down(int(_INDICES[seen].sum()), count) if count else 0
    count = seen.sum(axis=-1)
    m = _round_half_down((seen * _INDICES).sum(axis=-1), np.maximum(count, 1))
    return np.where(count > 0, m, 0).astype(np.int64)


def _round_half_down(total: Any, count: Any) -> Any:
    """Total / count rounded to the nearest integer, ties down, in exact integer arithmetic.

    That is ``ceil((2·total − count) / (2·count))``, for ints or integer arrays.
    """
    return -((count - 2 * total) // (2 * count))


class Camera:
    """A downward-looking scanline of 40 binary pixels (``docs/envs.md`` draws the layout).

    Args:
        look_ahead: distance (m) from the body centre to the scanline.
        field_width: width (m) of floor the scanline covers.
        line_width: width (m) of the line on the floor.

    Raises:
        TypeError: an argument is not a number.
        ValueError: an argument is not finite and positive, or the scanline reaches further
            sideways (``field_width / 2 + line_width / 2``) than the track index answers for
            (``CELL_SIZE``, 0.04 m).

    A camera is immutable (its geometry is read-only; make a new camera for another one).
    """

    def __init__(
        self,
        look_ahead: float = LOOK_AHEAD,
        field_width: float = FIELD_WIDTH,
        line_width: float = LINE_WIDTH,
    ):
        look_ahead = check_real("look_ahead", look_ahead, 0.0, low_open=True, note=" (m)")
        field_width = check_real("field_width", field_width, 0.0, low_open=True, note=" (m)")
        line_width = check_real("line_width", line_width, 0.0, low_open=True, note=" (m)")
        reach = field_width / 2 + line_width / 2
        if reach > CELL_SIZE:
            raise ValueError(
                f"field_width / 2 + line_width / 2 must be <= {CELL_SIZE} m (the track index's "
                f"reach), got {reach}"
            )
        self._look_ahead, self._field_width, self._line_width = look_ahead, field_width, line_width
        #: Width (m) of one pixel's footprint.
        self.pixel_width = field_width / N_PIXELS
        #: Lateral offset (m, positive to the robot's left) of each pixel's sample point.
        self.offsets = ((N_PIXELS + 1) / 2 - _INDICES) * self.pixel_width
        self.offsets.setflags(write=False)
        # The geometry as the compiled reading (and the env) takes it.
        self._packed = _kernels.pack_camera(look_ahead, 0.5 * line_width, self.offsets)

    @property
    def look_ahead(self) -> float:
        """Distance (m) from the body centre to the scanline."""
        return self._look_ahead

    @property
    def field_width(self) -> float:
        """Width (m) of floor the scanline covers."""
        return self._field_width

    @property
    def line_width(self) -> float:
        """Width (m) of the line on the floor."""
        return self._line_width

    def _scanline(
        self, x: float, y: float, heading: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
        """``(xs, ys, cx, cy)``: the sample points' coordinates and the scanline's centre.

        The centre is ``look_ahead`` ahead, ``(x + look_ahead·cos, y + look_ahead·sin)``, and
        pixel i is ``offsets[i]`` to its left, along ``(−sin, cos)``; the heading's sine and
        cosine are ``delayed_rl._portable_math.sincos``'s (the same bits on every CPU).
        """
        sin, cos = portable_math.sincos(float(heading))
        cx, cy = float(x) + self.look_ahead * cos, float(y) + self.look_ahead * sin
        return cx + self.offsets * -sin, cy + self.offsets * cos, cx, cy

    def sample_points(self, x: float, y: float, heading: float) -> NDArray[np.float64]:
        """World coordinates ``(40, 2)`` of the pixels' sample points for a robot pose."""
        xs, ys, _, _ = self._scanline(x, y, heading)
        return np.column_stack([xs, ys])

    def read(self, track: Track, x: float, y: float, heading: float) -> NDArray[np.bool_]:
        """Which of the 40 pixels see the line, for a robot at (x, y) facing ``heading`` (rad)."""
        if not _kernels.enabled():
            return self._read_numpy(track, x, y, heading)
        out = np.empty(N_PIXELS, dtype=bool)
        sin, cos = portable_math.sincos(float(heading))
        _kernels.read_camera(float(x), float(y), cos, sin, self._packed, *track._packed, out)
        return out

    def _read_numpy(self, track: Track, x: float, y: float, heading: float) -> NDArray[np.bool_]:
        """:meth:`read` in numpy: the reference the compiled version mirrors."""
        xs, ys, cx, cy = self._scanline(x, y, heading)
        return track._near_line_numpy(xs, ys, 0.5 * self.line_width, cx, cy)

    def __repr__(self) -> str:
        return (
            f"Camera(look_ahead={self.look_ahead}, field_width={self.field_width}, "
            f"line_width={self.line_width})"
        )

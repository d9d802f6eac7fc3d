"""Drawing the line-following scene: with numpy (``rgb_array``), shown with pygame (``human``).

pygame is imported only when a window is first shown, so ``rgb_array`` rendering needs numpy
alone.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from delayed_rl import _portable_math as portable_math
from delayed_rl._validation import check_int
from delayed_rl.envs.linefollow.camera import Camera
from delayed_rl.envs.linefollow.robot import BODY_RADIUS
from delayed_rl.envs.linefollow.track import Track

__all__ = ["Renderer"]

FLOOR = (236, 234, 226)
LINE = (25, 25, 25)
TRAIL = (70, 130, 220)
ROBOT = (200, 70, 60)
ROBOT_EDGE = (120, 30, 25)
PIXEL_ON = (40, 200, 70)
PIXEL_OFF = (250, 190, 40)
CAMERA_FLOOR = (255, 255, 255)
MARGIN = 0.12  # metres of floor around the track


class Renderer:
    """Draws the track, the robot, its trail and its camera scanline, and the camera's view.

    The scanline is drawn on the floor, green where a pixel sees the line and amber where not;
    the camera's view is magnified in the top-left corner.

    Args:
        track: the track to draw (drawn once, then reused).
        camera: the robot's camera (for the scanline).
        size: the longer side of the image (pixels), an integer ``>= 1``.

    Raises:
        TypeError: ``size`` is not an integer.
        ValueError: ``size`` is below 1.
    """

    def __init__(self, track: Track, camera: Camera, size: int = 640):
        size = check_int("size", size, 1)
        self.track = track
        self.camera = camera
        low, high = track.bounds
        self._origin = (float(low[0]) - MARGIN, float(high[1]) + MARGIN)  # top-left, in metres
        span = (high - low) + 2 * MARGIN
        self.scale = size / float(span.max())  # pixels per metre
        self.width = int(np.ceil(span[0] * self.scale))
        self.height = int(np.ceil(span[1] * self.scale))
        self._background = np.empty((self.height, self.width, 3), dtype=np.uint8)
        self._background[:] = FLOOR
        line_radius = max(1.5, 0.5 * camera.line_width * self.scale)
        self._stamp(self._background, track.points, line_radius, LINE)
        self._window: Any = None
        self._clock: Any = None

    def _to_pixels(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """World (x, y) metres → image (column, row), y up → rows down."""
        return np.column_stack(
            [
                (points[:, 0] - self._origin[0]) * self.scale,
                (self._origin[1] - points[:, 1]) * self.scale,
            ]
        )

    def _stamp(
        self, image: NDArray[np.uint8], points: NDArray[np.float64], radius: float, colour: tuple
    ) -> None:
        """Paint a filled disc of ``radius`` pixels at every world point."""
        if len(points) == 0:
            return
        centre = self._to_pixels(points)
        r = int(np.ceil(radius))
        dx, dy = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1))
        inside = dx**2 + dy**2 <= radius**2
        dx, dy = dx[inside], dy[inside]
        cols = (np.rint(centre[:, 0])[:, None] + dx).astype(np.int64).ravel()
        rows = (np.rint(centre[:, 1])[:, None] + dy).astype(np.int64).ravel()
        ok = (cols >= 0) & (cols < self.width) & (rows >= 0) & (rows < self.height)
        image[rows[ok], cols[ok]] = colour

    def draw(
        self,
        pose: tuple[float, float, float],
        pixels: NDArray[np.bool_],
        trail: Iterable[tuple[float, float]],
    ) -> NDArray[np.uint8]:
        """An ``(height, width, 3)`` uint8 frame of the scene.

        Args:
            pose: the robot's ``(x, y, heading)``.
            pixels: the camera's 40 readings (drawn green where the line is seen).
            trail: past robot positions.
        """
        frame = self._background.copy()
        trail_points = np.asarray(list(trail), dtype=np.float64).reshape(-1, 2)
        self._stamp(frame, trail_points, 1.0, TRAIL)
        x, y, heading = pose
        body = np.array([[x, y]])
        self._stamp(frame, body, BODY_RADIUS * self.scale, ROBOT_EDGE)
        self._stamp(frame, body, BODY_RADIUS * self.scale - 1.5, ROBOT)
        nose = np.linspace(0.0, 0.8 * BODY_RADIUS, 8)
        sin, cos = portable_math.sincos(float(heading))
        direction = np.array([cos, sin])
        self._stamp(frame, body + nose[:, None] * direction, 1.2, ROBOT_EDGE)
        samples = self.camera.sample_points(x, y, heading)
        seen = np.asarray(pixels, dtype=bool)
        self._stamp(frame, samples[~seen], 1.0, PIXEL_OFF)
        self._stamp(frame, samples[seen], 1.0, PIXEL_ON)
        self._draw_camera_view(frame, seen)
        return frame

    @staticmethod
    def _draw_camera_view(frame: NDArray[np.uint8], seen: NDArray[np.bool_]) -> None:
        """Draw the 40 pixels as the robot sees them, magnified in the top-left corner.

        Pixel 1 is on the left and a pixel is dark where it sees the line (like thesis Fig. 5.17).
        """
        cell, height, x0, y0 = 6, 14, 8, 8
        width = cell * len(seen)
        if frame.shape[0] < y0 + height + 2 or frame.shape[1] < x0 + width + 2:
            return
        frame[y0 - 1 : y0 + height + 1, x0 - 1 : x0 + width + 1] = ROBOT_EDGE
        strip = np.where(seen[:, None], np.array(LINE), np.array(CAMERA_FLOOR))
        frame[y0 : y0 + height, x0 : x0 + width] = np.repeat(strip, cell, axis=0)[None, :, :]

    def show(self, frame: NDArray[np.uint8], fps: float) -> None:
        """Show a frame in a pygame window (opened on first use), at most ``fps`` per second."""
        import pygame  # the ``render`` extra; imported only for human rendering

        if self._window is None:
            pygame.display.init()
            pygame.display.set_caption("delayed_rl EPuckLineFollow")
            self._window = pygame.display.set_mode((self.width, self.height))
            self._clock = pygame.time.Clock()
        pygame.event.pump()
        surface = pygame.surfarray.make_surface(np.ascontiguousarray(frame.transpose(1, 0, 2)))
        self._window.blit(surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(fps)

    def close(self) -> None:
        """Close the window, if one is open."""
        if self._window is not None:
            import pygame

            pygame.display.quit()
            self._window = None
            self._clock = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_window"] = state["_clock"] = None  # pygame objects do not pickle
        return state

"""The e-puck line-following task (thesis section 5.2): track, robot, camera, env, rendering.

See :class:`~delayed_rl.envs.linefollow.env.EPuckLineFollowEnv` for the env's documentation.
"""

from delayed_rl.envs.linefollow.camera import Camera, line_centroid
from delayed_rl.envs.linefollow.env import WHEEL_SPEED_ACTIONS, EPuckLineFollowEnv
from delayed_rl.envs.linefollow.track import TRACK_NAMES, Track, make_track, random_track

__all__ = [
    "TRACK_NAMES",
    "WHEEL_SPEED_ACTIONS",
    "Camera",
    "EPuckLineFollowEnv",
    "Track",
    "line_centroid",
    "make_track",
    "random_track",
]

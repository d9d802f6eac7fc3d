"""The e-puck line follower inside the compiled training loop.

:func:`robot_step` is :meth:`~delayed_rl.envs.linefollow.EPuckLineFollowEnv.step` compiled, to the last bit (the same C
calls, arithmetic and random draws from the env's own ``np_random``), so that
:func:`~delayed_rl.compiled.kernel.run_chunk` steps the robot itself and a whole training chunk
runs without returning to Python; :class:`RobotLink` joins an env to a run, or says why it
cannot. What compiles, what goes back to Python and what the env holds between chunks: the
docs' compiled-path page (``docs/compiled.md``, "The e-puck line follower").
"""

from __future__ import annotations

import contextlib
import itertools
import warnings
from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np

from delayed_rl import _portable_math as portable_math
from delayed_rl._numba import HAVE_NUMBA
from delayed_rl._numba import jit as _jit
from delayed_rl.compiled.tabular import NotCompilable
from delayed_rl.envs.linefollow import _chipmunk, _kernels
from delayed_rl.envs.linefollow.camera import CENTRE_PIXEL, line_centroid
from delayed_rl.envs.linefollow.env import MAX_WHEEL_SPEED, WHEEL_SPEED_ACTIONS, EPuckLineFollowEnv
from delayed_rl.envs.linefollow.robot import AXLE_LENGTH, METRES_PER_STEP

__all__ = ["Robot", "RobotLink", "linked", "robot_reset", "robot_step"]

if HAVE_NUMBA:
    from numba import objmode
    from numba.core.errors import NumbaWarning

    # numba notes that the object-mode blocks below take the GIL, which the library's ``nogil``
    # compiled loop releases: true, and meant (they run at rare events only), so not shown
    warnings.filterwarnings(
        "ignore",
        message="Code running in object mode won't allow parallel execution",
        category=NumbaWarning,
        module=r".*delayed_rl[/\\]fast[/\\]",
    )
else:  # pragma: no cover - without numba the functions below run as Python, for reading

    def objmode(**types: str) -> contextlib.AbstractContextManager:
        """Stand in for numba's object-mode block where numba is missing: plain Python."""
        return contextlib.nullcontext()


# the layout of Robot.reals, Robot.ints, Robot.live and Robot.counters
_SLIP, _CONTRAST, _NOISE, _GAIN, _DT, _LENGTH = range(6)
_SUBSTEPS, _LOST_STEPS, _TERMINATE, _MAX_STEPS, _LAGGED, _KEY = range(6)
_ARC, _LATERAL, _PROGRESS, _LEFT, _RIGHT = range(5)
_SEGMENT, _LOST, _STEPS = range(3)


class Robot(NamedTuple):
    """The e-puck env as :func:`~delayed_rl.compiled.kernel.run_chunk` steps it.

    Attributes:
        handles: the Chipmunk functions and objects of the env's robot
            (:func:`~delayed_rl.envs.linefollow._chipmunk.handles`), rewritten when a recovery
            or a reset rebuilds its space.
        speeds: the (left, right) wheel speeds (steps/s) of each discrete action.
        reals: wheel slip, line contrast, camera noise, the motor lag's gain, the physics
            sub-step (s) and the track's length (m).
        ints: physics sub-steps a step, line-less steps before the line counts as lost,
            whether losing it terminates (else the robot is put back), ``max_steps`` (0: none),
            whether the motor lags, and the env's key in the link's registry.
        live: the arc position (m), lateral error (m), lap progress, and the (lagged) left and
            right wheel speeds: the env's state, updated step by step.
        counters: the track segment (the next position's search hint), the line-less steps so
            far and the episode's steps.
        camera: the camera's packed geometry.
        track_floats: the track's packed geometry.
        track_ints: the track's packed grid.
        draws: the env's per-pixel uniform draws of a reading (contrast, then noise).
        pixels: the env's last camera reading.
        generator: the env's ``np_random``.
    """

    handles: np.ndarray
    speeds: np.ndarray
    reals: np.ndarray
    ints: np.ndarray
    live: np.ndarray
    counters: np.ndarray
    camera: np.ndarray
    track_floats: np.ndarray
    track_ints: np.ndarray
    draws: np.ndarray
    pixels: np.ndarray
    generator: np.random.Generator


_LINKED: dict[int, EPuckLineFollowEnv] = {}
"""The envs of the chunks running now, by key: the Python half of a recovery or reset finds its
env here."""
_KEYS = itertools.count(1)


class RobotLink:
    """Hands an :class:`EPuckLineFollowEnv` to compiled runs, and its state back after each.

    Args:
        env: the unwrapped env.

    Raises:
        NotCompilable: the env's configuration does not compile (the message says which
            argument, and what would).
    """

    def __init__(self, env: EPuckLineFollowEnv):
        reasons = [
            ("observation_mode", env.observation_mode != "centroid", "'centroid'"),
            ("action_mode", env.action_mode != "discrete", "'discrete'"),
            ("command_latency", env.latency_substeps > 0, "0"),
            ("track", env._random_tracks, "a fixed track or a track_seed"),
            ("render_mode", env.render_mode is not None, "None"),
        ]
        for name, refused, allowed in reasons:
            if refused:
                raise NotCompilable(
                    f"EPuckLineFollowEnv with {name}={getattr(env, name)!r} does not compile "
                    f"(it does with {allowed})"
                )
        _compiled_reading(env)
        self.env = env

    def observation(self) -> int:
        """The env's current state: the centroid of its last camera reading."""
        return line_centroid(self.env._pixels)

    @contextlib.contextmanager
    def arguments(self) -> Iterator[Robot]:
        """The :class:`Robot` of the env's current state, for one compiled call.

        The env is reachable by its key during the call; on leaving, its state is the run's.
        """
        env = self.env
        # (checked each call: an env unpickled on another machine may not have them)
        camera, track_floats, track_ints, draws, pixels = _compiled_reading(env)
        key = next(_KEYS)
        live, counters = np.zeros(5), np.zeros(3, np.int64)
        _load(env, live, counters)
        robot = Robot(
            env.robot._driver[1].copy(),
            np.array(WHEEL_SPEED_ACTIONS, dtype=np.float64),
            np.array(
                [
                    env.wheel_slip,
                    env.line_contrast,
                    env.camera_noise,
                    env.robot._lag_gain,
                    env.robot.physics_dt,
                    env.track.length,
                ]
            ),
            np.array(
                [
                    env.physics_substeps,
                    env.lost_line_steps,
                    env.lost_line == "terminate",
                    env.max_steps or 0,
                    env.robot.motor_lag > 0,
                    key,
                ],
                dtype=np.int64,
            ),
            live,
            counters,
            camera,
            track_floats,
            track_ints,
            draws,
            pixels,
            env.np_random,
        )
        _LINKED[key] = env
        try:
            yield robot
        finally:
            del _LINKED[key]
            _store(env, live, counters)


def _compiled_reading(env: EPuckLineFollowEnv) -> tuple:
    """The env's compiled camera arguments; refuses an env whose physics or camera is not compiled.

    Raises:
        NotCompilable: numba cannot call its Chipmunk functions here, or is missing.
    """
    reading = env._reading_arguments()
    if env.robot._driver[0] is _chipmunk.drive_python or reading is None:
        raise NotCompilable(
            "the e-puck's compiled physics or camera is not in use on this platform"
        )
    return reading


def _load(env: EPuckLineFollowEnv, live: np.ndarray, counters: np.ndarray) -> None:
    """Copy the env's state into a :class:`Robot`'s ``live`` and ``counters``."""
    live[:] = (env._s, env._lateral, env._progress, *env.robot.wheel_speeds)
    counters[:] = (env._segment, env._lost, env._steps)


def _store(env: EPuckLineFollowEnv, live: np.ndarray, counters: np.ndarray) -> None:
    """Copy a :class:`Robot`'s ``live`` and ``counters`` into the env's state."""
    env._s, env._lateral, env._progress = float(live[0]), float(live[1]), float(live[2])
    env.robot.wheel_speeds = (float(live[3]), float(live[4]))
    env._segment, env._lost, env._steps = (int(c) for c in counters)


def _python_put_back(
    key: int, live: np.ndarray, counters: np.ndarray, handles: np.ndarray
) -> tuple[float, float, float]:
    """The env's own recovery (a rebuilt space: new handles); returns the robot's pose."""
    env = _LINKED[int(key)]
    _store(env, live, counters)
    pose = env._put_back()
    handles[:] = env.robot._driver[1]
    _load(env, live, counters)
    return pose


def _python_reset(key: int, live: np.ndarray, counters: np.ndarray, handles: np.ndarray) -> int:
    """The env's own ``reset()`` (unseeded: its generator goes on); returns the observation."""
    env = _LINKED[int(key)]
    obs, _ = env.reset()
    handles[:] = env.robot._driver[1]
    _load(env, live, counters)
    return int(obs)


@_jit
def _read(robot, x, y, heading):
    """``EPuckLineFollowEnv._read``: the noise drawn, the camera read, the track position moved."""
    reals, live, counters, draws = robot.reals, robot.live, robot.counters, robot.draws
    contrast, noise = reals[_CONTRAST], reals[_NOISE]
    if contrast < 1:
        for i in range(draws.shape[1]):
            draws[0, i] = robot.generator.random()
    if noise > 0:
        for i in range(draws.shape[1]):
            draws[1, i] = robot.generator.random()
    sin, cos = portable_math.sincos(heading)
    m, s, lateral, segment = _kernels.observe(
        x,
        y,
        cos,
        sin,
        counters[_SEGMENT],
        contrast,
        noise,
        robot.camera,
        robot.track_floats,
        robot.track_ints,
        draws,
        robot.pixels,
    )
    length = reals[_LENGTH]
    half = 0.5 * length
    live[_PROGRESS] += ((s - live[_ARC] + half) % length - half) / length
    live[_ARC] = s
    live[_LATERAL] = lateral
    counters[_SEGMENT] = segment
    return m


@_jit
def robot_step(robot, action):
    """``EPuckLineFollowEnv.step(action)`` without command latency, compiled.

    Returns:
        ``(m, reward, terminated, truncated)``, with ``m`` the observed centroid.
    """
    reals, ints, live, counters = robot.reals, robot.ints, robot.live, robot.counters
    v_left, v_right = robot.speeds[action, 0], robot.speeds[action, 1]
    slip_left = slip_right = 1.0
    if reals[_SLIP] > 0:  # numpy's uniform(1 − slip, 1, size=2): low + (high − low) · u
        low = 1.0 - reals[_SLIP]
        span = 1.0 - low
        slip_left = low + span * robot.generator.random()
        slip_right = low + span * robot.generator.random()
    lagged = ints[_LAGGED] != 0
    left, right = (live[_LEFT], live[_RIGHT]) if lagged else (v_left, v_right)
    left, right, x, y, heading = _chipmunk.drive(
        robot.handles,
        v_left,
        v_right,
        left,
        right,
        reals[_GAIN],
        lagged,
        slip_left,
        slip_right,
        ints[_SUBSTEPS],
        reals[_DT],
        METRES_PER_STEP,
        AXLE_LENGTH,
    )
    live[_LEFT], live[_RIGHT] = left, right
    counters[_STEPS] += 1
    m = _read(robot, x, y, heading)
    if m:
        counters[_LOST] = 0
        reward = (
            (v_left + v_right)
            / (2 * MAX_WHEEL_SPEED)
            * (1.0 - abs(m - CENTRE_PIXEL) / CENTRE_PIXEL)
        )
    else:
        counters[_LOST] += 1
        reward = -1.0
    terminated = False
    if counters[_LOST] >= ints[_LOST_STEPS]:
        if ints[_TERMINATE]:
            terminated = True
        else:
            key, handles = ints[_KEY], robot.handles
            with objmode(x="float64", y="float64", heading="float64"):
                x, y, heading = _python_put_back(key, live, counters, handles)
            m = _read(robot, x, y, heading)
            if m:
                counters[_LOST] = 0
    truncated = ints[_MAX_STEPS] > 0 and counters[_STEPS] >= ints[_MAX_STEPS]
    return m, reward, terminated, truncated


@_jit
def robot_reset(robot):
    """The env's ``reset()`` at an episode's end, in Python: the next episode's first state."""
    key, live, counters, handles = robot.ints[_KEY], robot.live, robot.counters, robot.handles
    with objmode(m="int64"):
        m = _python_reset(key, live, counters, handles)
    return m


def linked(env: Any) -> bool:
    """Whether ``env`` (unwrapped) is the e-puck env, which compiles through a :class:`RobotLink`."""
    return isinstance(env, EPuckLineFollowEnv)

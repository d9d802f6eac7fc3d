"""The e-puck line-following environment (thesis section 5.2), without Webots."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from delayed_rl import _portable_math as portable_math
from delayed_rl._numba import entry_point
from delayed_rl._validation import (
    check_choice,
    check_fraction,
    check_int,
    check_probability,
    check_real,
    check_real_vector,
)
from delayed_rl.envs.linefollow import _kernels
from delayed_rl.envs.linefollow.camera import CENTRE_PIXEL, N_PIXELS, Camera, line_centroid
from delayed_rl.envs.linefollow.robot import EPuckRobot
from delayed_rl.envs.linefollow.track import TRACK_NAMES, Track, make_track

__all__ = [
    "CONTROL_PERIOD",
    "MAX_PHYSICS_DT",
    "MAX_WHEEL_SPEED",
    "PHYSICS_SUBSTEPS",
    "REAL_ROBOT",
    "WHEEL_SPEED_ACTIONS",
    "EPuckLineFollowEnv",
]

#: Seconds of simulated time per env step (the default ``control_period``).
CONTROL_PERIOD = 0.064
#: Physics sub-steps per env step at the default period (each CONTROL_PERIOD / 4 = 16 ms long).
PHYSICS_SUBSTEPS = 4
#: The longest physics sub-step (s): a step of ``control_period`` T has ⌈T / 0.016⌉ sub-steps.
MAX_PHYSICS_DT = 0.016
#: The arguments of ``delayed_rl/EPuckLineFollowReal-v0``, the stand-in for the thesis's real
#: e-puck on a paper print of the track (section 5.3); the class docstring gives their sources.
REAL_ROBOT = MappingProxyType(
    {
        "control_period": 0.2,
        "command_latency": 0.1,
        "motor_lag": 0.05,
        "wheel_slip": 0.1,
        "camera_noise": 0.01,
        "line_contrast": 0.9,
    }
)
#: v_max of Eq. 5.7 and the top wheel speed of every action (steps/s).
MAX_WHEEL_SPEED = 300
#: Thesis Table 5.2: (left, right) wheel speeds (steps/s) of discrete actions 0..6 (thesis 1..7).
WHEEL_SPEED_ACTIONS: tuple[tuple[int, int], ...] = (
    (0, 300),
    (100, 300),
    (200, 300),
    (300, 300),
    (300, 200),
    (300, 100),
    (300, 0),
)

#: Wheel-slip factors when there is none.
_NO_SLIP = (1.0, 1.0)
#: WHEEL_SPEED_ACTIONS as floats, by action.
_DISCRETE_SPEEDS = {
    action: (float(left), float(right)) for action, (left, right) in enumerate(WHEEL_SPEED_ACTIONS)
}
_OBSERVATION_MODES = ("centroid", "pixels")
_ACTION_MODES = ("discrete", "continuous")
_LOST_LINE_MODES = ("terminate", "recover")
_RESET_OPTIONS = ("start_progress", "pose")


class EPuckLineFollowEnv(gym.Env):
    """An e-puck robot follows a black line with a 1×40 camera (Campbell thesis, section 5.2).

    ## Description

    A simulated e-puck (a 7.4 cm differential-drive robot) drives on a floor with a closed black
    line. Its only sensor is one row of 40 binary pixels looking at the floor just in front of
    it. The goal is the thesis's: drive fast while keeping the line centred in the camera. The
    robot is a pymunk body with the e-puck's constants (wheel radius 0.0205 m, axle 0.053 m,
    body radius 0.037 m, 0.15 kg) dragged by top-down friction joints
    (:mod:`~delayed_rl.envs.linefollow.robot`); wheel speeds are in e-puck units (steps/s,
    1000 steps per wheel turn, so 300 ≈ 0.0386 m/s).

    Each step lasts ``control_period`` = 0.064 s of simulated time by default (4 physics
    sub-steps of 16 ms, a multiple of the 16–32 ms ``basicTimeStep`` of Webots' e-puck worlds;
    another period T gets ⌈T / 16 ms⌉ equal sub-steps). At full speed the
    robot then moves 2.5 mm and turns at most 2.7° per step, which shifts the line in the camera
    by one or two pixels: each of the 7 actions leads to distinguishable next states (a
    learnable tabular task) and the line never jumps out of view within one step. A 1700-step
    run (thesis Fig. 5.19) lasts 109 s, about four-fifths of a lap of the 5.1 m racetrack. (The
    thesis's real robot stepped every ~200 ms; there a sharp turn shifts the line ~5 pixels per
    step and a tabular agent sees far coarser dynamics; ``control_period=0.2`` simulates that.)
    A new command moves the robot from the second sub-step on (pymunk integrates positions
    before it solves the friction joints): one sub-step (16 ms) of actuation latency, to which
    ``command_latency`` adds the command link's.

    Camera (:mod:`~delayed_rl.envs.linefollow.camera`): the scanline is 0.05 m ahead of the body
    centre, 0.064 m wide (1.6 mm per pixel), across the heading; **pixel 1 is on the robot's
    left**. The line is 0.010 m wide, so a robot centred on a straight line sees pixels 18–23.

    ## Action Space

    ``action_mode="discrete"`` (default): ``Discrete(7)``, the (left, right) wheel speeds of
    thesis Table 5.2 (action k here is thesis action k + 1):

    | action | left | right | motion |
    |---|---|---|---|
    | 0 | 0 | 300 | sharpest left turn |
    | 1 | 100 | 300 | left |
    | 2 | 200 | 300 | gentle left |
    | 3 | 300 | 300 | straight, full speed |
    | 4 | 300 | 200 | gentle right |
    | 5 | 300 | 100 | right |
    | 6 | 300 | 0 | sharpest right turn |

    ``action_mode="continuous"``: ``Box(-1, 1, (2,), float32)``, (left, right) wheel speeds as a
    fraction of 300, mapped linearly to [−300, 300] steps/s (negative = reverse; out-of-range
    values are clipped).

    ## Observation Space

    ``observation_mode="centroid"`` (default): ``Discrete(41)``, the line centroid state of
    Eq. 5.6, m = round(Σ f(i)·i / Σ f(i)) ∈ 1..40, ties rounded down (pixels 18–23 → 20.5 → 20),
    and 0 when no pixel sees the line.

    ``observation_mode="pixels"``: ``Box(0, 1, (40,), float32)``, the raw pixels (1 = line),
    pixel 1 first.

    ## Rewards

    Eq. 5.7: −1 when the line is not seen (m = 0), else
    (v_l + v_r) / (2·300) · (1 − |m − 20| / 20), with the commanded wheel speeds of the step's
    action and the centroid m of the camera reading at the end of the step (with
    ``camera_noise``, of the noisy reading the agent observes). At most 1 (full speed, line
    centred); reversing in continuous mode earns negative rewards.

    ## Starting State

    The robot is at rest on the centreline at a uniformly random point of the track (from the
    env's generator, so ``reset(seed=...)`` is deterministic), facing along the track's
    direction. ``reset(options=...)`` may instead give ``{"start_progress": f}`` (the point a
    fraction f ∈ [0, 1) of the way round the track) or ``{"pose": (x, y, heading)}`` (any pose,
    metres and radians). With ``track="random"`` and no ``track_seed``, every reset also draws a
    new random track from the env's generator.

    ## Episode End

    - Termination: the line has been out of sight for ``lost_line_steps`` consecutive steps
      (default 50 steps = 3.2 s) and ``lost_line="terminate"`` (default). With
      ``lost_line="recover"`` the robot is instead put back on the nearest centreline point,
      facing along the track, wheels stopped (as the thesis's experimenters did by hand), and
      the episode continues; that step's reward is the −1 earned before the recovery, its
      observation and ``info`` describe the robot after it, and ``info["recovered"]`` is True.
    - Truncation: after ``max_steps`` steps (default 2000); ``max_steps=None`` never truncates.
      The env counts its own steps instead of relying on Gymnasium's ``TimeLimit`` because
      reward-delay wrappers sit directly on the env (``gym.make(..., reward_delay=λ)``) and must
      see every episode end to flush their pending rewards; a ``TimeLimit`` would sit outside
      them.

    ## Info

    - ``line_visible`` (bool): whether any pixel sees the line.
    - ``centroid`` (int): m, 0..40 (also in pixel mode).
    - ``line_error_px`` (int): m − 20 when the line is visible, 0 when it is not (check
      ``line_visible``); positive when the line is to the robot's right.
    - ``lateral_error_m`` (float): signed distance (m) of the body centre from the nearest
      centreline point, positive when the robot is left of the track (for its direction).
    - ``lap_progress`` (float): laps driven along the track since the reset (arc length / track
      length, cumulative, negative when driving backwards).
    - ``wheel_speeds`` ((float, float)): the commanded (left, right) speeds (steps/s).
    - ``lost_steps`` (int): consecutive steps without the line so far.
    - ``recovered`` (bool): the robot was put back on the track this step.
    - ``pose`` ((float, float, float)): x, y (m) and heading (rad, in (−π, π]).

    ## Arguments

    - ``track``: ``"racetrack"`` (default; long sweeping turns, like thesis Fig. 5.18),
      ``"oval"``, ``"figure8"``, ``"random"``, a :class:`~delayed_rl.envs.linefollow.track.Track`,
      or an ``(n, 2)`` closed polyline in metres (last point == first; validated by
      :meth:`Track.from_polyline`).
    - ``track_seed``: with ``track="random"``, an int fixes the track; None draws a new one at
      every reset.
    - ``observation_mode``: ``"centroid"`` or ``"pixels"``.
    - ``action_mode``: ``"discrete"`` or ``"continuous"``.
    - ``max_steps``: steps before truncation (int ≥ 1) or None.
    - ``lost_line``: ``"terminate"`` or ``"recover"``.
    - ``lost_line_steps``: consecutive line-less steps before that happens (int ≥ 1).
    - ``motor_lag``: first-order time constant (s, ≥ 0) of the wheel speeds; 0 = off.
    - ``wheel_slip``: in [0, 1): each step, each wheel's ground speed is scaled by a factor drawn
      uniformly from [1 − wheel_slip, 1]; 0 = off.
    - ``camera_noise``: in [0, 1]: each pixel is flipped with this probability each step;
      0 = off.
    - ``line_contrast``: in (0, 1]: each pixel over the line reads as line with this
      probability each reading (a grey print instead of black tape: some of its pixels stay
      above the camera's binarisation threshold), before ``camera_noise``; 1 = off.
    - ``control_period``: seconds of simulated time per step (> 0; default 0.064), split into
      ⌈control_period / 0.016⌉ equal physics sub-steps.
    - ``command_latency``: seconds (≥ 0) between an action and the moment the robot starts
      executing it (a radio link's delay), rounded up to whole physics sub-steps; until then
      the previous command goes on (wheels stopped after a reset or a recovery). It may exceed
      ``control_period`` (a command then lands in a later step). The reward still uses the
      commanded speeds of the step's action (the controller computes it from what it sent);
      ``info["wheel_speeds"]`` reports them too. 0 = off.
    - ``render_mode``: None, ``"rgb_array"`` (numpy-drawn track, trail, robot and scanline) or
      ``"human"`` (a pygame window; needs the ``render`` extra).

    Noise (slip, contrast, camera flips) is drawn from the env's ``np_random``, so seeded
    resets reproduce it; with every one of them off the env draws nothing per step.

    Speed: with numba (a core dependency) the camera reading, the track position and the
    physics sub-steps run compiled (``benchmarks/epuck_speed.py`` times them); without it the
    env runs the numpy and Python code they mirror, several times slower, with the same
    trajectories to the last bit. With centroid states, discrete actions and no
    ``command_latency``, the agents' ``learn()`` steps the env inside their compiled training
    loop (:mod:`delayed_rl.compiled.robot`), again to the last bit.

    An argument of the wrong type (``max_steps="5"``, ``motor_lag=True``, ``action_mode=1``)
    raises ``TypeError``; one of the right type but out of range (``max_steps=0``,
    ``wheel_slip=1.0``, ``lost_line="reset"``, ``control_period=0``) raises ``ValueError``.
    Messages name the argument.

    ## Registered Configurations

    - ``delayed_rl/EPuckLineFollow-v0``: the defaults above (the clean simulation). Pass any
      argument to ``gym.make``, and ``reward_delay=λ`` to get the env already wrapped in
      :class:`~delayed_rl.wrappers.PoissonRewardDelay`.
    - ``delayed_rl/EPuckLineFollowReal-v0``: a stand-in for the thesis's real e-puck on a paper
      print of the racetrack (section 5.3), the defaults above with :data:`REAL_ROBOT`'s
      arguments (any of them can still be passed to ``gym.make``):

      | argument | value | source |
      |---|---|---|
      | ``track`` | ``"racetrack"`` | thesis 5.3: "a scale print out of the Webots racetracks" (same shape; the scale is not given, 1:1 here) |
      | ``control_period`` | 0.2 s | thesis 5.3: "one time step being approximately 200 ms" |
      | ``command_latency`` | 0.1 s (7 sub-steps of 15.4 ms = 108 ms) | a guess: commands went over Bluetooth from MATLAB (thesis 5.3), sent after the camera line came back within the ~200 ms step; no latency is given |
      | ``wheel_slip`` | 0.1 | a guess: the thesis names "wheel slippage on paper" as what the simulation lacked but gives no number; up to 10 % (mean 5 %) of each wheel's ground speed lost per step |
      | ``motor_lag`` | 0.05 s | a guess: the e-puck's stepper motors (data sheet: 1000 steps per wheel turn, wheels 41 mm, axle 53 mm) follow their step rate open-loop; what lags is the 150 g body on compliant tyres |
      | ``camera_noise`` | 0.01 | a guess: the e-puck's CMOS camera on paper under room light; one reading in three has a flipped pixel (1 − 0.99⁴⁰) |
      | ``line_contrast`` | 0.9 | a guess: a printed line is dark grey, not black tape; one line pixel in ten stays above the threshold |

      The thesis's λ = 90 reward delay is in steps, as in the simulation; at 200 ms a step it
      is 18 s. ``lost_line``, ``lost_line_steps`` and ``max_steps`` keep their defaults (the
      ``real-robot`` experiment passes ``lost_line="recover"``, ``max_steps=None``).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": round(1 / CONTROL_PERIOD)}

    def __init__(
        self,
        track: str | Track | ArrayLike = "racetrack",
        *,
        track_seed: int | None = None,
        observation_mode: str = "centroid",
        action_mode: str = "discrete",
        max_steps: int | None = 2000,
        lost_line: str = "terminate",
        lost_line_steps: int = 50,
        motor_lag: float = 0.0,
        wheel_slip: float = 0.0,
        camera_noise: float = 0.0,
        line_contrast: float = 1.0,
        control_period: float = CONTROL_PERIOD,
        command_latency: float = 0.0,
        render_mode: str | None = None,
    ):
        self.observation_mode = check_choice(
            "observation_mode", observation_mode, _OBSERVATION_MODES
        )
        self.action_mode = check_choice("action_mode", action_mode, _ACTION_MODES)
        self.max_steps = check_int("max_steps", max_steps, 1, optional=True)
        self.lost_line = check_choice("lost_line", lost_line, _LOST_LINE_MODES)
        self.lost_line_steps = check_int("lost_line_steps", lost_line_steps, 1)
        self.motor_lag = check_real("motor_lag", motor_lag, 0.0)
        self.wheel_slip = check_real("wheel_slip", wheel_slip, 0.0, 1.0, high_open=True)
        self.camera_noise = check_probability("camera_noise", camera_noise)
        self.line_contrast = check_fraction("line_contrast", line_contrast)
        self.control_period = check_real(
            "control_period", control_period, 0.0, low_open=True, note=" (s)"
        )
        self.command_latency = check_real("command_latency", command_latency, 0.0, note=" (s)")
        #: Physics sub-steps per step, and the sub-steps a command waits before it applies.
        self.physics_substeps = max(1, math.ceil(self.control_period / MAX_PHYSICS_DT - 1e-9))
        physics_dt = self.control_period / self.physics_substeps
        self.latency_substeps = math.ceil(self.command_latency / physics_dt - 1e-9)
        if self.control_period != CONTROL_PERIOD:
            self.metadata = {**self.metadata, "render_fps": round(1 / self.control_period)}
        self.render_mode = check_choice(
            "render_mode", render_mode, (None, *self.metadata["render_modes"])
        )
        track_seed = check_int("track_seed", track_seed, 0, optional=True)
        if track_seed is not None and not (isinstance(track, str) and track == "random"):
            raise ValueError(f"track_seed is only used with track='random', got track={track!r}")
        self._random_tracks = isinstance(track, str) and track == "random" and track_seed is None
        self.track = self._make_track(track, track_seed)

        if self.observation_mode == "centroid":
            self.observation_space: spaces.Space = spaces.Discrete(N_PIXELS + 1)
        else:
            self.observation_space = spaces.Box(0.0, 1.0, (N_PIXELS,), np.float32)
        if self.action_mode == "discrete":
            self.action_space: spaces.Space = spaces.Discrete(len(WHEEL_SPEED_ACTIONS))
        else:
            self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

        self.camera = Camera()
        self.robot = EPuckRobot(physics_dt, self.motor_lag)
        #: Commands on their way to the robot, oldest first: ((left, right), sub-steps) runs.
        self._in_flight: deque[tuple[tuple[float, float], int]] = deque()
        self._renderer: Any = None
        self._trail: deque[tuple[float, float]] = deque(maxlen=4000)
        self._pixels = np.zeros(N_PIXELS, dtype=bool)
        #: Each step's uniform draws per pixel: for line_contrast, then for camera_noise.
        self._draws = np.zeros((2, N_PIXELS))
        #: The track the compiled reading's arguments were made for, and those arguments.
        self._compiled_track: Track | None = None
        self._compiled: tuple | None = None
        self._observe: Any = None  # _kernels.observe for these arguments, without dispatch
        self._s = 0.0
        self._segment = 0
        self._lateral = 0.0
        self._progress = 0.0
        self._lost = 0
        self._steps = 0

    @staticmethod
    def _make_track(track: Any, track_seed: int | None) -> Track:
        """The track for the ``track`` argument (see the class docstring's "Arguments")."""
        if isinstance(track, Track):
            return track
        if isinstance(track, str):
            check_choice("track", track, TRACK_NAMES)
            # A random track without track_seed is redrawn at every reset; seed 0 until then.
            return make_track(track, 0 if track_seed is None else track_seed)
        try:
            return Track.from_polyline(track)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"track: {exc}") from exc

    # ------------------------------------------------------------------ gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode (see the class docstring's "Starting State").

        Args:
            seed: seeds the env's generator (the start point, a random track, sensor noise).
            options: ``None``, or a dict with one of ``"start_progress"`` (a number in
                ``[0, 1)``: the fraction of the way round the track to start at) and
                ``"pose"`` (``(x, y, heading)``: a list, tuple or 1-D array of three finite
                real numbers, metres and radians; bools and strings are not numbers).

        Raises:
            TypeError: ``options`` is not a dict, ``options['pose']`` is not a sequence of numbers (a string, ``None``,
                an entry that is not a real number), or ``options['start_progress']`` is not
                a number.
            ValueError: ``options`` holds an unknown key or both keys, ``options['pose']``
                does not hold three numbers or holds a NaN or infinite one, or
                ``options['start_progress']`` is outside ``[0, 1)``.
        """
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, Mapping):
            raise TypeError(
                f"options must be None or a dict (keys {list(_RESET_OPTIONS)}), got "
                f"{options!r} ({type(options).__name__})"
            )
        unknown = set(options) - set(_RESET_OPTIONS)
        if unknown or len(options) > 1:
            raise ValueError(
                f"options may hold one of {_RESET_OPTIONS}, got {sorted(options)}"
                if not unknown
                else f"unknown reset options {sorted(unknown)}; allowed: {_RESET_OPTIONS}"
            )
        if self._random_tracks:
            self.track = make_track("random", self.np_random)
        track = self.track
        if "pose" in options:
            x, y, heading = check_real_vector(
                "options['pose']", options["pose"], 3, note=" (x, y in metres, heading in radians)"
            )
        else:
            fraction = options.get("start_progress")
            if fraction is None:
                fraction = float(self.np_random.uniform())
            else:
                fraction = check_real(
                    "options['start_progress']", fraction, 0.0, 1.0, high_open=True
                )
            x, y, heading = track.point_at(fraction * track.length)
        self.robot.reset(x, y, heading)
        self._stop_commands()
        self._s, _, self._segment = track.locate(x, y)
        self._progress = 0.0
        self._lost = 0
        self._steps = 0
        self._trail.clear()
        obs, info = self._obs_info(self._read(x, y, heading), x, y, heading, 0.0, 0.0, False)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Drive for one control period with the action's wheel speeds."""
        v_left, v_right = self._wheel_speeds(action)
        slip = _NO_SLIP
        if self.wheel_slip > 0:
            factors = self.np_random.uniform(1.0 - self.wheel_slip, 1.0, size=2)
            slip = (float(factors[0]), float(factors[1]))
        if self.latency_substeps == 0:
            x, y, heading = self.robot.step(v_left, v_right, self.physics_substeps, slip)
        else:
            x, y, heading = self._drive_through_link(v_left, v_right, slip)
        self._steps += 1
        m = self._read(x, y, heading)
        if m:
            self._lost = 0
            reward = (
                (v_left + v_right)
                / (2 * MAX_WHEEL_SPEED)
                * (1.0 - abs(m - CENTRE_PIXEL) / CENTRE_PIXEL)
            )
        else:
            self._lost += 1
            reward = -1.0
        terminated = recovered = False
        if self._lost >= self.lost_line_steps:
            if self.lost_line == "terminate":
                terminated = True
            else:
                x, y, heading = self._put_back()
                m = self._read(x, y, heading)
                self._lost = 0 if m else self._lost
                recovered = True
        obs, info = self._obs_info(m, x, y, heading, v_left, v_right, recovered)
        truncated = self.max_steps is not None and self._steps >= self.max_steps
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), terminated, truncated, info

    def _drive_through_link(
        self, v_left: float, v_right: float, slip: tuple[float, float]
    ) -> tuple[float, float, float]:
        """Send a command down the latency link and drive one step; returns the robot's pose.

        The step executes the commands that arrive during its sub-steps, one ``robot.step``
        per run of sub-steps with the same command (a robot step split in two drives exactly
        like one).
        """
        in_flight = self._in_flight
        in_flight.append(((v_left, v_right), self.physics_substeps))
        remaining = self.physics_substeps
        while remaining:
            (left, right), count = in_flight[0]
            run = min(count, remaining)
            pose = self.robot.step(left, right, run, slip)
            remaining -= run
            if run == count:
                in_flight.popleft()
            else:
                in_flight[0] = ((left, right), count - run)
        return pose

    def _put_back(self) -> tuple[float, float, float]:
        """Put the robot back on the track (``lost_line="recover"``); returns its pose.

        It goes to the centreline point at its track position, facing along the track, with its
        wheels and its command link stopped.
        """
        x, y, heading = self.track.point_at(self._s)
        self.robot.reset(x, y, heading)
        self._stop_commands()
        return x, y, heading

    def _stop_commands(self) -> None:
        """Fill the command link with "wheels stopped" (after a reset or a recovery)."""
        self._in_flight.clear()
        if self.latency_substeps:
            self._in_flight.append(((0.0, 0.0), self.latency_substeps))

    def _wheel_speeds(self, action: Any) -> tuple[float, float]:
        """The commanded (left, right) wheel speeds (steps/s) of an action, which it validates."""
        if self.action_mode == "discrete":
            if isinstance(action, (int, np.integer)) and action in _DISCRETE_SPEEDS:
                return _DISCRETE_SPEEDS[action]
            try:
                index = int(action)
            except (TypeError, ValueError):
                index = -1
            if not (0 <= index < len(WHEEL_SPEED_ACTIONS)) or index != action:
                raise ValueError(
                    f"action must be an int in 0..{len(WHEEL_SPEED_ACTIONS) - 1}, got {action!r}"
                )
            left, right = WHEEL_SPEED_ACTIONS[index]
            return float(left), float(right)
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.empty(0)
        if a.shape == (2,):
            left, right = float(a[0]), float(a[1])
            if math.isfinite(left) and math.isfinite(right):
                return (
                    min(max(left, -1.0), 1.0) * MAX_WHEEL_SPEED,
                    min(max(right, -1.0), 1.0) * MAX_WHEEL_SPEED,
                )
        raise ValueError(f"action must be 2 finite numbers in [-1, 1], got {action!r}")

    def _read(self, x: float, y: float, heading: float) -> int:
        """Read the camera at a pose and update the track position; returns the centroid m.

        The noise is drawn first (locating the robot draws nothing, so this is the order of
        the draws either way). With the compiled kernels
        (:mod:`~delayed_rl.envs.linefollow._kernels`) one call reads the camera into
        ``_pixels``, adds the noise, takes the centroid and locates the robot; without them
        the camera, numpy, the track and :func:`line_centroid` do it. Both give the same bits.
        """
        track, draws = self.track, self._draws
        if self.line_contrast < 1:
            self.np_random.random(out=draws[0])
        if self.camera_noise > 0:
            self.np_random.random(out=draws[1])
        compiled = self._compiled if self._compiled_track is track else self._reading_arguments()
        if compiled is None:
            pixels = self.camera.read(track, x, y, heading)
            if self.line_contrast < 1:
                pixels &= draws[0] < self.line_contrast
            if self.camera_noise > 0:
                pixels ^= draws[1] < self.camera_noise
            self._pixels = pixels
            s, self._lateral, self._segment = track.locate(x, y, self._segment)
            m = line_centroid(pixels)
        else:
            sin, cos = portable_math.sincos(heading)
            m, s, self._lateral, self._segment = self._observe(
                x,
                y,
                cos,
                sin,
                self._segment,
                self.line_contrast,
                self.camera_noise,
                *compiled,
            )
        half = 0.5 * track.length
        self._progress += ((s - self._s + half) % track.length - half) / track.length
        self._s = s
        if self.render_mode is not None:
            self._trail.append((x, y))
        return m

    def _reading_arguments(self) -> tuple | None:
        """The current track's :meth:`_compiled_arguments`, made again when the track changes.

        With them, ``_observe`` is :func:`_kernels.observe` compiled for their types, called
        without numba's dispatch (:func:`~delayed_rl._numba.entry_point`): the pose, the
        hint and the noise levels are converted to its float and int arguments.
        """
        track = self.track
        if self._compiled_track is not track:
            compiled = self._compiled_arguments(track)
            observe = (
                None
                if compiled is None
                else entry_point(_kernels.observe, *[0.0] * 4, 0, 1.0, 0.0, *compiled)
            )
            # the track last: an interruption above (a first compilation) leaves them unmade
            self._compiled, self._observe, self._compiled_track = compiled, observe, track
        return self._compiled

    def _compiled_arguments(self, track: Track) -> tuple | None:
        """The arguments of :func:`_kernels.observe` after the pose, hint and noise, or None.

        None when the kernels are not in use (numba is missing): the env then reads with numpy.
        """
        if not _kernels.enabled():
            return None
        return (self.camera._packed, *track._packed, self._draws, self._pixels)

    def _obs_info(
        self,
        m: int,
        x: float,
        y: float,
        heading: float,
        v_left: float,
        v_right: float,
        recovered: bool,
    ) -> tuple[Any, dict[str, Any]]:
        if self.observation_mode == "centroid":
            obs: Any = np.int64(m)
        else:
            obs = self._pixels.astype(np.float32)
        info = {
            "line_visible": m > 0,
            "centroid": m,
            "line_error_px": m - CENTRE_PIXEL if m else 0,
            "lateral_error_m": self._lateral,
            "lap_progress": self._progress,
            "wheel_speeds": (v_left, v_right),
            "lost_steps": self._lost,
            "recovered": recovered,
            "pose": (x, y, math.remainder(heading, 2 * math.pi)),
        }
        return obs, info

    def __getstate__(self) -> dict[str, Any]:
        """The env's state without the compiled reading's arguments.

        They hold a compiled function of this process; a copy or an unpickled env (perhaps in
        another process) makes its own at its first reading.
        """
        state = self.__dict__.copy()
        state["_compiled_track"] = state["_compiled"] = state["_observe"] = None
        return state

    # ------------------------------------------------------------------ rendering
    def render(self) -> NDArray[np.uint8] | None:
        """Draw the scene: an RGB array (``"rgb_array"``) or a pygame window (``"human"``)."""
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        from delayed_rl.envs.linefollow.render import Renderer

        if self._renderer is None or self._renderer.track is not self.track:
            self._renderer = Renderer(self.track, self.camera)
        frame = self._renderer.draw(self.robot.pose, self._pixels, self._trail)
        if self.render_mode == "human":
            self._renderer.show(frame, self.metadata["render_fps"])
            return None
        return frame

    def close(self) -> None:
        """Close the pygame window, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()

"""A pymunk e-puck: a differential-drive disc on a floor with friction, seen from above.

:class:`EPuckRobot` turns wheel speeds (e-puck units, with an optional motor lag and the
env's slip factors) into motion: a kinematic control body set from the differential-drive
kinematics drags the robot within the tyres' grip (pymunk's "tank" example). It draws no random
numbers, so it is deterministic given its inputs; its Chipmunk calls go past pymunk's Python
wrappers (:mod:`~delayed_rl.envs.linefollow._chipmunk`) to the same bits. The physics in full:
the docs' environments page (``docs/envs.md``, "The robot's physics").
"""

from __future__ import annotations

import math
from typing import Any

import pymunk

from delayed_rl import _portable_math as portable_math
from delayed_rl._validation import check_real
from delayed_rl.envs.linefollow import _chipmunk

__all__ = [
    "AXLE_LENGTH",
    "BODY_RADIUS",
    "FRICTION",
    "MASS",
    "METRES_PER_STEP",
    "STEPS_PER_REVOLUTION",
    "WHEEL_RADIUS",
    "EPuckRobot",
]

#: e-puck wheel radius (m).
WHEEL_RADIUS = 0.0205
#: Distance (m) between the e-puck's wheels.
AXLE_LENGTH = 0.053
#: e-puck body radius (m).
BODY_RADIUS = 0.037
#: e-puck mass (kg).
MASS = 0.15
#: Motor steps per wheel revolution (e-puck stepper motors).
STEPS_PER_REVOLUTION = 1000
#: Ground distance (m) per motor step: 300 steps/s ≈ 0.0386 m/s.
METRES_PER_STEP = 2 * math.pi * WHEEL_RADIUS / STEPS_PER_REVOLUTION
#: Tyre–floor friction coefficient behind the joints' force limits.
FRICTION = 0.8
_GRAVITY = 9.81


class EPuckRobot:
    """The e-puck's body and its pymunk space.

    Args:
        physics_dt: the physics sub-step (s).
        motor_lag: first-order time constant (s) of the wheel speeds; 0 = instantaneous.

    Raises:
        TypeError: an argument is not a number.
        ValueError: ``physics_dt`` is not positive or ``motor_lag`` is negative (or either is
            not finite).
    """

    def __init__(self, physics_dt: float = 0.016, motor_lag: float = 0.0):
        self.physics_dt = check_real("physics_dt", physics_dt, 0.0, low_open=True, note=" (s)")
        self.motor_lag = check_real("motor_lag", motor_lag, 0.0, note=" (s)")
        #: Fraction of the gap to the commanded speed closed per sub-step.
        self._lag_gain = (
            1.0
            if self.motor_lag == 0
            else 1.0 - portable_math.exp(-self.physics_dt / self.motor_lag)
        )
        #: Current (lagged) wheel speeds (steps/s).
        self.wheel_speeds = (0.0, 0.0)
        self._build({})

    # ------------------------------------------------------------------ space
    def _build(self, state: dict[str, Any]) -> None:
        space = pymunk.Space()
        moment = 0.5 * MASS * BODY_RADIUS**2  # a uniform disc
        body = pymunk.Body(MASS, moment)
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        for b, prefix in ((body, "body"), (control, "control")):
            b.position = state.get(f"{prefix}_position", (0.0, 0.0))
            b.angle = state.get(f"{prefix}_angle", 0.0)
            b.velocity = state.get(f"{prefix}_velocity", (0.0, 0.0))
            b.angular_velocity = state.get(f"{prefix}_angular_velocity", 0.0)
        pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
        pivot.max_bias = 0.0  # match velocities only
        pivot.max_force = FRICTION * MASS * _GRAVITY  # linear grip
        gear = pymunk.GearJoint(control, body, 0.0, 1.0)
        gear.max_bias = 0.0
        gear.max_force = FRICTION * MASS * _GRAVITY * AXLE_LENGTH / 2  # angular grip (N·m)
        space.add(body, control, pivot, gear)
        self.space, self.body, self.control = space, body, control
        self._calls = _chipmunk.python_calls(body, control, space)
        handles = _chipmunk.handles(body, control, space)
        #: How :meth:`step` drives: the compiled loop where it is in use, else its reference.
        self._driver = (
            (_chipmunk.drive_entry(), handles)
            if handles is not None and _chipmunk.enabled()
            else (_chipmunk.drive_python, self._calls)
        )

    def _state(self) -> dict[str, Any]:
        state: dict[str, Any] = {}
        for b, prefix in ((self.body, "body"), (self.control, "control")):
            state[f"{prefix}_position"] = tuple(b.position)
            state[f"{prefix}_angle"] = b.angle
            state[f"{prefix}_velocity"] = tuple(b.velocity)
            state[f"{prefix}_angular_velocity"] = b.angular_velocity
        return state

    def __getstate__(self) -> dict[str, Any]:
        # pymunk's solver caches each joint's last impulse for warm-starting, which a pickled
        # space cannot restore: pickle the plain state, rebuild the space on unpickling, and
        # rebuild the original's too, so that both copies continue bit-for-bit identically.
        state = self._state()
        self._build(state)
        return {
            "physics": state,
            "physics_dt": self.physics_dt,
            "motor_lag": self.motor_lag,
            "lag_gain": self._lag_gain,
            "wheel_speeds": self.wheel_speeds,
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.physics_dt = state["physics_dt"]
        self.motor_lag = state["motor_lag"]
        self._lag_gain = state["lag_gain"]
        self.wheel_speeds = state["wheel_speeds"]
        self._build(state["physics"])

    # ------------------------------------------------------------------ control
    def reset(self, x: float, y: float, heading: float) -> None:
        """Place the robot at rest at (x, y) facing ``heading`` (rad), wheels stopped."""
        self.wheel_speeds = (0.0, 0.0)
        self._build({"body_position": (x, y), "body_angle": heading})

    @property
    def pose(self) -> tuple[float, float, float]:
        """``(x, y, heading)``: position (m) and heading (rad, unwrapped)."""
        calls = self._calls
        position = calls.get_position(calls.body)
        return position.x, position.y, calls.get_angle(calls.body)

    def step(
        self,
        v_left: float,
        v_right: float,
        substeps: int,
        slip: tuple[float, float] = (1.0, 1.0),
    ) -> tuple[float, float, float]:
        """Drive for ``substeps`` physics sub-steps with commanded wheel speeds (steps/s).

        Args:
            v_left: the commanded left wheel speed (steps/s).
            v_right: the commanded right wheel speed (steps/s).
            substeps: number of physics sub-steps of ``physics_dt``.
            slip: factors scaling each wheel's ground speed during these sub-steps.

        Returns:
            The :attr:`pose` after them.
        """
        drive, handles = self._driver
        lagged = self.motor_lag > 0
        wl, wr = self.wheel_speeds if lagged else (v_left, v_right)
        wl, wr, x, y, heading = drive(
            handles,
            v_left,
            v_right,
            wl,
            wr,
            self._lag_gain,
            lagged,
            slip[0],
            slip[1],
            substeps,
            self.physics_dt,
            METRES_PER_STEP,
            AXLE_LENGTH,
        )
        self.wheel_speeds = (wl, wr)
        return x, y, heading

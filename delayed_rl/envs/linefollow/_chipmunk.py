"""The robot's calls into pymunk's Chipmunk, made as cheaply as possible, to the same bits.

:func:`drive_python` (on :func:`python_calls`, the reference) calls pymunk's cffi binding from
Python; :func:`drive` (on :func:`handles`) runs all the sub-steps of a robot step in one
compiled loop that calls the C functions by address, where :func:`enabled` has checked that it
ends in exactly :func:`drive_python`'s state. Both reach the same C functions with the same
arguments, so the physics stays pymunk's. Why and where: the docs' environments page
(``docs/envs.md``, "Its compiled pieces, equal to the last bit").
"""

from __future__ import annotations

import functools
import platform
import sys
from typing import Any, NamedTuple

import numpy as np
import pymunk
from numpy.typing import NDArray

from delayed_rl import _portable_math as portable_math
from delayed_rl._numba import HAVE_NUMBA, entry_point, jit

__all__ = [
    "PythonCalls",
    "available",
    "body_velocity",
    "drive",
    "drive_python",
    "enabled",
    "handles",
    "python_calls",
]

try:  # pymunk's cffi binding of Chipmunk, behind its Python wrappers
    from pymunk._chipmunk_cffi import ffi as _ffi
    from pymunk._chipmunk_cffi import lib as _lib
except ImportError:  # pragma: no cover - a pymunk without it
    _ffi = _lib = None

#: The Chipmunk functions :func:`drive` calls, in the order of :func:`handles`.
_FUNCTIONS = (
    "cpBodyGetPosition",
    "cpBodyGetAngle",
    "cpBodySetVelocity",
    "cpBodySetAngularVelocity",
    "cpSpaceStep",
)
#: Wheel speeds (steps/s) of :func:`enabled`'s trial: turns both ways, reversing, straight.
_TRIAL_COMMANDS = ((300.0, 120.0), (-80.0, 250.0), (300.0, 300.0))
#: Machines whose C calling convention (outside Windows) passes a ``cpVect`` as two doubles.
_MACHINES = ("x86_64", "amd64", "aarch64", "arm64")


def body_velocity(
    wl: float, wr: float, sl: float, sr: float, metres_per_step: float, axle: float
) -> tuple[float, float]:
    """Differential drive: ``(v, ω)`` (m/s, rad/s) of wheel speeds (steps/s) scaled by slips."""
    gl, gr = wl * sl * metres_per_step, wr * sr * metres_per_step
    return 0.5 * (gl + gr), (gr - gl) / axle


_compiled_body_velocity = jit(body_velocity)


# ---------------------------------------------------------------------- from Python
class PythonCalls(NamedTuple):
    """A sub-step's Chipmunk calls and the handles they take, e.g. ``get_angle(calls.body)``."""

    body: Any
    control: Any
    space: Any
    get_position: Any
    get_angle: Any
    set_velocity: Any
    set_angular_velocity: Any
    step: Any


def _has_pointers(body: pymunk.Body, control: pymunk.Body, space: pymunk.Space) -> bool:
    """Whether pymunk exposes the Chipmunk pointers behind these objects, and its binding."""
    pointers = (getattr(body, "_body", None), getattr(control, "_body", None))
    return _lib is not None and None not in pointers and getattr(space, "_space", None) is not None


def python_calls(body: pymunk.Body, control: pymunk.Body, space: pymunk.Space) -> PythonCalls:
    """The calls that read the robot and drive its space from Python, as cheap as pymunk allows.

    ``get_position(calls.body)`` returns an object with ``.x`` and ``.y``; the calls are those
    of :func:`drive_python`.
    """
    if not _has_pointers(body, control, space):
        return PythonCalls(  # pragma: no cover - pymunk without its cffi internals
            body,
            control,
            space,
            pymunk.Body.position.fget,
            pymunk.Body.angle.fget,
            pymunk.Body.velocity.fset,
            pymunk.Body.angular_velocity.fset,
            pymunk.Space.step,
        )
    return PythonCalls(
        body._body,
        control._body,
        space._space,
        _lib.cpBodyGetPosition,
        _lib.cpBodyGetAngle,
        _lib.cpBodySetVelocity,
        _lib.cpBodySetAngularVelocity,
        _lib.cpSpaceStep,
    )


def drive_python(
    calls, v_left, v_right, wl, wr, gain, lagged, sl, sr, substeps, dt, metres_per_step, axle
):
    """``substeps`` sub-steps of ``EPuckRobot.step`` from Python: the reference of :func:`drive`.

    Args:
        calls: the robot's :func:`python_calls`.
        v_left: the commanded left wheel speed (steps/s).
        v_right: the commanded right wheel speed (steps/s).
        wl: the left wheel speed to start from (the commanded one without motor lag).
        wr: the right wheel speed to start from.
        gain: the motor lag's per-sub-step gain.
        lagged: whether the wheel speeds lag.
        sl: the left wheel's slip factor.
        sr: the right wheel's slip factor.
        substeps: the number of sub-steps.
        dt: the sub-step (s).
        metres_per_step: the robot's ground distance per motor step (m).
        axle: the robot's axle length (m).

    Returns:
        ``(wl, wr, x, y, heading)``: the final (lagged) wheel speeds and the body's pose.
    """
    body, control, space, get_position, get_angle, set_velocity, set_angular_velocity, step = calls
    sincos = portable_math.sincos
    v, w = body_velocity(wl, wr, sl, sr, metres_per_step, axle)  # without lag: throughout
    for _ in range(substeps):
        if lagged:
            wl += (v_left - wl) * gain
            wr += (v_right - wr) * gain
            v, w = body_velocity(wl, wr, sl, sr, metres_per_step, axle)
        sin, cos = sincos(get_angle(body))
        set_velocity(control, (v * cos, v * sin))
        set_angular_velocity(control, w)
        step(space, dt)
    position = get_position(body)
    return wl, wr, position.x, position.y, get_angle(body)


# ---------------------------------------------------------------------- compiled
if HAVE_NUMBA:
    from llvmlite import ir
    from numba import types
    from numba.core.extending import intrinsic

    _DOUBLE = ir.DoubleType()
    #: A ``cpVect`` returned by value (in two registers under the conventions of _MACHINES).
    _VECT = ir.LiteralStructType([_DOUBLE, _DOUBLE])

    def _call_by_address(result: Any, doubles: int) -> Any:
        """The code generator of a call ``f(pointer, *doubles)`` to a C function's address.

        ``result``: None (void), ``_DOUBLE`` or ``_VECT`` (returned as a numba pair).
        """

        def codegen(context, builder, signature, args):
            void_p = ir.IntType(8).as_pointer()
            returns = ir.VoidType() if result is None else result
            function_type = ir.FunctionType(returns, [void_p] + [_DOUBLE] * doubles)
            function = builder.inttoptr(args[0], function_type.as_pointer())
            value = builder.call(function, [builder.inttoptr(args[1], void_p), *args[2:]])
            if result is None:
                return context.get_dummy_value()
            if result is _VECT:
                parts = [builder.extract_value(value, i) for i in range(2)]
                return context.make_tuple(builder, signature.return_type, parts)
            return value

        return codegen

    @intrinsic
    def _get_angle(typingctx, function, body):
        """``cpBodyGetAngle(body)`` at address ``function``."""
        return types.float64(types.int64, types.int64), _call_by_address(_DOUBLE, 0)

    @intrinsic
    def _get_position(typingctx, function, body):
        """``cpBodyGetPosition(body)`` at address ``function``, as ``(x, y)``."""
        sig = types.UniTuple(types.float64, 2)(types.int64, types.int64)
        return sig, _call_by_address(_VECT, 0)

    @intrinsic
    def _set_velocity(typingctx, function, body, vx, vy):
        """``cpBodySetVelocity(body, cpv(vx, vy))`` at address ``function``."""
        sig = types.void(types.int64, types.int64, types.float64, types.float64)
        return sig, _call_by_address(None, 2)

    @intrinsic
    def _set_scalar(typingctx, function, target, value):
        """``function(target, value)``: ``cpBodySetAngularVelocity`` or ``cpSpaceStep``."""
        return types.void(types.int64, types.int64, types.float64), _call_by_address(None, 1)

else:  # pragma: no cover - exercised where numba is absent; enabled() is then False

    def _not_compiled(*args: Any) -> Any:
        raise RuntimeError("calling Chipmunk by address needs numba")

    _get_angle = _get_position = _set_velocity = _set_scalar = _not_compiled


@jit
def drive(
    handles, v_left, v_right, wl, wr, gain, lagged, sl, sr, substeps, dt, metres_per_step, axle
):
    """:func:`drive_python` compiled, on :func:`handles`' array instead of the Python calls."""
    get_position, get_angle, set_velocity, set_angular_velocity, step_space = (
        handles[0],
        handles[1],
        handles[2],
        handles[3],
        handles[4],
    )
    body, control, space = handles[5], handles[6], handles[7]
    v, w = _compiled_body_velocity(wl, wr, sl, sr, metres_per_step, axle)
    for _ in range(substeps):
        if lagged:
            wl += (v_left - wl) * gain
            wr += (v_right - wr) * gain
            v, w = _compiled_body_velocity(wl, wr, sl, sr, metres_per_step, axle)
        sin, cos = portable_math.sincos(_get_angle(get_angle, body))
        _set_velocity(set_velocity, control, v * cos, v * sin)
        _set_scalar(set_angular_velocity, control, w)
        _set_scalar(step_space, space, dt)
    x, y = _get_position(get_position, body)
    return wl, wr, x, y, _get_angle(get_angle, body)


@functools.cache
def _function_addresses() -> tuple[int, ...]:
    return tuple(int(_ffi.cast("uintptr_t", _ffi.addressof(_lib, name))) for name in _FUNCTIONS)


def available() -> bool:
    """Whether :func:`drive` can run here at all: numba, pymunk's cffi binding, a known ABI."""
    if not HAVE_NUMBA or _lib is None or sys.platform == "win32":
        return False
    return platform.machine().lower() in _MACHINES


def handles(
    body: pymunk.Body, control: pymunk.Body, space: pymunk.Space
) -> NDArray[np.int64] | None:
    """The addresses :func:`drive` takes, or None where it cannot run (:func:`available`).

    :func:`drive`'s C functions, then the Chipmunk body, control body and space behind the
    pymunk ``body``, ``control`` and ``space``, which must outlive the array (the robot holds
    both).
    """
    if not (available() and _has_pointers(body, control, space)):
        return None
    pointers = (body._body, control._body, space._space)
    objects = [int(_ffi.cast("uintptr_t", p)) for p in pointers]
    return np.array([*_function_addresses(), *objects], dtype=np.int64)


@functools.cache
def drive_entry() -> Any:
    """:func:`drive` as the robot calls it at every step, without numba's per-call dispatch.

    Its arguments' types are fixed (:func:`~delayed_rl._numba.entry_point`): the
    :func:`handles` array, five floats, a bool, two floats, the sub-step count and three floats.
    """
    return entry_point(drive, np.zeros(8, np.int64), *[0.0] * 5, False, 1.0, 1.0, 1, *[1.0] * 3)


@functools.cache
def enabled() -> bool:
    """Whether robots step with :func:`drive`: it can run, and it passed a trial.

    The trial drives two bodies like the robot's (a disc dragged by a kinematic body through a
    pivot and a gear joint), with motor lag and slip, through a few commands, one with
    :func:`drive` and one with :func:`drive_python`; they must end in the same states, bit for
    bit. The answer is cached.
    """
    if not available():
        return False
    ends = []
    for compiled in (False, True):
        space, body, control = _trial_space()
        if compiled:
            run, calls = drive, handles(body, control, space)
            if calls is None:
                return False
        else:
            run, calls = drive_python, python_calls(body, control, space)
        wl = wr = 0.0
        for left, right in _TRIAL_COMMANDS:
            end = run(calls, left, right, wl, wr, 0.3, True, 0.93, 0.98, 5, 0.016, 2e-4, 0.05)
            wl, wr = end[:2]
        ends.append(repr((end, body.velocity, body.angular_velocity)))
    return ends[0] == ends[1]


def _trial_space() -> tuple[pymunk.Space, pymunk.Body, pymunk.Body]:
    """A space like the robot's, for :func:`enabled`'s trial: ``(space, body, control)``."""
    space = pymunk.Space()
    body = pymunk.Body(0.15, 1e-4)
    body.position, body.angle = (0.3, -0.2), 1.0
    control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
    gear = pymunk.GearJoint(control, body, 0.0, 1.0)
    for joint, force in ((pivot, 1.2), (gear, 0.03)):
        joint.max_bias, joint.max_force = 0.0, force
    space.add(body, control, pivot, gear)
    return space, body, control

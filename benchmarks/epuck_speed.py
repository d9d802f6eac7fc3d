"""Random-action steps per second of EPuckLineFollow, against the bare physics in the same run.

Each configuration is driven with ``env.action_space.sample()`` (an episode end is followed by
a reset, whose cost is included), in interleaved repeats so that a slow spell of a shared
machine hits every configuration alike; the rate is printed as min – median – max over the
repeats, with the median cost of one ``action_space.sample()`` (part of every step; gymnasium's
``Box.sample`` is far slower than ``Discrete.sample``) and of a step of the same actions drawn
beforehand (the env's own cost).

The floor is what the physics alone costs per env step, measured in the same run: Chipmunk's
``cpSpaceStep`` on the robot's space, called through pymunk's cffi binding, once per physics
sub-step (4 at the default ``control_period``, 13 for the real-robot configuration).
``env/floor`` is how many times that the env's own step costs. ``--no-compiled`` turns the
compiled kernels off (as without numba) to time the numpy reference path. Run::

    python benchmarks/epuck_speed.py [--steps 2000] [--repeats 5] [--no-compiled] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import statistics
import time
from typing import Any

from interleaved import seconds_per_call
from pymunk._chipmunk_cffi import lib as chipmunk

from delayed_rl.envs.linefollow.env import REAL_ROBOT, EPuckLineFollowEnv

try:  # the compiled paths (absent before they were written: the script also times old code)
    from delayed_rl.envs.linefollow import _chipmunk, _kernels
except ImportError:
    _chipmunk = _kernels = None

#: name -> the env's arguments.
CONFIGURATIONS: dict[str, dict[str, Any]] = {
    "default (centroid, discrete)": {},
    "pixels, discrete": {"observation_mode": "pixels"},
    "centroid, continuous": {"action_mode": "continuous"},
    "pixels, continuous": {"observation_mode": "pixels", "action_mode": "continuous"},
    "EPuckLineFollowReal-v0": dict(REAL_ROBOT),
}


def steps_per_second(env: EPuckLineFollowEnv, steps: int, seed: int) -> float:
    """Random-action steps per second over ``steps`` steps from a seeded reset."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    sample, step, reset = env.action_space.sample, env.step, env.reset
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = step(sample())
        if terminated or truncated:
            reset()
    return steps / (time.perf_counter() - start)


def seconds_per_step(env: EPuckLineFollowEnv, steps: int, seed: int) -> float:
    """Seconds per step of the same random actions, drawn beforehand: the env's own cost."""
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=seed)
    step, reset = env.step, env.reset
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = step(action)
        if terminated or truncated:
            reset()
    return (time.perf_counter() - start) / steps


def space_step_floor(env: EPuckLineFollowEnv, calls: int) -> float:
    """Seconds of Chipmunk's ``cpSpaceStep`` per env step: the C solver, once per sub-step."""
    env.reset(seed=0)
    env.step(env.action_space.sample())  # the robot moves: the solver has work to do
    space, step, dt = env.robot.space._space, chipmunk.cpSpaceStep, env.robot.physics_dt
    return seconds_per_call(lambda: step(space, dt), calls) * env.physics_substeps


def summary(values: list[float]) -> str:
    """``min – median – max`` of rates."""
    return f"{min(values):8,.0f} – {statistics.median(values):8,.0f} – {max(values):8,.0f}"


def disable_compiled() -> None:
    """Make the env take its numpy and Python reference paths (as it does without numba)."""
    if _kernels is not None:
        _kernels.enabled = lambda: False  # type: ignore[assignment]
        _chipmunk.enabled = lambda: False  # type: ignore[assignment]


def compiled_paths() -> str:
    """Which paths the env takes."""
    if _kernels is None:
        return "a version without compiled paths"
    if _kernels.enabled() and _chipmunk.enabled():
        return "compiled kernels"
    return "numpy reference path"


def profile(env: EPuckLineFollowEnv, steps: int, top: int) -> str:
    """The ``top`` functions by own time over ``steps`` random-action steps."""
    profiler = cProfile.Profile()
    profiler.enable()
    steps_per_second(env, steps, seed=0)
    profiler.disable()
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).strip_dirs().sort_stats("tottime").print_stats(top)
    return out.getvalue().split("\n", 4)[-1].rstrip()


def main() -> None:
    """Time every configuration in interleaved repeats, then print rates and floors."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2_000, help="steps per timed run")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per configuration")
    parser.add_argument("--no-compiled", action="store_true", help="time the numpy reference")
    parser.add_argument("--profile", action="store_true", help="profile the default config")
    args = parser.parse_args()
    if args.no_compiled:
        disable_compiled()

    envs = {name: EPuckLineFollowEnv(**kwargs) for name, kwargs in CONFIGURATIONS.items()}
    rates: dict[str, list[float]] = {name: [] for name in envs}
    floors: dict[str, list[float]] = {name: [] for name in envs}
    samples: dict[str, list[float]] = {name: [] for name in envs}
    own: dict[str, list[float]] = {name: [] for name in envs}
    for env in envs.values():
        steps_per_second(env, 500, seed=0)  # warm up: compiled code, caches
    for repeat in range(args.repeats):
        for name, env in envs.items():
            rates[name].append(steps_per_second(env, args.steps, seed=repeat))
            floors[name].append(space_step_floor(env, 4 * args.steps))
            samples[name].append(seconds_per_call(env.action_space.sample, 1000))
            own[name].append(seconds_per_step(env, args.steps, seed=repeat))

    print(
        f"EPuckLineFollow, random actions, {args.repeats} × {args.steps:,} steps per "
        f"configuration ({compiled_paths()})"
    )
    print(
        f"{'configuration':30s} {'steps/s (min – median – max)':>34s}  {'µs/step':>7s}  "
        f"{'sample µs':>9s}  {'env µs':>6s}  {'floor µs':>8s}  {'env/floor':>9s}"
    )
    for name in envs:
        step_us = 1e6 / statistics.median(rates[name])
        sample_us = 1e6 * statistics.median(samples[name])
        own_us = 1e6 * statistics.median(own[name])
        floor_us = 1e6 * statistics.median(floors[name])
        print(
            f"{name:30s} {summary(rates[name]):>34s}  {step_us:7.1f}  {sample_us:9.1f}  "
            f"{own_us:6.1f}  {floor_us:8.1f}  {own_us / floor_us:9.1f}"
        )
    print(
        "steps/s, µs/step: with action_space.sample(); sample µs: one sample() alone; env µs: "
        "a step of the\nsame actions drawn beforehand; floor: Chipmunk's cpSpaceStep alone (via "
        "pymunk's cffi binding),\nonce per physics sub-step of an env step (all medians)"
    )
    if args.profile:
        name = next(iter(envs))
        print(f"\nWhere the time goes ({name}, {args.steps:,} steps, by own time):")
        print(profile(envs[name], args.steps, top=15))


if __name__ == "__main__":
    main()

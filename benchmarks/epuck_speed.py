"""Env steps per second of EPuckLineFollow driven by the proportional controller, profiled.

Prints the rate in both observation modes and, from a profile, where the time goes. Target:
≥ 5,000 steps/s on one core (a 150k-step training run then costs the env ≤ 30 s). Each timed
step includes the controller's ``predict``, as a training loop would include its agent. Run::

    python benchmarks/epuck_speed.py [--steps 20000] [--profile-steps 20000] [--top 15]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

from delayed_rl.agents.controllers import ProportionalController
from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv


def make(observation_mode: str) -> tuple[EPuckLineFollowEnv, ProportionalController]:
    """A continuing racetrack env in ``observation_mode`` and a P controller to drive it."""
    env = EPuckLineFollowEnv(
        "racetrack",
        observation_mode=observation_mode,
        action_mode="continuous",
        max_steps=None,
        lost_line="recover",
    )
    return env, ProportionalController(env=env)


def drive(env: EPuckLineFollowEnv, ctrl: ProportionalController, steps: int) -> float:
    """Drive ``steps`` steps from a seeded reset; return the mean reward."""
    obs, _ = env.reset(seed=0)
    state, total = None, 0.0
    for _ in range(steps):
        action, state = ctrl.predict(obs, state=state)
        obs, reward, _, _, _ = env.step(action)
        total += reward
    return total / steps


def main() -> None:
    """Time both observation modes, then profile the centroid mode."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="timed steps per mode")
    parser.add_argument("--profile-steps", type=int, default=20_000, help="0 skips the profile")
    parser.add_argument("--top", type=int, default=15, help="profile rows to print")
    args = parser.parse_args()

    print(f"EPuckLineFollow + ProportionalController, {args.steps} steps per mode")
    for mode in ("centroid", "pixels"):
        env, ctrl = make(mode)
        drive(env, ctrl, 500)  # warm up (imports, caches)
        start = time.perf_counter()
        mean_reward = drive(env, ctrl, args.steps)
        elapsed = time.perf_counter() - start
        print(
            f"  {mode:8s}: {args.steps / elapsed:8,.0f} steps/s "
            f"({1e6 * elapsed / args.steps:.0f} µs/step, mean reward {mean_reward:.3f})"
        )

    if args.profile_steps:
        env, ctrl = make("centroid")
        profile = cProfile.Profile()
        profile.enable()
        drive(env, ctrl, args.profile_steps)
        profile.disable()
        out = io.StringIO()
        stats = pstats.Stats(profile, stream=out).strip_dirs().sort_stats("tottime")
        stats.print_stats(args.top)
        print(f"\nWhere the time goes (centroid mode, {args.profile_steps} steps, by own time):")
        print(out.getvalue().split("\n", 4)[-1].rstrip())


if __name__ == "__main__":
    main()

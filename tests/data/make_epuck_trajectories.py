"""Record reference trajectories of the e-puck env, for tests/envs/test_linefollow_trajectories.py.

Each configuration below is run from a seeded reset for a fixed number of steps (an episode
end is followed by an unseeded reset, which continues the env's generator). Every reset and
every step is one row of the recording: the action taken (a filler at resets), the
observation, reward, terminated, truncated, the ``info`` entries and the robot body's velocity.
The test replays the stored actions and asserts that every row is bit-for-bit the same, so any
change to the env's numerics (an optimisation that reorders float operations, say) shows up.

The file was last produced when the env's arithmetic was made independent of the CPU (real
operations and ``delayed_rl._portable_math`` instead of numpy's complex loops and the C
library's trigonometry), so it holds on every x86-64 CPU; regenerate it only on purpose, when
the env's dynamics are meant to change::

    python tests/data/make_epuck_trajectories.py  # writes tests/data/epuck_trajectories.npz
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.envs.linefollow.camera import CENTRE_PIXEL, line_centroid

PATH = Path(__file__).with_name("epuck_trajectories.npz")

#: name -> env id, its keyword arguments, the reset seed, the steps and the policy that chose
#: the recorded actions ("random": ``action_space.sample()`` seeded with the reset seed;
#: "follow": a noisy proportional line follower, which keeps the camera on the line).
CONFIGURATIONS: dict[str, dict[str, Any]] = {
    "default-random-0": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {},
        "seed": 0,
        "steps": 1000,
        "policy": "random",
    },
    "default-random-7": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {},
        "seed": 7,
        "steps": 500,
        "policy": "random",
    },
    "default-follow-1": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"max_steps": 300},
        "seed": 1,
        "steps": 800,
        "policy": "follow",
    },
    "pixels-continuous-random-2": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"observation_mode": "pixels", "action_mode": "continuous"},
        "seed": 2,
        "steps": 1000,
        "policy": "random",
    },
    "pixels-discrete-follow-3": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"observation_mode": "pixels"},
        "seed": 3,
        "steps": 1200,
        "policy": "follow",
    },
    "continuous-follow-recover-4": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"action_mode": "continuous", "lost_line": "recover", "max_steps": None},
        "seed": 4,
        "steps": 800,
        "policy": "follow",
    },
    "real-random-5": {
        "id": "delayed_rl/EPuckLineFollowReal-v0",
        "kwargs": {},
        "seed": 5,
        "steps": 1000,
        "policy": "random",
    },
    "real-pixels-follow-recover-6": {
        "id": "delayed_rl/EPuckLineFollowReal-v0",
        "kwargs": {"observation_mode": "pixels", "lost_line": "recover", "max_steps": None},
        "seed": 6,
        "steps": 1500,
        "policy": "follow",
    },
    "real-continuous-random-8": {
        "id": "delayed_rl/EPuckLineFollowReal-v0",
        "kwargs": {"action_mode": "continuous", "lost_line": "recover", "lost_line_steps": 10},
        "seed": 8,
        "steps": 600,
        "policy": "random",
    },
    "latency-recover-random-11": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"lost_line": "recover", "lost_line_steps": 20, "command_latency": 0.03},
        "seed": 11,
        "steps": 1000,
        "policy": "random",
    },
    "figure8-follow-9": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"track": "figure8", "control_period": 0.1, "motor_lag": 0.03},
        "seed": 9,
        "steps": 1500,
        "policy": "follow",
    },
    "random-tracks-random-10": {
        "id": "delayed_rl/EPuckLineFollow-v0",
        "kwargs": {"track": "random", "lost_line_steps": 20, "max_steps": 150},
        "seed": 10,
        "steps": 400,
        "policy": "random",
    },
}


def follower(env: gym.Env, seed: int) -> Callable[[Any], Any]:
    """A proportional line follower with 10 % random actions, seeded (the "follow" policy)."""
    rng = np.random.default_rng(seed)
    discrete = isinstance(env.action_space, gym.spaces.Discrete)

    def act(obs: Any) -> Any:
        m = int(obs) if np.ndim(obs) == 0 else int(line_centroid(obs))
        error = (m - CENTRE_PIXEL) / CENTRE_PIXEL if m else 0.0  # > 0: line to the right
        if discrete:
            if rng.random() < 0.1:
                return np.int64(rng.integers(7))
            return np.int64(np.clip(round(3 + 4 * error), 0, 6))
        turn = 1.6 * error + (rng.normal(0.0, 0.3) if rng.random() < 0.1 else 0.0)
        return np.array([1.0 + min(turn, 0.0), 1.0 - max(turn, 0.0)], dtype=np.float32)

    return act


def policy(env: gym.Env, config: dict[str, Any]) -> Callable[[Any], Any]:
    """The action chooser of a configuration, given the current observation."""
    if config["policy"] == "follow":
        return follower(env, config["seed"])
    env.action_space.seed(config["seed"])
    return lambda obs: env.action_space.sample()


def record(config: dict[str, Any], choose: Callable[[Any], Any] | None = None) -> dict:
    """Run a configuration; ``choose(obs)`` picks the actions (default: its own policy).

    Returns:
        Arrays, one row per reset or step: ``kind`` (0 reset, 1 step), ``action``, ``obs``,
        ``reward``, ``terminated``, ``truncated``, the ``info`` entries and ``velocity`` (the
        body's x, y and angular velocity).
    """
    env = gym.make(config["id"], **config["kwargs"])
    choose = policy(env, config) if choose is None else choose
    rows: dict[str, list] = {key: [] for key in ROW_FIELDS}
    space = env.action_space
    filler = np.zeros(space.shape, dtype=space.dtype)

    def add(kind: int, action: Any, obs: Any, reward: float, ends: tuple, info: dict) -> None:
        rows["kind"].append(kind)
        rows["action"].append(action)
        rows["obs"].append(obs)
        rows["reward"].append(reward)
        rows["terminated"].append(ends[0])
        rows["truncated"].append(ends[1])
        for key in INFO_FIELDS:
            rows[key].append(info[key])
        body = env.unwrapped.robot.body  # rebuilt at every reset
        rows["velocity"].append((*body.velocity, body.angular_velocity))

    obs, info = env.reset(seed=config["seed"])
    add(0, filler, obs, 0.0, (False, False), info)
    for _ in range(config["steps"]):
        action = choose(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        add(1, action, obs, reward, (terminated, truncated), info)
        if terminated or truncated:
            obs, info = env.reset()
            add(0, filler, obs, 0.0, (False, False), info)
    env.close()
    return {key: np.array(value) for key, value in rows.items()}


INFO_FIELDS = (
    "line_visible",
    "centroid",
    "line_error_px",
    "lateral_error_m",
    "lap_progress",
    "wheel_speeds",
    "lost_steps",
    "recovered",
    "pose",
)
ROW_FIELDS = (
    "kind",
    "action",
    "obs",
    "reward",
    "terminated",
    "truncated",
    *INFO_FIELDS,
    "velocity",
)


def main() -> None:
    """Record every configuration into :data:`PATH`."""
    arrays: dict[str, np.ndarray] = {}
    for name, config in CONFIGURATIONS.items():
        arrays[f"{name}/config"] = np.array(json.dumps(config))
        for key, value in record(config).items():
            arrays[f"{name}/{key}"] = value
        steps = int(arrays[f"{name}/kind"].sum())
        resets = len(arrays[f"{name}/kind"]) - steps
        seen = float(arrays[f"{name}/line_visible"].mean())
        print(f"{name:30s} {steps} steps, {resets} resets, line seen {seen:.0%}")
    np.savez_compressed(PATH, **arrays)
    print(f"wrote {PATH} ({PATH.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()

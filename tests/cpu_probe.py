"""Short seeded runs whose bits must not depend on the CPU: run as a script, prints their hashes.

``python tests/cpu_probe.py [NAME ...]`` prints one JSON object mapping each run's name to the
SHA-256 of everything it produced (observations, rewards, ``info``, velocities, Q-tables, delay
estimates, every experiment's quick results). ``tests/test_cpu_independence.py`` runs it in a subprocess with numpy's SIMD loops
and numba's host-CPU code turned off and compares the hashes with the same runs in its own
process.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import re
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

import gymnasium as gym
import numpy as np

import delayed_rl  # noqa: F401  (registers the envs)
from delayed_rl.agents import (
    DeconvolutionQLearning,
    ExpectedCreditQLearning,
    FixedDelayQLearning,
    MultipleModelQLearning,
    OracleQLearning,
    QLearning,
)
from delayed_rl.delays import Poisson
from delayed_rl.wrappers import PoissonRewardDelay


class Digest:
    """A SHA-256 over values fed to it: arrays by dtype, shape and bytes, the rest as repr."""

    def __init__(self) -> None:
        self._hash = hashlib.sha256()

    def add(self, value) -> None:
        """Feed one value (recursing into dicts, lists and tuples)."""
        if isinstance(value, dict):
            for key in sorted(value, key=str):
                self.add(key)
                self.add(value[key])
        elif isinstance(value, (list, tuple)):
            self._hash.update(f"seq{len(value)}".encode())
            for item in value:
                self.add(item)
        elif isinstance(value, (np.ndarray, np.generic, float, int)) and not isinstance(
            value, bool
        ):
            array = np.ascontiguousarray(value)
            if array.dtype.hasobject:  # an int beyond int64: object arrays' bytes are addresses
                self._hash.update(f"int{value!r}".encode())
                return
            self._hash.update(f"{array.dtype.str}{array.shape}".encode())
            self._hash.update(array.tobytes())
        else:
            self._hash.update(repr(value).encode())

    def hexdigest(self) -> str:
        """The hash so far."""
        return self._hash.hexdigest()


# ---------------------------------------------------------------------- the e-puck
EPUCK_CONFIGS: dict[str, dict] = {
    "epuck-centroid-discrete": {},
    "epuck-pixels-continuous": {"observation_mode": "pixels", "action_mode": "continuous"},
    "epuck-centroid-continuous": {"action_mode": "continuous"},
    "epuck-pixels-discrete-noisy": {
        "observation_mode": "pixels",
        "wheel_slip": 0.1,
        "motor_lag": 0.3,
        "camera_noise": 0.05,
        "lost_line": "recover",
    },
    "epuck-figure-eight": {"track": "figure8"},
    "epuck-random-track": {"track": "random", "track_seed": 5, "lost_line": "recover"},
    "epuck-latency-contrast": {"command_latency": 0.05, "line_contrast": 0.8, "track": "oval"},
}


def epuck_run(kwargs: dict, steps: int = 80, seed: int = 3) -> str:
    """Random actions on the e-puck: every output of every step, and the body's velocities."""
    env = gym.make("delayed_rl/EPuckLineFollow-v0", **kwargs)
    env.action_space.seed(seed)
    digest = Digest()
    obs, info = env.reset(seed=seed)
    digest.add((obs, info))
    robot = env.unwrapped
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        digest.add((obs, reward, terminated, truncated, info))
        digest.add(_velocities(robot))
        if terminated or truncated:
            obs, info = env.reset()
            digest.add((obs, info))
    env.close()
    return digest.hexdigest()


def _velocities(env) -> tuple:
    body = env.robot.body
    return (tuple(body.velocity), body.angular_velocity, tuple(body.position), body.angle)


# ---------------------------------------------------------------------- the agents
def _grid(seed_lam: float = 3.0, record: bool = False) -> gym.Env:
    return PoissonRewardDelay(
        gym.make("delayed_rl/GridWorld-5x5-v0"), lam=seed_lam, max_delay=20, record_arrivals=record
    )


PROBES: dict[str, Callable[[gym.Env], object]] = {
    "q": lambda env: QLearning(env, q_init=5.0, seed=1),
    "fixed": lambda env: FixedDelayQLearning(env, delay_estimate=3, q_init=5.0, seed=1),
    "mmq": lambda env: MultipleModelQLearning(env, max_delay_estimate=8, q_init=5.0, seed=1),
    "expected-credit": lambda env: ExpectedCreditQLearning(
        env, delay=Poisson(3.0), max_delay_estimate=20, q_init=5.0, seed=1
    ),
    "oracle": lambda env: OracleQLearning(env, q_init=5.0, seed=1),
    "deconv-known": lambda env: DeconvolutionQLearning(
        env, delay=Poisson(3.0), max_delay_estimate=20, solve_interval=1500, q_init=5.0, seed=1
    ),
    "deconv-learned": lambda env: DeconvolutionQLearning(
        env, max_delay_estimate=20, solve_interval=1500, q_init=5.0, seed=1
    ),
}


def agent_run(name: str, compiled: bool, steps: int = 6000) -> str:
    """Train one agent briefly on a delayed 5×5 grid world; hash its learned arrays."""
    env = _grid(record=name == "oracle")
    agent = PROBES[name](env)
    agent.learn(steps, compiled=compiled)
    digest = Digest()
    digest.add(agent.q_table)
    for attribute in ("delay_pmf", "reward_model", "mean_delay"):
        value = getattr(agent, attribute, None)
        if value is not None:
            digest.add(value)
    digest.add(agent.predict(np.arange(25), deterministic=True)[0])
    return digest.hexdigest()


def taxi_deconv_run(steps: int = 4000) -> str:
    """DeconvQ with the delay learned on Taxi: 3000 pairs, the hashed statistics and CG solves."""
    env = PoissonRewardDelay(gym.make("Taxi-v4"), lam=2.0, max_delay=10)
    agent = DeconvolutionQLearning(env, max_delay_estimate=10, solve_interval=2000, seed=4)
    agent.learn(steps, compiled=False)
    digest = Digest()
    for value in (agent.q_table, agent.delay_pmf, agent.reward_model):
        digest.add(value)
    return digest.hexdigest()


def epuck_agent_run(compiled: bool, steps: int = 1500) -> str:
    """MMQ on the delayed e-puck line follower, on either training path."""
    env = gym.make("delayed_rl/EPuckLineFollow-v0", reward_delay=20)
    agent = MultipleModelQLearning(env, max_delay_estimate=30, q_init=1.0, seed=2)
    agent.learn(steps, compiled=compiled)
    digest = Digest()
    digest.add(agent.q_table)
    digest.add(_velocities(env.unwrapped))
    return digest.hexdigest()


#: Keys of an experiment's ``summary.json`` that hold timings, not results.
TIMINGS = re.compile(r"ns_per_step|seconds|wall_time")


RECORDED_KEYS = {"lambda_max": "max_delay_estimate"}
"""Summary keys renamed after the fingerprints were recorded, ``{recorded: current}`` (as
``seeded_runs.RECORDED_NAMES``): a key is hashed under its recorded name, so that a rename alone
(CHANGELOG.md) changes no fingerprint while a changed value still does."""
_RECORDED_AS = {current: recorded for recorded, current in RECORDED_KEYS.items()}


def _without_timings(value):
    if isinstance(value, dict):
        return {
            _RECORDED_AS.get(k, k): _without_timings(v)
            for k, v in value.items()
            if not TIMINGS.search(k)
        }
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def experiments_run() -> str:
    """``delayed-rl bench all --quick``: every experiment's curves and summary, less timings."""
    from delayed_rl.cli import main

    digest = Digest()
    with tempfile.TemporaryDirectory() as out, contextlib.redirect_stdout(io.StringIO()):
        assert main(["bench", "all", "--quick", "--workers", "1", "--out", out]) == 0
        for path in sorted(Path(out).glob("*/curves.csv")) + sorted(Path(out).glob("*/*.json")):
            digest.add(path.relative_to(out).as_posix())
            if path.suffix == ".json":
                digest.add(_without_timings(json.loads(path.read_text())))
            else:
                digest.add(path.read_text())
    return digest.hexdigest()


def runs() -> dict[str, Callable[[], str]]:
    """Every probe run by name."""
    table: dict[str, Callable[[], str]] = {
        name: (lambda kwargs=kwargs: epuck_run(kwargs)) for name, kwargs in EPUCK_CONFIGS.items()
    }
    for name in PROBES:
        for compiled in (False, True):
            path = "compiled" if compiled else "python"
            table[f"{name}-{path}"] = lambda name=name, compiled=compiled: agent_run(name, compiled)
    table["taxi-deconv-learned-python"] = taxi_deconv_run
    table["experiments-quick"] = experiments_run
    for compiled in (False, True):
        path = "compiled" if compiled else "python"
        table[f"epuck-mmq-{path}"] = lambda compiled=compiled: epuck_agent_run(compiled)
    return table


def hashes(names: Iterable[str] | None = None) -> dict[str, str]:
    """The hash of each named run (all of them by default)."""
    table = runs()
    return {name: table[name]() for name in (names or table)}


if __name__ == "__main__":
    json.dump(hashes(sys.argv[1:] or None), sys.stdout, indent=1)
    print()

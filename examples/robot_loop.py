"""A robot-style loop: you step the world yourself and hand each transition to ``update()``.

A real robot has no ``learn()``: its control loop reads the sensor, picks an action, waits for
the next reading and the (delayed) reward, and learns from that one transition. Here the "robot"
is the simulated e-puck with Poisson(90) reward delays (the thesis's line-following task); the
agent is MMQ with λ̂max = 150, as in the thesis, driving it through ``predict`` and ``update``.

Run::

    python examples/robot_loop.py [--steps 20000]
"""

from __future__ import annotations

import argparse

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.agents import MultipleModelQLearning


def main() -> None:
    """Drive the e-puck for ``--steps`` control periods, learning online."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    args = parser.parse_args()
    robot = gym.make(
        "delayed_rl/EPuckLineFollow-v0", reward_delay=90, lost_line="recover", max_steps=None
    )
    agent = MultipleModelQLearning(
        robot, max_delay_estimate=150, q_init=10.0, seed=0, exploration_fraction=0.5
    )
    obs, _ = robot.reset(seed=0)
    earned = 0.0
    for step in range(args.steps):
        action, _ = agent.predict(obs)  # ε-greedy, as during training
        next_obs, reward, terminated, truncated, info = robot.step(action)
        agent.update(obs, action, reward, next_obs, terminated, truncated)  # one transition
        earned += info["undelayed_reward"]
        obs = next_obs if not (terminated or truncated) else robot.reset()[0]
        if (step + 1) % max(1, args.steps // 4) == 0:
            print(f"step {step + 1}: average reward so far {earned / (step + 1):+.3f}")


if __name__ == "__main__":
    main()

"""The ``delayed-rl`` command line: ``delayed-rl list`` shows what the library provides."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import gymnasium as gym

import delayed_rl
from delayed_rl.envs import env_ids


def _list(args: argparse.Namespace) -> int:
    print("Environments (gymnasium.make(id, reward_delay=λ) adds a Poisson reward delay):")
    for env_id in env_ids():
        print(f"  {env_id}")
    agents = [
        name
        for name in ("QLearning", "FixedDelayQLearning", "MultipleModelQLearning")
        if hasattr(delayed_rl, name)
    ]
    if agents:
        print("Agents:")
        for name in agents:
            print(f"  {name}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``delayed-rl`` (one sub-command per job)."""
    parser = argparse.ArgumentParser(
        prog="delayed-rl",
        description="Stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning.",
    )
    parser.add_argument("--version", action="version", version=delayed_rl.__version__)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    listing = commands.add_parser("list", help="list the registered envs and the agents")
    listing.set_defaults(run=_list)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``delayed-rl`` with ``argv`` (default: the process's arguments); return the exit code."""
    args = build_parser().parse_args(argv)
    gym.logger.min_level = 40  # keep Gymnasium's warnings out of command output
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())

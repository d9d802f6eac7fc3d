"""The ``delayed-rl`` command line.

- ``delayed-rl list``: the envs, agents and experiments;
- ``delayed-rl bench NAME``: one thesis experiment over seeds, written to ``--out/NAME``;
- ``delayed-rl reproduce``: every experiment.

Exit codes: 0 success, 2 bad usage (unknown names, bad values), 1 a failure while running.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym

import delayed_rl
from delayed_rl.envs import env_ids
from delayed_rl.experiments import NAMES
from delayed_rl.experiments.runner import BACKENDS


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
    print("Experiments (delayed-rl bench NAME):")
    for name in NAMES:
        print(f"  {name}")
    return 0


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _bench(args: argparse.Namespace) -> int:
    from delayed_rl.experiments import Config, get_experiment, run_experiment

    names = list(NAMES) if args.name == "all" else [args.name]
    for name in names:
        config = Config(seeds=args.seeds, steps=args.steps, quick=args.quick,
                        workers=args.workers, backend=args.backend, base_seed=args.seed)  # fmt: skip
        out = Path(args.out) / name
        summary = run_experiment(get_experiment(name), config, out)
        print((out / "report.md").read_text())
        print(f"[{name}] wrote {out} in {summary.extra['wall_time_s']} s")
    return 0


def _add_bench_options(parser: argparse.ArgumentParser, default_out: str) -> None:
    parser.add_argument("--seeds", type=_positive_int, default=None,
                        help="runs per condition (default: the thesis's, or 2 with --quick)")  # fmt: skip
    parser.add_argument("--steps", type=_positive_int, default=None,
                        help="training steps per run (default: the thesis's)")  # fmt: skip
    parser.add_argument("--workers", type=_positive_int, default=1, help="parallel processes")
    parser.add_argument("--backend", choices=BACKENDS, default="loky",
                        help="joblib backend: loky (default), ray or dask")  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    parser.add_argument("--quick", action="store_true", help="a scaled-down run, in seconds")


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
    bench = commands.add_parser("bench", help="run one thesis experiment over seeds")
    bench.add_argument("name", choices=NAMES, help="the experiment")
    _add_bench_options(bench, "runs")
    bench.set_defaults(run=_bench)
    reproduce = commands.add_parser("reproduce", help="run every thesis experiment")
    _add_bench_options(reproduce, "runs")
    reproduce.set_defaults(run=_bench, name="all")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``delayed-rl`` with ``argv`` (default: the process's arguments); return the exit code."""
    args = build_parser().parse_args(argv)
    gym.logger.min_level = 40  # keep Gymnasium's warnings out of command output
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())

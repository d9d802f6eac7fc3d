"""The ``delayed-rl`` command line.

- ``delayed-rl list``: the envs, agents and experiments;
- ``delayed-rl train``: train a tabular agent on an env (optionally reward-delayed) and save it;
- ``delayed-rl evaluate``: run a saved agent greedily and report its average reward;
- ``delayed-rl bench NAME [NAME ...]``: experiments over seeds, each written to ``--out/NAME``
  (``all``: every experiment but the long ones; ``--long`` adds them);
- ``delayed-rl sweep FILE``: your own agents × envs × delays × seeds, from a YAML or JSON file
  (:mod:`delayed_rl.sweep` documents the file), written to ``--out``.

:func:`main` gives the exit codes; option values are checked by :mod:`delayed_rl._validation`,
so the command line and the Python API refuse the same values with the same words.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import time
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym

import delayed_rl
from delayed_rl._validation import Limit, check_int, check_limit, check_real
from delayed_rl.agents.common.hyperparameters import (
    DEFAULTS,
    HYPERPARAMETER_CHECKS,
    MAX_SEED_VALUE,
)
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.agents.registry import REGISTRY, option_flag
from delayed_rl.delays import Poisson
from delayed_rl.envs import env_ids
from delayed_rl.experiments import DEFAULT_NAMES, LONG_NAMES, NAMES
from delayed_rl.parallel.pools import BACKENDS, MAX_SEED_COUNT, check_workers
from delayed_rl.sweep.runs import MAX_EVAL_EPISODE_STEPS, EpisodeTooLong, greedy_rollout
from delayed_rl.sweep.schema import (
    MAX_EVAL_EPISODES,
    MAX_EVAL_STEPS,
    Evaluation,
    env_id_hint,
)

#: The name :func:`_checked` gives the library's checks, cut from their messages again: argparse
#: already names the option (``argument --steps: must be an integer >= 1, got 0``).
_VALUE = "value"


def _checked(kind: type, check: Callable[..., Any], *bounds: Any) -> Callable[[str], Any]:
    """An argparse ``type``: the text read as ``kind``, then checked by ``check``.

    Args:
        kind: ``int`` or ``float``, what the text is read as.
        check: one of :mod:`delayed_rl._validation`'s checks, e.g. ``check_int``.
        *bounds: ``check``'s arguments after the value, e.g. the lower bound.

    Returns:
        The parser of the option's text. Text that does not read as ``kind`` reaches ``check``
        as the string itself, which it refuses with a ``TypeError``; a value out of range it
        refuses with a ``ValueError``. Both become an ``argparse.ArgumentTypeError`` with the
        check's message, so argparse prints it and exits with code 2.
    """

    def parse(text: str) -> Any:
        try:
            value: Any = kind(text)
        except ValueError:
            value = text
        try:
            return check(_VALUE, value, *bounds)
        except (TypeError, ValueError) as error:
            raise argparse.ArgumentTypeError(str(error).removeprefix(f"{_VALUE} ")) from None

    parse.__name__ = kind.__name__
    return parse


def _limited(low: int, limit: Limit) -> Callable[[str], int]:
    """An argparse ``type``: an integer ``>= low`` and at most ``limit`` (named in the message)."""

    def check(name: str, value: Any) -> int:
        return check_limit(name, check_int(name, value, low), limit)

    return _checked(int, check)


def _hyperparameter(name: str) -> Callable[[str], float]:
    """An argparse ``type``: a number, checked as the agents check the hyper-parameter ``name``."""
    return _checked(float, HYPERPARAMETER_CHECKS[name])


_poisson_mean = _checked(float, check_real, 0.0, Poisson.MAX_LAM)
_non_negative_int = _checked(int, check_int, 0)
_positive_int = _checked(int, check_int, 1)
_steps = _limited(1, MAX_TIMESTEPS)
_seeds = _limited(1, MAX_SEED_COUNT)
_seed = _limited(0, MAX_SEED_VALUE)
_workers = _checked(int, check_workers)
_eval_steps = _limited(1, MAX_EVAL_STEPS)
_eval_episodes = _limited(1, MAX_EVAL_EPISODES)

#: ``--agent`` choices: the agent class for each (the registry's agents whose options ``train``
#: has: :attr:`~delayed_rl.agents.registry.AgentEntry.train_options`).
TRAIN_AGENTS = {key: e.class_name for key, e in REGISTRY.items() if e.train_options is not None}
#: How many episodes ``evaluate`` runs when given neither ``--episodes`` nor ``--steps``.
EPISODES = 10


class CommandError(Exception):
    """A failure while running a command: reported as ``error: ...`` with exit code 1."""


#: What a command may fail with, reported as one ``error:`` line and exit code 1 (a corrupt file
#: or a request too large for the machine included: ``zlib.error``, ``MemoryError``, ...; a
#: missing extra: ``ImportError``).
FAILURES = (
    CommandError,
    ImportError,
    OSError,
    ValueError,
    TypeError,
    RuntimeError,
    OverflowError,
    MemoryError,
    zlib.error,
    gym.error.Error,
)


def _one_line(error: BaseException) -> str:
    """``error`` as the text of one ``error:`` line."""
    text = " ".join(str(error).split()) or type(error).__name__
    if isinstance(error, MemoryError):
        return f"out of memory: {text}"
    return text


def _list(args: argparse.Namespace) -> int:
    """``delayed-rl list``: print the registered envs, the agents and the experiments."""
    print("Environments (gymnasium.make(id, reward_delay=λ) adds a Poisson reward delay):")
    for env_id in env_ids():
        print(f"  {env_id}")
    print("Agents (delayed-rl train --agent KEY, or a sweep file's agents[].name):")
    for key, entry in REGISTRY.items():
        if key in TRAIN_AGENTS:
            flags = [f"--agent {key}"] + [
                option_flag(option) + (" required" if option in entry.train_required else "")
                for option in entry.train_options
            ]
            where = f" (train: {', '.join(flags)})"
        else:
            where = " (sweeps and Python; not train)"
        print(f"  {key}: {entry.class_name}, {entry.description}{where}")
    print("Experiments (delayed-rl bench NAME):")
    for name in NAMES:
        print(f"  {name}")
    return 0


def _env_id(text: str) -> str:
    """An argparse ``type``: a registered Gymnasium id (or ``module:Id``, imported on make)."""
    hint = env_id_hint(text)
    if hint is None:
        return text
    raise argparse.ArgumentTypeError(f"unknown env id {text!r}{hint}")


def _make_env(env_id: str, reward_delay: float | None) -> gym.Env:
    """``gym.make(env_id)``, behind a Poisson(``reward_delay``) reward delay when one is given."""
    try:
        env = gym.make(env_id)
    except (gym.error.Error, ImportError, TypeError, ValueError) as error:
        raise CommandError(f"cannot make env {env_id!r}: {error}") from None
    if reward_delay is None:
        return env
    from delayed_rl.wrappers import PoissonRewardDelay

    return PoissonRewardDelay(env, reward_delay)


def _delay_text(reward_delay: float | None) -> str:
    """How the reports name the reward delay of ``--reward-delay``."""
    return "undelayed" if reward_delay is None else f"Poisson reward delay λ = {reward_delay:g}"


def _train(args: argparse.Namespace) -> int:
    """``delayed-rl train``: train the agent, save it, report its average reward."""
    from delayed_rl import agents

    env = _make_env(args.env, args.reward_delay)
    options: dict[str, Any] = {
        "learning_rate": args.learning_rate,
        "gamma": args.gamma,
        "exploration_initial_eps": args.epsilon,
        "exploration_final_eps": args.epsilon,
        "q_init": args.q_init,
        "seed": args.seed,
    }
    for option in REGISTRY[args.agent].train_options:
        options[option] = getattr(args, option)
    save = Path(args.save)
    try:  # fail before training, not after, when the model cannot be written there
        save.parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise CommandError(f"cannot create the folder of --save {save}: {error}") from None
    try:
        agent = getattr(agents, TRAIN_AGENTS[args.agent])(env, **options)
    except (TypeError, ValueError) as error:
        raise CommandError(
            f"cannot train {TRAIN_AGENTS[args.agent]} on {args.env}: {error}"
        ) from None
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    started = time.perf_counter()
    agent.learn(args.steps, log_interval=None, progress_bar=progress)
    seconds = time.perf_counter() - started
    average = agent.logger.dumps[-1]["rollout/undelayed_reward_per_step"]
    try:
        written = agent.save(save)
    except OSError as error:
        raise CommandError(f"cannot save the model to {save}: {error}") from None
    print(
        f"trained {TRAIN_AGENTS[args.agent]} on {args.env} ({_delay_text(args.reward_delay)}) for "
        f"{args.steps} steps in {seconds:.1f} s: average undelayed reward {average:.4f} per "
        f"step; saved to {written}"
    )
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    """``delayed-rl evaluate``: run a saved agent greedily, report its average reward."""
    from delayed_rl.agents import load_agent

    env = _make_env(args.env, args.reward_delay)
    agent = load_agent(args.path, env)  # its errors name the file and the problem
    obs, _ = env.reset(seed=args.seed)
    if args.steps is not None:
        length = Evaluation("step", args.steps)
    else:
        length = Evaluation("episode", EPISODES if args.episodes is None else args.episodes)
    try:
        run = greedy_rollout(agent, env, obs, length, args.max_eval_episode_steps)
    except EpisodeTooLong:
        raise CommandError(
            f"no episode of {args.env} ended within {args.max_eval_episode_steps} steps: it looks "
            "like a continuing task; evaluate it with --steps N"
        ) from None
    env.close()
    returns = run.returns
    per_episode = (
        f"{sum(returns) / len(returns):.4f} per episode over {len(returns)} episode(s)"
        if returns
        else "no episode ended"
    )
    print(
        f"evaluated {type(agent).__name__} from {args.path} greedily on {args.env} "
        f"({_delay_text(args.reward_delay)}) for {run.steps} steps: average undelayed reward "
        f"{run.total / run.steps:.4f} per step; {per_episode}"
    )
    return 0


def _bench(args: argparse.Namespace) -> int:
    """``delayed-rl bench NAME [NAME ...]``: run experiments, write and print their reports.

    The experiments run together on one pool of workers
    (:func:`~delayed_rl.experiments.run_experiments`): each prints its report as it finishes.
    ``all`` names every experiment but the long ones
    (:data:`~delayed_rl.experiments.LONG_NAMES`), which ``--long`` adds. With more than one
    experiment, an index of them all is written to ``--out/index.md``.
    """
    from delayed_rl.experiments import Config, get_experiment, run_experiments

    if args.long and "all" not in args.names:
        args.parser.error("--long adds the long experiments to 'all': name 'all' with it")
    every = list(NAMES if args.long else DEFAULT_NAMES)
    names = list(
        dict.fromkeys(n for name in args.names for n in (every if name == "all" else [name]))
    )
    config = Config(
        seeds=args.seeds,
        steps=args.steps,
        quick=args.quick,
        workers=args.workers,
        backend=args.backend,
        base_seed=args.base_seed,
    )
    out = Path(args.out)

    def report(experiment: Any, summary: Any) -> None:
        print((out / experiment.name / "report.md").read_text())
        print(
            f"[{experiment.name}] wrote {out / experiment.name} after "
            f"{summary.extra['wall_time_s']} s ({summary.extra['run_seconds']} core-seconds)"
        )

    started = time.perf_counter()
    experiments = [get_experiment(name) for name in names]
    summaries = run_experiments(experiments, config, out, _bench_progress(args), report)
    if len(experiments) > 1:
        from delayed_rl.experiments.framework.report import write_index

        ran = list(zip(experiments, summaries, strict=True))
        index = write_index(out, ran, time.perf_counter() - started)
        print(f"[bench] wrote {index}")
    return 0


def _bench_progress(args: argparse.Namespace) -> bool:
    """Whether ``bench`` shows its progress (``--progress``/``--no-progress``).

    By default, when stderr is a terminal and tqdm (optional: the ``dev`` extra) can draw the
    bar; an explicit ``--progress`` without tqdm shows a plain count instead (as ``train``
    shows a plain bar).
    """
    if args.progress is not None:
        return args.progress
    from delayed_rl.parallel.progress import tqdm_installed

    return sys.stderr.isatty() and tqdm_installed()


def _sweep(args: argparse.Namespace) -> int:
    """``delayed-rl sweep FILE``: run the file's runs that ``--out`` lacks; print the summary."""
    from delayed_rl.sweep import load_sweep, run_sweep

    if args.address is not None and args.backend == "loky":
        args.parser.error("--address is for --backend ray or dask")
    try:
        sweep = load_sweep(args.file)
    except (TypeError, ValueError) as error:  # what the file says is wrong: bad usage
        args.parser.error(_one_line(error))
    out = Path("runs") / Path(args.file).stem if args.out is None else Path(args.out)
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    outcome = run_sweep(sweep, out, args.workers, args.backend, args.address, progress)
    print((out / "summary.md").read_text(encoding="utf-8"))
    print(
        f"[sweep] ran {outcome.ran} of {outcome.runs} runs ({outcome.skipped} already in "
        f"{out / 'results.csv'}) in {outcome.wall_s} s; wrote {out}"
    )
    return 0


def _add_bench_options(parser: argparse.ArgumentParser, default_out: str) -> None:
    """``bench``'s options: seeds, steps, workers, output, progress."""
    parser.add_argument(
        "--seeds",
        type=_seeds,
        default=None,
        help="runs per condition (default: the experiment's, or 2 with --quick)",
    )
    parser.add_argument(
        "--steps",
        type=_steps,
        default=None,
        help="training steps per run (default: the thesis's)",
    )
    parser.add_argument("--workers", type=_workers, default=1, help="parallel processes")
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="loky",
        help="joblib backend: loky (default), ray or dask",
    )
    parser.add_argument(
        "--base-seed",
        type=_seed,
        default=0,
        help="the first run's seed, >= 0; the others count up from it (default 0)",
    )
    parser.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    parser.add_argument("--quick", action="store_true", help="a scaled-down run, in seconds")
    parser.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="show a progress bar on stderr: the runs done out of the total, the time elapsed "
        "and the time left (default: when stderr is a terminal and tqdm is installed; without "
        "tqdm, --progress prints a line per finished run)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``delayed-rl`` (one sub-command per job)."""
    parser = argparse.ArgumentParser(
        prog="delayed-rl",
        description="Stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning.",
    )
    parser.add_argument("--version", action="version", version=delayed_rl.__version__)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_list_command(commands)
    _add_train_command(commands)
    _add_evaluate_command(commands)
    _add_bench_command(commands)
    _add_sweep_command(commands)
    return parser


def _add_list_command(commands: Any) -> None:
    """The ``list`` sub-command's parser."""
    listing = commands.add_parser(
        "list", help="list the registered envs, the agents and the experiments"
    )
    listing.set_defaults(run=_list)


def _add_train_command(commands: Any) -> None:
    """The ``train`` sub-command's parser."""
    train = commands.add_parser(
        "train",
        help="train a tabular agent and save it",
        description="Train a tabular agent (--agent) on a Gymnasium env with Discrete spaces "
        "(optionally behind a Poisson reward delay), save the agent and print its average "
        "undelayed reward per step during training.",
    )
    train.add_argument(
        "--env",
        required=True,
        type=_env_id,
        help="a registered env id, e.g. delayed_rl/GridWorld-3x3-v0",
    )
    train.add_argument(
        "--agent",
        required=True,
        choices=TRAIN_AGENTS,
        help="; ".join(f"{key}: {REGISTRY[key].description}" for key in TRAIN_AGENTS),
    )
    train.add_argument(
        "--reward-delay",
        type=_poisson_mean,
        metavar="λ",
        help="delay rewards by Poisson(λ) steps (default: undelayed)",
    )
    train.add_argument(
        "--steps", type=_steps, default=100_000, help="training steps (default 100000)"
    )
    _add_agent_options(train)
    train.add_argument(
        "--seed",
        type=_seed,
        default=None,
        help="seeds the agent and the env (default: unseeded)",
    )
    train.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="show a progress bar (default: when stderr is a terminal)",
    )
    train.add_argument(
        "--save",
        required=True,
        metavar="PATH",
        help="where to save the agent (.npz appended when PATH has no suffix)",
    )
    train.set_defaults(run=_train, parser=train)


def _add_agent_options(train: argparse.ArgumentParser) -> None:
    """``train``'s hyper-parameter options: α, γ, ε, the initial Q-value and the delays."""
    train.add_argument(
        "--learning-rate",
        type=_hyperparameter("learning_rate"),
        default=DEFAULTS.learning_rate,
        help=f"α in (0, 1] (default {DEFAULTS.learning_rate:g})",
    )
    train.add_argument(
        "--gamma",
        type=_hyperparameter("gamma"),
        default=DEFAULTS.gamma,
        help=f"discount factor in [0, 1] (default {DEFAULTS.gamma:g})",
    )
    train.add_argument(
        "--epsilon",
        type=_hyperparameter("exploration_final_eps"),
        default=DEFAULTS.exploration_final_eps,
        help=f"constant ε of ε-greedy exploration (default {DEFAULTS.exploration_final_eps:g})",
    )
    train.add_argument(
        "--q-init",
        type=_hyperparameter("q_init"),
        default=DEFAULTS.q_init,
        help="initial Q-value; above the true values explores optimistically "
        f"(default {DEFAULTS.q_init:g})",
    )
    train.add_argument(
        "--delay-estimate",
        type=_non_negative_int,
        metavar="STEPS",
        help=f"--agent {_takers('delay_estimate')}: the constant delay in steps that it assumes",
    )
    train.add_argument(
        "--max-delay-estimate",
        type=_non_negative_int,
        metavar="N",
        help=f"--agent {_takers('max_delay_estimate')}: the longest delay the agent models "
        "(MMQ's λ̂max, the end of a learned pmf; default 50)",
    )


def _add_evaluate_command(commands: Any) -> None:
    """The ``evaluate`` sub-command's parser."""
    evaluate = commands.add_parser(
        "evaluate",
        help="run a saved agent greedily and report its average reward",
        description="Load an agent saved by `delayed-rl train` (or agent.save), run its greedy "
        "policy without learning, and print the average undelayed reward per step and per "
        "episode. Continuing envs (whose episodes never end, like the grid worlds) need --steps.",
    )
    evaluate.add_argument("path", help="the saved model file")
    evaluate.add_argument(
        "--env", required=True, type=_env_id, help="the env id (its spaces must match the model's)"
    )
    evaluate.add_argument(
        "--reward-delay",
        type=_poisson_mean,
        metavar="λ",
        help="delay rewards by Poisson(λ) steps (the reported reward is the "
        "undelayed one either way)",
    )
    length = evaluate.add_mutually_exclusive_group()
    length.add_argument(
        "--episodes",
        type=_eval_episodes,
        default=None,
        help=f"run this many episodes (default {EPISODES})",
    )
    length.add_argument(
        "--steps",
        type=_eval_steps,
        default=None,
        help="run this many steps (for continuing envs)",
    )
    evaluate.add_argument(
        "--max-eval-episode-steps",
        type=_eval_steps,
        default=MAX_EVAL_EPISODE_STEPS,
        help="with --episodes: fail when an episode runs longer than this, as a continuing "
        f"env's would (default {MAX_EVAL_EPISODE_STEPS}; not a time limit on the env)",
    )
    evaluate.add_argument(
        "--seed",
        type=_seed,
        default=None,
        help="seeds the env's first reset (default: unseeded)",
    )
    evaluate.set_defaults(run=_evaluate)


def _add_bench_command(commands: Any) -> None:
    """The ``bench`` sub-command's parser."""
    bench = commands.add_parser(
        "bench",
        help="run experiments (the thesis's or beyond it, `delayed-rl list` names them) over seeds",
        description="Run the named experiments over seeds on one pool of workers, write each "
        "one's report, curves, summary and figures to --out/NAME and print its report. 'all' "
        "names every experiment but the long ones, which --long adds.",
    )
    bench.add_argument(
        "names",
        nargs="+",
        choices=(*NAMES, "all"),
        metavar="NAME",
        help=f"an experiment ({', '.join(NAMES)}), or all",
    )
    _add_bench_options(bench, "runs")
    bench.add_argument(
        "--long",
        action="store_true",
        help=f"with all: the long experiments too ({', '.join(LONG_NAMES)}; they need the sb3 "
        "and multiagent extras)",
    )
    bench.set_defaults(run=_bench, parser=bench)


def _add_sweep_command(commands: Any) -> None:
    """The ``sweep`` sub-command's parser."""
    sweep = commands.add_parser(
        "sweep",
        help="run your own agents × envs × delays × seeds, from a YAML or JSON file",
        description="Train every agent of FILE on every env under every delay for every seed, "
        "evaluate each greedily, and write results.csv (one row per run), summary.csv, "
        "summary.md and one figure per env into --out. A rerun with the same --out runs only "
        "what its results.csv lacks. The file's fields are documented in "
        "delayed_rl.sweep; examples/sweep.yaml is a commented example.",
    )
    sweep.add_argument(
        "file",
        metavar="FILE",
        help="the sweep file: .yaml or .yml (needs the sweep extra, PyYAML), or .json",
    )
    sweep.add_argument(
        "--out",
        metavar="DIR",
        help="the output folder; a results.csv there is resumed (default: runs/NAME, NAME the "
        "file's name without its suffix)",
    )
    sweep.add_argument(
        "--workers",
        type=_workers,
        metavar="N",
        help="runs at once (default: 1 with loky, in this process; every core of the cluster "
        "with ray or dask)",
    )
    sweep.add_argument(
        "--backend",
        choices=BACKENDS,
        default="loky",
        help="where the runs go: loky (default: joblib's processes on this machine), ray or dask",
    )
    sweep.add_argument(
        "--address",
        metavar="ADDR",
        help="a running cluster to use: for ray, ray.init(address=ADDR), e.g. auto or "
        "ray://HOST:10001; for dask, its scheduler, e.g. tcp://HOST:8786 (default: a local "
        "one, started for the sweep)",
    )
    sweep.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="show a progress bar on stderr (default: when stderr is a terminal)",
    )
    sweep.set_defaults(run=_sweep, parser=sweep)


def _check_train_arguments(args: argparse.Namespace) -> None:
    """Refuse bad ``train`` values as bad usage (exit 2), before training rather than after.

    A ``--save`` with no file name (``""``, ``"."``).
    """
    from delayed_rl.agents.common.save_util import check_model_path

    try:
        check_model_path(args.save)
    except (TypeError, ValueError) as error:
        args.parser.error(f"argument --save: {str(error).removeprefix('path ')}")


def _takers(option: str) -> str:
    """The ``train`` agents that take ``option``, as ``"mmq or deconv"``."""
    return " or ".join(key for key in TRAIN_AGENTS if option in REGISTRY[key].train_options)


def _check_agent_options(args: argparse.Namespace) -> None:
    """Refuse an agent option given to an agent that does not take it, or one missing (usage)."""
    for option in REGISTRY[args.agent].train_required:
        if getattr(args, option) is None:
            args.parser.error(f"--agent {args.agent} needs {option_flag(option)}")
    for option in sorted({o for key in TRAIN_AGENTS for o in REGISTRY[key].train_options}):
        if getattr(args, option) is not None and option not in REGISTRY[args.agent].train_options:
            args.parser.error(
                f"{option_flag(option)} is for --agent {_takers(option)}, not --agent {args.agent}"
            )


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``delayed-rl`` with ``argv`` (default: the process's arguments); return the exit code.

    0 success; 2 bad usage (unknown names, bad values, in options or in a sweep file's fields
    or syntax: argparse's usage and one ``error:`` line); 1 a failure while running (a missing,
    corrupt or oversized model file, a missing sweep file, an env the agent cannot use, tables
    over ``delayed_rl.agents.common.q_table.MAX_TABLE_BYTES``, a sweep's run that fails,
    running out of memory, ...), reported as one ``error: ...`` line on stderr, without a
    traceback; 130 after Ctrl-C (a second Ctrl-C quits at once, see :func:`console`).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "train":
        _check_agent_options(args)
        _check_train_arguments(args)
    level, gym.logger.min_level = gym.logger.min_level, 40  # Gymnasium's warnings stay out
    try:
        return args.run(args)
    except FAILURES as error:
        print(f"error: {_one_line(error)}", file=sys.stderr)
        return 1
    finally:
        gym.logger.min_level = level  # main() may be called from a program: leave it as it was


def console() -> int:
    """The ``delayed-rl`` command: :func:`main`, with Ctrl-C as a terminal user expects it.

    The first Ctrl-C stops the run as Python does (``KeyboardInterrupt``: the worker pools are
    stopped, the files already written stay) and the command exits with status 130; a second
    one kills the worker processes and quits at once. Without that, a second Ctrl-C while
    Python shuts the worker pools down could leave the process waiting forever for them.

    It is the command's entry point (programs call :func:`main`): after a Ctrl-C its handler
    stays, for the exit that follows; otherwise the previous handler is put back. A Ctrl-C
    that is ignored (a background job) stays ignored.
    """
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupt)
    try:
        code = main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    if previous is signal.default_int_handler:
        signal.signal(signal.SIGINT, previous)
    return code


def _interrupt(signum: int, frame: Any) -> None:
    """The first Ctrl-C: ``KeyboardInterrupt``, as Python's own handler; the next quits."""
    signal.signal(signal.SIGINT, _quit_now)
    raise KeyboardInterrupt


def _quit_now(signum: int, frame: Any) -> None:
    """A second Ctrl-C: stop this process's worker processes and exit at once, status 130."""
    import multiprocessing

    with contextlib.suppress(Exception):  # (a child gone meanwhile: nothing may stop the exit)
        for child in multiprocessing.active_children():  # (loky's workers are among them)
            os.kill(child.pid, getattr(signal, "SIGKILL", signal.SIGTERM))
    os._exit(130)


if __name__ == "__main__":
    sys.exit(console())

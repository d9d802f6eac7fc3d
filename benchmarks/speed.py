"""The speed suite: one command, one table, every figure measured in this one run.

- wrapper overhead: ``PoissonRewardDelay`` against ``RecordEpisodeStatistics`` (GridWorld-9x9);
- env steps per second for every registered env, random actions;
- ``learn()`` cost per step against |Λ| on the Python path and on the compiled path;
- compiled vs Python path for Q-learning and MMQ (|Λ| = 51) on GridWorld-9x9 with Poisson(13);
- the wall time of a 1M-step MMQ run (|Λ| = 51) in a fresh process, including the load of the
  compiled code from numba's on-disk cache (the cache is warmed first);
- the compiled path on ``gym.make``'d toy-text envs (``TimeLimit`` included) against the Python
  path and the bare env step, and every agent's compiled cost per step;
- the e-puck: random-action steps/s beside pymunk's bare solver (the floor), and the
  line-following training loop (env + MMQ |Λ| = 151) compiled and on the Python path, beside
  the env's own Python steps alone;
- with ``--bench-all``, the wall time of ``delayed-rl bench all`` at full scale (numba's cache
  warmed first by ``bench all --quick``), and each experiment's cost.

    python benchmarks/speed.py [--quick] [--bench-all [--bench-all-out DIR]] [--markdown FILE]

Targets: delay-wrapper overhead ≤ 1.5 × RecordEpisodeStatistics' (each beside the bare env, its
floor); Q-learning's Python-path ``learn()`` ≤ 2 × a minimal Q-learning loop on the same env;
compiled ≥ 30 × the Python path for Q-learning and for MMQ |Λ| = 51; a 1M-step MMQ run ≤ 1.5 s
including compilation from a warm cache; e-puck random steps ≥ 60,000/s; its training loop ≥ 2 ×
faster than the Python loop.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import agent_step_cost
import epuck_speed
import gymnasium as gym
import numpy as np
import wrapper_overhead
from interleaved import fastest, one_repeat, shown, spread

import delayed_rl

ONE_MILLION_MMQ = """
import time
start = time.perf_counter()
import gymnasium as gym
import delayed_rl
from delayed_rl.agents import MultipleModelQLearning
ready = time.perf_counter()
agent = MultipleModelQLearning(gym.make("delayed_rl/GridWorld-9x9-v0", reward_delay=13), max_delay_estimate=50,
            q_init=10.0, seed=0)
agent.learn(1_000_000, log_interval=None)
assert agent.last_learn_path == "compiled"
print(time.perf_counter() - ready, ready - start)
"""


def env_steps_per_second(steps: int) -> dict[str, float]:
    """Random-action steps per second of every registered env (and the e-puck's pixel mode)."""
    configs = {
        env_id: {} for env_id in delayed_rl.envs.env_ids() if env_id != "delayed_rl/GridWorld-v0"
    }
    configs["delayed_rl/EPuckLineFollow-v0 (pixels)"] = {"observation_mode": "pixels"}
    rates = {}
    for name, kwargs in configs.items():
        env = gym.make(name.split(" ")[0], **kwargs).unwrapped
        env.reset(seed=0)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(steps)]
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        rates[name] = steps / (time.perf_counter() - start)
    return rates


def one_million_mmq_seconds() -> tuple[float, float]:
    """(learn seconds, import seconds) of a 1M-step MMQ run in a fresh interpreter, cache warm."""
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as handle:
        handle.write(ONE_MILLION_MMQ)
    subprocess.run([sys.executable, handle.name], check=True, capture_output=True)  # warm cache
    out = subprocess.run([sys.executable, handle.name], check=True, capture_output=True, text=True)
    Path(handle.name).unlink()
    learn, imports = (float(x) for x in out.stdout.split())
    return learn, imports


def bench_all_seconds(out: Path) -> tuple[float, float, list[str]]:
    """Wall time of ``delayed-rl bench all --workers 2`` at full scale, and its index's rows.

    numba's cache is warmed first by ``bench all --quick`` (the same agents on the same envs,
    so every compiled signature the full run needs), whose wall time is returned too: what a
    first run after installing also spends compiling, about. The results are written into
    ``out`` (``index.md`` lists each experiment's runs and their core-seconds).

    Returns:
        ``(seconds, warm-up seconds, rows)``.
    """

    def bench_all(*options: str) -> float:
        start = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "delayed_rl.cli", "bench", "all", "--workers", "2", *options],
            check=True,
            capture_output=True,
        )
        return time.perf_counter() - start

    with tempfile.TemporaryDirectory() as scratch:
        warm_up = bench_all("--quick", "--out", scratch)
    seconds = bench_all("--out", str(out))
    rows = [line for line in (out / "index.md").read_text().splitlines() if line.startswith("|")]
    return seconds, warm_up, rows


def spread_text(values: Sequence[float], scale: float = 1e6, digits: int = 2) -> str:
    """``min–median–max`` of ``values`` times ``scale``."""
    return shown(spread([v * scale for v in values]), digits)


def toy_text_runs(steps: int) -> dict[str, Callable[[], float]]:
    """Seconds per step of Q-learning on ``gym.make("Taxi-v4")`` under Poisson(5) reward delays.

    The compiled path, the Python path, and the bare env's step (the Python path's floor).
    """
    from delayed_rl.agents import QLearning
    from delayed_rl.wrappers import PoissonRewardDelay

    def learn(compiled: bool) -> Callable[[], float]:
        def run() -> float:
            agent = QLearning(PoissonRewardDelay(gym.make("Taxi-v4"), 5.0), seed=0)
            n = steps if compiled else steps // 20
            start = time.perf_counter()
            agent.learn(n, compiled=compiled, log_interval=None)
            return (time.perf_counter() - start) / n

        return run

    def bare() -> float:
        env = gym.make("Taxi-v4").unwrapped
        env.reset(seed=0)
        actions = np.random.default_rng(0).integers(6, size=steps // 20).tolist()
        start = time.perf_counter()
        for action in actions:
            if env.step(action)[2]:
                env.reset()
        return (time.perf_counter() - start) / len(actions)

    QLearning(PoissonRewardDelay(gym.make("Taxi-v4"), 5.0)).learn(1000, compiled=True)  # compile
    return {"compiled": learn(True), "Python path": learn(False), "bare env step": bare}


def compiled_agent_runs(steps: int) -> dict[str, Callable[[], float]]:
    """Seconds per compiled step of every agent on GridWorld-9x9 with Poisson(13) delays."""
    from delayed_rl import agents
    from delayed_rl.delays import Poisson
    from delayed_rl.wrappers import RewardDelay

    def grid(record: bool = False) -> gym.Env:
        return RewardDelay(
            gym.make("delayed_rl/GridWorld-9x9-v0"), Poisson(13.0), record_arrivals=record
        )

    makers = {
        "Q-learning": lambda: agents.QLearning(grid()),
        "MMQ |Λ| = 51": lambda: agents.MultipleModelQLearning(grid(), max_delay_estimate=50),
        "expected credit (51 lags)": lambda: agents.ExpectedCreditQLearning(
            grid(), 13.0, max_delay_estimate=50
        ),
        "oracle": lambda: agents.OracleQLearning(grid(record=True)),
        "DeconvQ, delay known": lambda: agents.DeconvolutionQLearning(
            grid(), delay=Poisson(13.0), max_delay_estimate=50
        ),
        "DeconvQ, delay learned": lambda: agents.DeconvolutionQLearning(
            grid(), max_delay_estimate=50
        ),
    }

    def run(make: Callable[[], Any]) -> Callable[[], float]:
        def timed() -> float:
            agent = make()
            start = time.perf_counter()
            agent.learn(steps, log_interval=None)
            assert agent.last_learn_path == "compiled"
            return (time.perf_counter() - start) / steps

        return timed

    for make in makers.values():  # load the compiled code
        make().learn(2000)
    return {name: run(make) for name, make in makers.items()}


#: The e-puck rows of :func:`epuck_runs` that the summary line compares.
RANDOM_STEPS, SOLVER_FLOOR = "random steps", "pymunk solver (floor)"
COMPILED_TRAINING = "training, compiled loop: env + MMQ |Λ| = 151"
PYTHON_TRAINING = "training, Python loop: env + MMQ |Λ| = 151"
ENV_ALONE = "the training env's steps alone (Python)"


def epuck_runs(steps: int) -> dict[str, Callable[[], float]]:
    """Seconds per step of the e-puck: random actions, and the line-following training loop.

    Beside each, its floor: pymunk's bare solver for one env step; the training loop on both
    paths (the compiled one steps the robot itself), beside the env's own steps alone.
    """
    from delayed_rl.agents import MultipleModelQLearning
    from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv
    from delayed_rl.experiments.framework.line_following import line_env

    env = EPuckLineFollowEnv("racetrack", max_steps=None, lost_line="recover")

    MultipleModelQLearning(line_env(), max_delay_estimate=150, q_init=10.0).learn(
        500
    )  # compile the loop first

    def training(compiled: bool) -> Callable[[], float]:
        def run() -> float:
            agent = MultipleModelQLearning(line_env(), max_delay_estimate=150, q_init=10.0, seed=0)
            n = steps if compiled else steps // 2
            start = time.perf_counter()
            agent.learn(n, log_interval=None, compiled=compiled)
            assert agent.last_learn_path == ("compiled" if compiled else "python")
            return (time.perf_counter() - start) / n

        return run

    def env_alone() -> float:
        return epuck_speed.seconds_per_step(line_env().unwrapped, steps // 2, 0)

    return {
        RANDOM_STEPS: lambda: 1.0 / epuck_speed.steps_per_second(env, steps, 0),
        SOLVER_FLOOR: lambda: epuck_speed.space_step_floor(env, steps),
        COMPILED_TRAINING: training(True),
        PYTHON_TRAINING: training(False),
        ENV_ALONE: env_alone,
    }


def markdown_table(title: str, columns: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a report section: a ``## title`` heading, then a table and a blank line."""
    return [
        f"## {title}",
        "",
        "| " + " | ".join(columns) + " |",
        "|" + "---|" * len(columns),
        *("| " + " | ".join(row) + " |" for row in rows),
        "",
    ]


def main() -> None:
    """Measure everything, print the report and, with ``--markdown``, write it to a file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps (noisier)")
    parser.add_argument("--bench-all", action="store_true", help="also time the full reproduction")
    parser.add_argument("--markdown", type=Path, help="also write the report to this file")
    parser.add_argument(
        "--bench-all-out", type=Path, help="with --bench-all: keep its results in this folder"
    )
    args = parser.parse_args()
    scale = 5 if args.quick else 1
    lines = [
        f"Machine: {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, numpy {np.__version__}, "
        f"delayed-rl {delayed_rl.__version__}.",
        "",
    ]

    repeats = wrapper_overhead.measure(10_000 // scale, 11)
    lines += markdown_table(
        "Wrapper overhead (GridWorld-9x9, µs/step, min–median–max of 11 interleaved repeats)",
        ["stack", "µs/step", "overhead over bare"],
        wrapper_overhead.cost_rows(repeats),
    )
    lines += [wrapper_overhead.summary(repeats) + ".", ""]

    rates = env_steps_per_second(100_000 // scale)
    lines += markdown_table(
        "Env steps per second (random actions, unwrapped)",
        ["env", "steps/s"],
        [(n, f"{r:,.0f}") for n, r in rates.items()],
    )

    per_repeat = agent_step_cost.measure_repeats(10_000 // scale, 3, rounds=3)
    best = [fastest(r) for r in per_repeat]
    python = {name: min(r[name] for r in best) for name in agent_step_cost.configurations()}
    compiled = agent_step_cost.measure(300_000 // scale, 3, compiled=True)
    lines += markdown_table(
        "learn() cost per step (µs; GridWorld with Poisson(13) delays)",
        ["configuration", "Python path", "compiled path", "speed-up"],
        [
            (
                n,
                f"{python[n] * 1e6:.2f}",
                f"{compiled[n] * 1e6:.3f}",
                f"{python[n] / compiled[n]:.0f}×",
            )
            for n in python
        ],
    )
    q_gain = python["9x9, |Λ|=1"] / compiled["9x9, |Λ|=1"]
    mmq_gain = python["9x9, |Λ|=51"] / compiled["9x9, |Λ|=51"]
    scaling = python["9x9, |Λ|=151"] / python["9x9, |Λ|=1"]
    world = python["30x30, |Λ|=51"] / python["9x9, |Λ|=51"]
    lines += [
        f"Compiled vs Python: Q-learning **{q_gain:.0f}×**, MMQ |Λ| = 51 **{mmq_gain:.0f}×** "
        "(the ≥ 30× target was set against the Python path before its update steps were "
        "compiled; the compiled path's own cost is the third column).",
        f"Python path: cost(|Λ| = 151) / cost(|Λ| = 1) = {scaling:.2f} (target ≤ 3); "
        f"cost(30×30) / cost(9×9) at |Λ| = 51 = {world:.2f} (target ≤ 1.5); "
        f"{agent_step_cost.floor_summary(per_repeat)}.",
        "",
    ]
    repeats = 5
    toy = one_repeat(toy_text_runs(200_000 // scale), repeats)
    lines += markdown_table(
        "gym.make('Taxi-v4') (TimeLimit 200) with Poisson(5) reward delays: Q-learning, "
        f"µs/step, min–median–max of {repeats} interleaved repeats",
        ["run", "µs/step", "ratio to the compiled run (median of per-repeat ratios)"],
        [
            (
                name,
                spread_text(values),
                f"{np.median(np.array(values) / np.array(toy['compiled'])):.1f}",
            )
            for name, values in toy.items()
        ],
    )
    compiled = one_repeat(compiled_agent_runs(300_000 // scale), 3)
    lines += markdown_table(
        "Every agent on the compiled path (GridWorld-9x9, Poisson(13), µs/step, 3 interleaved repeats)",
        ["agent", "µs/step", "ratio to Q-learning (median)"],
        [
            (
                name,
                spread_text(values, digits=3),
                f"{np.median(np.array(values) / np.array(compiled['Q-learning'])):.1f}",
            )
            for name, values in compiled.items()
        ],
    )
    epuck = one_repeat(epuck_runs(10_000 // scale), repeats)
    lines += markdown_table(
        f"The e-puck (µs/step, min–median–max of {repeats} interleaved repeats)",
        ["run", "µs/step", "steps/s (median)"],
        [(name, spread_text(v), f"{1 / np.median(v):,.0f}") for name, v in epuck.items()],
    )
    env_ratio = np.median(np.array(epuck[RANDOM_STEPS]) / np.array(epuck[SOLVER_FLOOR]))
    gain = np.median(np.array(epuck[PYTHON_TRAINING]) / np.array(epuck[COMPILED_TRAINING]))
    below_env = np.median(np.array(epuck[ENV_ALONE]) / np.array(epuck[COMPILED_TRAINING]))
    lines += [
        f"e-puck random steps: **{1 / np.median(epuck[RANDOM_STEPS]):,.0f} steps/s** (target ≥ "
        f"60,000), {env_ratio:.1f}× pymunk's bare solver. The line-following training loop "
        f"(the experiments' default, compiled) is **{gain:.1f}× faster** than the Python loop "
        f"(target ≥ 2×), and {below_env:.1f}× faster than the env's own Python steps alone.",
        "",
    ]
    learn, imports = one_million_mmq_seconds()
    lines += [
        f"1M-step MMQ (|Λ| = 51) in a fresh process: **{learn:.2f} s** of learn() "
        f"including loading the compiled code from the warm cache (target ≤ 1.5 s); "
        f"importing the library took a further {imports:.2f} s.",
        "",
    ]
    if args.bench_all:
        with tempfile.TemporaryDirectory() as scratch:
            seconds, warm_up, rows = bench_all_seconds(args.bench_all_out or Path(scratch))
        lines += [
            f"## `delayed-rl bench all --workers 2` at full scale: **{seconds:.0f} s** "
            f"({seconds / 60:.1f} min)",
            "",
            f"With numba's cache warm (target ≤ 5 min); warming it, `bench all --quick`, took "
            f"{warm_up:.0f} s, about what a first run after installing spends compiling.",
            "",
            "What each experiment cost (its `index.md`: the runs it needed, how many of them "
            "another experiment shared, and their core-seconds; every experiment's runs go to "
            "one pool of 2 workers, the longest first, so the wall time is about half the "
            "distinct runs' core-seconds):",
            "",
            *rows,
            "",
        ]
    report = "\n".join(lines)
    print(report)
    if args.markdown:
        command = "python benchmarks/speed.py" + (" --bench-all" if args.bench_all else "")
        kept = _kept_section(args.markdown)
        args.markdown.write_text(f"# Speed\n\nGenerated by `{command}`.\n\n{report}{kept}")


#: The heading of SPEED.md's last section, which this script keeps as it is when it rewrites the
#: file: the measurements behind design choices, which the code links instead of quoting.
KEPT_HEADING = "## Measurements behind design choices"


def _kept_section(path: Path) -> str:
    """The section of ``path`` from :data:`KEPT_HEADING` on ("" if there is none)."""
    text = path.read_text() if path.exists() else ""
    start = text.find(KEPT_HEADING)
    return "" if start < 0 else "\n" + text[start:]


if __name__ == "__main__":
    main()

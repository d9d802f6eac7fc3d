"""The speed suite: one command, one table, every figure measured in this one run.

- wrapper overhead: ``PoissonRewardDelay`` against ``RecordEpisodeStatistics`` (GridWorld-9x9);
- env steps per second for every registered env, random actions;
- ``learn()`` cost per step against |Λ| on the Python path and on the compiled path;
- compiled vs Python path for Q-learning and MMQ (|Λ| = 51) on GridWorld-9x9 with Poisson(13);
- the wall time of a 1M-step MMQ run (|Λ| = 51) in a fresh process, including the load of the
  compiled code from numba's on-disk cache (the cache is warmed first);
- with ``--reproduce``, the wall time of ``delayed-rl reproduce`` at full scale.

    python benchmarks/speed.py [--quick] [--reproduce] [--markdown benchmarks/SPEED.md]

Targets: delay-wrapper overhead ≤ 1.5 × RecordEpisodeStatistics' (each beside the bare env, its
floor); Q-learning's Python-path ``learn()`` ≤ 2 × a minimal Q-learning loop on the same env;
compiled ≥ 30 × the Python path for Q-learning and for MMQ |Λ| = 51; a 1M-step MMQ run ≤ 1.5 s
including compilation from a warm cache.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

import agent_step_cost
import gymnasium as gym
import numpy as np
import wrapper_overhead

import delayed_rl

ONE_MILLION_MMQ = """
import time
start = time.perf_counter()
import gymnasium as gym
import delayed_rl
from delayed_rl.agents import MMQ
ready = time.perf_counter()
agent = MMQ(gym.make("delayed_rl/GridWorld-9x9-v0", reward_delay=13), max_delay_estimate=50,
            q_init=10.0, seed=0)
agent.learn(1_000_000, log_interval=None)
assert agent.last_learn_path == "fused"
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


def reproduce_seconds(out: Path) -> float:
    """Wall time of ``delayed-rl reproduce --workers 2`` at full scale."""
    command = ["reproduce", "--workers", "2", "--out", str(out)]
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "delayed_rl.cli", *command], check=True, capture_output=True
    )
    return time.perf_counter() - start


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
    parser.add_argument("--reproduce", action="store_true", help="also time the full reproduction")
    parser.add_argument("--markdown", type=Path, help="also write the report to this file")
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
    best = agent_step_cost.fastest(per_repeat)
    python = {name: min(r[name] for r in best) for name in agent_step_cost.configurations()}
    fused = agent_step_cost.measure(300_000 // scale, 3, fused=True)
    lines += markdown_table(
        "learn() cost per step (µs; GridWorld with Poisson(13) delays)",
        ["configuration", "Python path", "compiled path", "speed-up"],
        [
            (n, f"{python[n] * 1e6:.2f}", f"{fused[n] * 1e6:.3f}", f"{python[n] / fused[n]:.0f}×")
            for n in python
        ],
    )
    q_gain = python["9x9, |Λ|=1"] / fused["9x9, |Λ|=1"]
    mmq_gain = python["9x9, |Λ|=51"] / fused["9x9, |Λ|=51"]
    scaling = python["9x9, |Λ|=151"] / python["9x9, |Λ|=1"]
    world = python["30x30, |Λ|=51"] / python["9x9, |Λ|=51"]
    lines += [
        f"Compiled vs Python: Q-learning **{q_gain:.0f}×**, MMQ |Λ| = 51 **{mmq_gain:.0f}×** "
        "(target ≥ 30×).",
        f"Python path: cost(|Λ| = 151) / cost(|Λ| = 1) = {scaling:.2f} (target ≤ 3); "
        f"cost(30×30) / cost(9×9) at |Λ| = 51 = {world:.2f} (target ≤ 1.5); "
        f"{agent_step_cost.floor_summary(per_repeat)}.",
        "",
    ]
    learn, imports = one_million_mmq_seconds()
    lines += [
        f"1M-step MMQ (|Λ| = 51) in a fresh process: **{learn:.2f} s** of learn() "
        f"including loading the compiled code from the warm cache (target ≤ 1.5 s); "
        f"importing the library took a further {imports:.2f} s.",
        "",
    ]
    if args.reproduce:
        with tempfile.TemporaryDirectory() as out:
            seconds = reproduce_seconds(Path(out))
        lines += [f"`delayed-rl reproduce --workers 2` at full scale: **{seconds:.0f} s**.", ""]
    report = "\n".join(lines)
    print(report)
    if args.markdown:
        command = "python benchmarks/speed.py" + (" --reproduce" if args.reproduce else "")
        args.markdown.write_text(f"# Speed\n\nGenerated by `{command}`.\n\n{report}")


if __name__ == "__main__":
    main()

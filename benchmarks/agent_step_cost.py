"""Per-step cost of ``learn()`` for Q-learning and MMQ as the number of delay models grows.

This measures the Python path (``learn(fused=False)``); ``benchmarks/speed.py`` sets it beside
the compiled one. MMQ's per-step cost must be O(|Λ|) with a small constant, not O(|Λ|²·|A|):
every step updates one entry per model (a batch of numpy gathers and scatters) and reads each
next state's max over all models from a cache instead of recomputing it. This script measures,
in one process:

- ``learn()`` on ``GridWorld-9x9`` with Poisson(13) reward delays for |Λ| ∈ {1, 11, 51, 151}
  (|Λ| = 1 is plain Q-learning; Λ = {0, 1, ..., |Λ| − 1});
- the same at |Λ| = 51 on a 30×30 grid (900 states instead of 81).

Each configuration starts from a warmed-up agent (so early, history-limited steps do not count)
and repeats are interleaved so machine noise hits all alike; each cost is the fastest repeat.
Targets: cost(|Λ| = 151) ≤ 3 × cost(|Λ| = 1), and cost(30×30) ≤ 1.5 × cost(9×9) at |Λ| = 51.

    python benchmarks/agent_step_cost.py [--steps 30000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import MMQ, QLearning

MODEL_COUNTS = (1, 11, 51, 151)
LAMBDA = 13


def make_agent(size: int, n_models: int) -> MMQ:
    """An agent on a ``size``×``size`` grid with Poisson(13) delays and ``n_models`` models."""
    env = gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=LAMBDA)
    settings = {"q_init": 20.0, "seed": 0}
    if n_models == 1:
        return QLearning(env, **settings)
    return MMQ(env, delay_estimates=list(range(n_models)), **settings)


def time_learn(agent: MMQ, steps: int, fused: bool = False) -> float:
    """Seconds per step of ``agent.learn(steps)`` on one path, continuing the agent's run."""
    start = time.perf_counter()
    agent.learn(steps, reset_num_timesteps=False, fused=fused)
    return (time.perf_counter() - start) / steps


def measure(steps: int, repeats: int, fused: bool = False) -> dict[str, float]:
    """Fastest seconds per step of each configuration, repeats interleaved, on one path."""
    configs = {f"9x9, |Λ|={n}": (9, n) for n in MODEL_COUNTS}
    configs["30x30, |Λ|=51"] = (30, 51)
    agents = {name: make_agent(*config) for name, config in configs.items()}
    for agent in agents.values():
        agent.learn(steps, fused=fused)  # warm-up: past the history-limited start
    best = {name: float("inf") for name in agents}
    for _ in range(repeats):
        for name, agent in agents.items():
            best[name] = min(best[name], time_learn(agent, steps, fused))
    return best


def main() -> None:
    """Measure every configuration and print the cost table and the two target checks."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30_000, help="steps per timed repeat")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats")
    args = parser.parse_args()
    best = measure(args.steps, args.repeats)

    print(f"learn() cost per step (fastest of {args.repeats} x {args.steps} steps)")
    print(f"{'configuration':<18} {'µs/step':>9} {'vs |Λ|=1':>9}")
    base = best["9x9, |Λ|=1"]
    for name, cost in best.items():
        print(f"{name:<18} {cost * 1e6:9.2f} {cost / base:9.2f}")
    scaling = best["9x9, |Λ|=151"] / base
    world = best["30x30, |Λ|=51"] / best["9x9, |Λ|=51"]
    print()
    print(
        f"cost(|Λ|=151) / cost(|Λ|=1)      = {scaling:.2f}  (target <= 3)  {_verdict(scaling, 3)}"
    )
    print(
        f"cost(30x30) / cost(9x9) at |Λ|=51 = {world:.2f}  (target <= 1.5)  {_verdict(world, 1.5)}"
    )


def _verdict(ratio: float, target: float) -> str:
    """``ok`` when ``ratio`` meets its target (at most ``target``), else ``MISSED``."""
    return "ok" if ratio <= target else "MISSED"


if __name__ == "__main__":
    main()

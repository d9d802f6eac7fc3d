"""Per-step cost of ``learn()`` for Q-learning and MMQ, against a minimal Q-learning loop.

This measures the Python path (``learn(compiled=False)``); ``benchmarks/speed.py`` sets it beside
the compiled one. In one process, repeats interleaved so machine noise hits all alike:

- the floor: a minimal hand-written Q-learning loop (Python lists, ε-greedy, first arg-max) on
  the same env as the agents, ``GridWorld-9x9`` with Poisson(13) reward delays;
- ``learn()`` on that env for |Λ| ∈ {1, 11, 51, 151} (|Λ| = 1 is plain Q-learning;
  Λ = {0, 1, ..., |Λ| − 1}), and at |Λ| = 51 on a 30×30 grid (900 states instead of 81).

Each configuration starts from a warmed-up agent (so early, history-limited steps do not count).
A repeat is ``--rounds`` rounds, each timing every configuration once, back to back (garbage
collector off, as ``timeit`` does); a repeat's cost of a configuration is its fastest round, its
ratio to the floor the median over the rounds of the two timings' quotient (taken back to back,
both slowed alike by a slow spell of the machine). Figures are min–median–max over the repeats.
Targets:

- ``learn()`` of Q-learning at most 2 × the minimal loop, in every repeat (the shell's overhead:
  callbacks, logging, the record, random tie-breaks and the cached maxima on a numpy table);
- cost(|Λ| = 151) ≤ 3 × cost(|Λ| = 1): MMQ is O(|Λ|) per step with a small constant, not
  O(|Λ|²·|A|) (one compiled batch update per step, next-state maxima read from a cache);
- cost(30×30) ≤ 1.5 × cost(9×9) at |Λ| = 51.

    python benchmarks/agent_step_cost.py [--steps 5000] [--rounds 7] [--repeats 5]
"""

from __future__ import annotations

import argparse
import random
from collections.abc import Callable

import gymnasium as gym
from interleaved import (
    Repeat,
    fastest,
    interleave,
    median_ratio,
    seconds_per_step,
    shown,
    spread,
    target_summary,
    verdict,
)

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import DEFAULTS, MultipleModelQLearning, QLearning

MODEL_COUNTS = (1, 11, 51, 151)
LAM = 13
FLOOR = "minimal loop"
"""The name of the floor's timings."""
WARM_UP = 30_000
"""Steps every run takes before it is timed: past the start, when optimistic values tie."""
SETTINGS = {"q_init": 20.0, "seed": 0}
"""The agents' settings; α, γ and ε are the defaults, as in the minimal loop."""


def make_env(size: int) -> gym.Env:
    """A ``size``×``size`` grid world with Poisson(13) reward delays, made as users make it."""
    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=LAM)


def make_agent(size: int, n_models: int) -> MultipleModelQLearning:
    """An agent on a ``size``×``size`` grid with Poisson(13) delays and ``n_models`` models."""
    if n_models == 1:
        return QLearning(make_env(size), **SETTINGS)
    return MultipleModelQLearning(make_env(size), delay_estimates=list(range(n_models)), **SETTINGS)


def configurations() -> dict[str, tuple[int, int]]:
    """``name: (grid size, |Λ|)`` of every measured agent."""
    configs = {f"9x9, |Λ|={n}": (9, n) for n in MODEL_COUNTS}
    configs["30x30, |Λ|=51"] = (30, 51)
    return configs


class MinimalQLearning:
    """The floor: Q-learning as few Python operations as it takes, on ``env``.

    Lists for the table, ``random.random`` for ε-greedy, the first arg-max (no random
    tie-break), the textbook update after every step; α, γ, ε and the initial values are the
    agents'. Calls continue the same run.

    Args:
        env: the env (``Discrete`` spaces).
    """

    def __init__(self, env: gym.Env):
        self.env, self.alpha, self.gamma = env, DEFAULTS.learning_rate, DEFAULTS.gamma
        self.eps = DEFAULTS.exploration_initial_eps
        q_init = SETTINGS["q_init"]
        self.q = [[q_init] * env.action_space.n for _ in range(env.observation_space.n)]
        self.random = random.Random(0).random
        self.s = env.reset(seed=0)[0]

    def learn(self, steps: int) -> None:
        """Take ``steps`` steps, learning from each."""
        env, q, rand = self.env, self.q, self.random
        alpha, gamma, eps, n_actions = self.alpha, self.gamma, self.eps, len(q[0])
        s = self.s
        for _ in range(steps):
            row = q[s]
            a = int(rand() * n_actions) if rand() < eps else row.index(max(row))
            s2, r, terminated, truncated, _ = env.step(a)
            row[a] += alpha * (r + gamma * (0.0 if terminated else max(q[s2])) - row[a])
            s = env.reset()[0] if terminated or truncated else s2
        self.s = s


def learners(compiled: bool) -> dict[str, Callable[[int], object]]:
    """``name: run(steps)`` of every configuration (and, on the Python path, of the floor)."""
    runs: dict[str, Callable[[int], object]] = {}
    if not compiled:
        runs[FLOOR] = MinimalQLearning(make_env(9)).learn
    for name, config in configurations().items():
        agent = make_agent(*config)
        runs[name] = lambda steps, agent=agent: agent.learn(
            steps, reset_num_timesteps=False, compiled=compiled
        )
    return runs


def measure_repeats(
    steps: int, repeats: int, compiled: bool = False, rounds: int = 1
) -> list[Repeat]:
    """Seconds per step of each configuration in each round, one dict per repeat.

    Every run is warmed up first (:data:`WARM_UP` steps: past the history-limited start and the
    ties of the optimistic start, and the compilation on the compiled path); a round times every
    configuration once, back to back. On the Python path
    the floor (:data:`FLOOR`) is measured too, first in each round.
    """
    runs = learners(compiled)
    for run in runs.values():
        run(WARM_UP)
    timed = {
        name: lambda run=run: seconds_per_step(lambda: run(steps), steps)
        for name, run in runs.items()
    }
    return interleave(timed, repeats, rounds)


def measure(steps: int, repeats: int, compiled: bool = False) -> dict[str, float]:
    """Fastest seconds per step of each configuration (the floor left out), on one path."""
    best = [fastest(r) for r in measure_repeats(steps, repeats, compiled)]
    return {name: min(r[name] for r in best) for name in configurations()}


def floor_summary(per_repeat: list[Repeat]) -> str:
    """Q-learning's ``learn()`` against the floor, within each repeat (min–median–max)."""
    ratios = [median_ratio(r, "9x9, |Λ|=1", FLOOR) for r in per_repeat]
    what = "learn() of Q-learning / minimal loop ="
    return target_summary(what, ratios, 2, per_repeat, FLOOR, "the minimal loop")


def main() -> None:
    """Measure every configuration and the floor; print the cost table and the target checks."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5_000, help="steps per timing")
    parser.add_argument("--rounds", type=int, default=7, help="rounds per repeat")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats")
    args = parser.parse_args()
    per_repeat = measure_repeats(args.steps, args.repeats, rounds=args.rounds)
    best = [fastest(r) for r in per_repeat]

    print(f"learn(compiled=False) cost per step, µs (min–median–max of {args.repeats} repeats)")
    print(f"{'configuration':<18} {'µs/step':>20} {'vs minimal loop':>18}")
    for name in per_repeat[0]:
        cost = spread([r[name] * 1e6 for r in best])
        ratio = spread([median_ratio(r, name, FLOOR) for r in per_repeat])
        print(f"{name:<18} {shown(cost):>20} {shown(ratio):>18}")
    scaling = [r["9x9, |Λ|=151"] / r["9x9, |Λ|=1"] for r in best]
    world = [r["30x30, |Λ|=51"] / r["9x9, |Λ|=51"] for r in best]
    print()
    print(floor_summary(per_repeat))
    print(
        f"cost(|Λ|=151) / cost(|Λ|=1) = {shown(spread(scaling))}  (target <= 3)  "
        f"{verdict(max(scaling), 3)}"
    )
    print(
        f"cost(30x30) / cost(9x9) at |Λ|=51 = {shown(spread(world))}  (target <= 1.5)  "
        f"{verdict(max(world), 1.5)}"
    )


if __name__ == "__main__":
    main()

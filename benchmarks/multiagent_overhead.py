"""Per-step cost of the multi-agent delay wrappers against a pass-through PettingZoo wrapper.

Runs one PettingZoo ``ParallelEnv`` under a pass-through ``BaseParallelWrapper`` (the floor:
what any wrapper layer costs) and under each of ``ParallelRewardDelay``,
``ParallelObservationDelay`` (both arrival rules) and ``ParallelActionDelay``, with Poisson(5)
delays, each stack on its own copy of the env, in one process. It prints each stack's cost per
step and each wrapper's cost as a ratio to the pass-through's (target: at most 1.6 in every
repeat, on ``pursuit_v5``).

A repeat is ``--rounds`` rounds, each timing every stack once, back to back, over the same
actions, with the garbage collector off (as ``timeit`` does). A repeat's cost of a stack is its
fastest round; its ratio is the median over its rounds of each round's ratio, whose timings were
taken back to back and so were slowed alike (as ``wrapper_overhead.py`` pairs them). Figures
are min–median–max over the repeats, beside the floor measured in the same run; a first round
warms up.

``--env pursuit`` (the default) is SISL's ``pursuit_v5`` at its default size (8 pursuers, 16×16
grid, 7×7×3 observations); ``--env rps`` is PettingZoo's rock-paper-scissors (2 agents, a step
of tens of µs, most of it PettingZoo's own AEC-to-parallel conversion); ``--env light`` is a
pure-Python env of 8 agents whose step costs a few µs, where the wrappers' own work is nearly
all of the time (rps and light are reported for information: the target is stated on pursuit,
where an env does work).

    python benchmarks/multiagent_overhead.py [--env pursuit|rps|light] [--steps 300] [--rounds 5]
        [--repeats 7] [--quick]
"""

from __future__ import annotations

import argparse
import functools
import importlib
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces
from interleaved import Repeat, interleave, median_ratio, seconds_per_step, shown, spread, verdict
from pettingzoo import ParallelEnv
from pettingzoo.utils import BaseParallelWrapper

from delayed_rl.delays import Poisson
from delayed_rl.multiagent import ParallelActionDelay, ParallelObservationDelay, ParallelRewardDelay

TARGET = 1.6
"""The most a wrapper's per-step cost may be, in units of the pass-through wrapper's (pursuit)."""

FLOOR = "pass-through"


class LightParallelEnv(ParallelEnv):
    """Eight agents, a 3-number observation each, rewards from a fixed table: a cheap step."""

    metadata = {"name": "light_v0", "render_modes": []}

    def __init__(self, agents: int = 8, max_cycles: int = 500):
        self.possible_agents = [f"agent_{i}" for i in range(agents)]
        self.max_cycles = max_cycles
        self.render_mode = None
        self._table = np.random.default_rng(0).normal(size=(97, agents)).tolist()

    @functools.lru_cache(maxsize=None)  # noqa: B019, UP033 (one space object per agent)
    def observation_space(self, agent: str) -> spaces.Space:
        """``Box(3)``."""
        return spaces.Box(-np.inf, np.inf, (3,), np.float64)

    @functools.lru_cache(maxsize=None)  # noqa: B019, UP033
    def action_space(self, agent: str) -> spaces.Space:
        """``Discrete(5)``."""
        return spaces.Discrete(5)

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode."""
        self.t = 0
        self.agents = list(self.possible_agents)
        return {a: np.zeros(3) for a in self.agents}, {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]):
        """Every agent gets its table's reward; all are truncated at ``max_cycles``."""
        self.t += 1
        row = self._table[self.t % 97]
        last = self.t >= self.max_cycles
        obs = {a: np.array([self.t, i, row[i]]) for i, a in enumerate(self.agents)}
        rewards = {a: row[i] for i, a in enumerate(self.agents)}
        done = dict.fromkeys(self.agents, last)
        infos = {a: {} for a in self.agents}
        if last:
            self.agents = []
        return obs, rewards, dict.fromkeys(done, False), done, infos


def pursuit() -> ParallelEnv:
    """SISL's ``pursuit_v5`` at its default size (PettingZoo 1.27's registry, or its module)."""
    import pettingzoo

    if hasattr(pettingzoo, "make"):
        return pettingzoo.make("parallel", "sisl/pursuit-v5", max_cycles=500)
    return importlib.import_module("pettingzoo.sisl.pursuit_v5").parallel_env(max_cycles=500)


def rps() -> ParallelEnv:
    """PettingZoo's rock-paper-scissors (two agents): a cheap step behind PettingZoo's own wrappers."""
    return importlib.import_module("pettingzoo.classic.rps_v2").parallel_env(max_cycles=500)


ENVS: dict[str, Callable[[], ParallelEnv]] = {
    "pursuit": pursuit,
    "rps": rps,
    "light": LightParallelEnv,
}


def make_stacks(make_env: Callable[[], ParallelEnv]) -> dict[str, ParallelEnv]:
    """The floor and the four wrapped stacks, each on its own env."""
    delay = Poisson(5)
    return {
        FLOOR: BaseParallelWrapper(make_env()),
        "ParallelRewardDelay": ParallelRewardDelay(make_env(), delay),
        "ParallelObservationDelay(stale)": ParallelObservationDelay(make_env(), delay),
        "ParallelObservationDelay(network)": ParallelObservationDelay(
            make_env(), delay, arrival="network"
        ),
        "ParallelActionDelay": ParallelActionDelay(make_env(), delay),
    }


def time_steps(env: ParallelEnv, actions: list[dict[str, Any]]) -> float:
    """Seconds per step over ``actions``, resetting when no agent is left (garbage collector off)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the last timing's rewards, left pending
        env.reset(seed=0)
    step, reset = env.step, env.reset

    def run() -> None:
        for action in actions:
            step(action)
            if not env.agents:
                reset()

    return seconds_per_step(run, len(actions))


def measure(env: str, steps: int, repeats: int, rounds: int) -> list[Repeat]:
    """Seconds per step of each stack in each round, one dict per repeat."""
    stacks = make_stacks(ENVS[env])
    probe = ENVS[env]()
    rng = np.random.default_rng(0)
    actions = [
        {a: int(rng.integers(probe.action_space(a).n)) for a in probe.possible_agents}
        for _ in range(steps)
    ]
    for stack in stacks.values():  # warm-up
        time_steps(stack, actions)
    timed = {name: lambda stack=stack: time_steps(stack, actions) for name, stack in stacks.items()}
    return interleave(timed, repeats, rounds)


def report(env: str, repeats: list[Repeat]) -> str:
    """The table of costs and ratios, and the verdict against :data:`TARGET` (pursuit)."""
    lines = [f"{'stack':<36}{'µs/step':>26}{'ratio to ' + FLOOR:>26}"]
    worst = 0.0
    for name in repeats[0]:
        cost = spread([min(r[name]) * 1e6 for r in repeats])
        ratios = [median_ratio(r, name, FLOOR) for r in repeats]
        worst = max(worst, max(ratios)) if name != FLOOR else worst
        lines.append(f"{name:<36}{shown(cost, 1):>26}{shown(spread(ratios), 3):>26}")
    lines.append(f"(min–median–max over {len(repeats)} repeats)\n")
    scope = "" if env == "pursuit" else " (stated on pursuit; for information here)"
    lines.append(
        f"Largest ratio of a wrapper to the {FLOOR} wrapper on {env}: {worst:.3f} "
        f"(target ≤ {TARGET} in every repeat{scope}: {verdict(worst, TARGET)})"
    )
    return "\n".join(lines)


def main() -> None:
    """Time the stacks and print their costs and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", choices=sorted(ENVS), default="pursuit")
    parser.add_argument("--steps", type=int, default=300, help="steps per timing")
    parser.add_argument("--rounds", type=int, default=5, help="rounds per repeat")
    parser.add_argument("--repeats", type=int, default=7, help="repeats")
    parser.add_argument(
        "--quick", action="store_true", help="a check that the script runs: 20 steps, 1 x 2"
    )
    args = parser.parse_args()
    if args.quick:
        args.steps, args.rounds, args.repeats = 20, 1, 2
    repeats = measure(args.env, args.steps, args.repeats, args.rounds)
    print(report(args.env, repeats))


if __name__ == "__main__":
    main()

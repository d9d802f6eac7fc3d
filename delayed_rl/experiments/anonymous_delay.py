"""``anonymous-delay`` (beyond the thesis): anonymous delayed-reward learners beside MMQ.

The thesis's future work asks how MMQ fares against other ways of learning from anonymous,
randomly delayed rewards, and under delays that are not Poisson. This experiment puts seven
learners on the grid world, each with the thesis's hyper-parameters (α = 0.1, γ = 0.9, constant
ε = 0.1, ``q_init`` = 25, see :mod:`.training`):

- ``Q``: Q-learning on the delayed reward as it arrives;
- ``MMQ``: Multiple Model Q-learning, Λ = {0, ..., 50} (the thesis's rule);
- ``expected credit``: :class:`~delayed_rl.agents.ExpectedCreditQLearning` given the true delay
  (its pmf clipped to 50 lags, the horizon every learner here has);
- ``DeconvQ known``: :class:`~DeconvolutionQLearning` given the true delay (``max_delay`` 50);
- ``DeconvQ learned``: :class:`~DeconvolutionQLearning` learning the delay on 0..50;
- ``oracle``: :class:`~delayed_rl.agents.OracleQLearning`, which is told which transition each
  reward came from (the non-anonymous upper bound);
- ``Q undelayed``: Q-learning without any delay (the reference; one run per seed and world,
  shared by its three delays: :func:`shared_run`).

Settings: the 9×9 grid with mean delay λ = 13 (1M steps a run) and the 7×7 grid with λ = 8
(300k steps), each under three delays of mean λ: Poisson(λ) (the thesis's), geometric
(``Geometric(p)`` with ``p = 1 / (λ + 1)``, mean ``(1 − p) / p = λ``) and a bimodal one (mass ½
at 0 and ½ at 2λ, an ``Empirical`` pmf). 20 seeds; a task is one (setting, agent, seed), 840 at
full size. ``--quick``: 7×7 under Poisson only, 2 seeds, 30k steps.

Per run, from the undelayed reward stream (``training_log["undelayed_reward"]``):

- the learning curve (running average reward) and the training mean reward;
- the greedy 1000-step average: the agent's deterministic greedy policy walked from the start
  cell of the undelayed grid (:func:`walk_average`); the policy is *optimal* when that average
  is at least ``LOOP_FRACTION`` = 0.95 of the optimum ``10 / (2(n − 1) + 1)``;
- greedy snapshots: the run learns in ``SNAPSHOTS`` = 50 pieces (``learn(...,
  reset_num_timesteps=False)``, which trains exactly as one call does) and after each records
  whether the greedy policy is optimal: a policy that settled, or one that keeps flipping;
- the delay estimate: DeconvQ's ``delay_pmf`` and ``mean_delay``; MMQ's acting-delay share;
- MMQ's runs also keep a greedy window (``greedy_window`` = ``steps // 10``), which changes
  nothing of how MMQ learns; ``future-work`` reports its snapshots from the same runs;
- ns/step: the wall time of ``learn`` over the steps, greedy evaluations excluded, after an
  untimed warm-up run that loads the compiled kernels.

``summary.json`` holds the full table (``table``: one row per setting and agent, every metric
with its 95 % CI). The claims, per setting, with verdicts computed from the runs by
:mod:`.common`'s rules (each row's ``criterion`` states its own):

- DeconvQ learned walks the optimal loop on at least 95 % of the seeds: the count rule (the
  Wilson 95 % interval inside [0.95, 1]; at 20 seeds at best ``inconclusive``);
- DeconvQ learned's training reward within 5 % of the oracle's (per seed, relative to the
  oracle's mean): the band 0 ± 0.05;
- DeconvQ learned's mean delay: the band λ ± 10 %;
- MMQ walks the optimal loop on at least 95 % of the seeds (the thesis's Fig. 5.9 and Table 5.1
  result, here carried to other worlds and delays): the count rule, as DeconvQ's;
- MMQ's greedy snapshots in the second half are optimal at least 90 % of the time (CI inside);
- MMQ earns more than delayed Q-learning during learning (paired by seed, the direction rule).

Figures, per setting: learning curves with 95 % bands, the delay estimates over the true pmf,
and the share of seeds whose greedy policy is optimal at each snapshot.

The pieces shared with ``future-work`` (:mod:`.future_work`, MMQ variants on the same settings)
live here: :func:`grid_tasks`, :func:`measure`, :func:`result_table`, :func:`agent_stats` and
:func:`setting_figures`.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_bool, check_choice, check_int
from delayed_rl.agents.mmq import greedy_actions
from delayed_rl.delays import Delay, Empirical, Geometric, Poisson
from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import (
    band_claim,
    count_claim,
    direction_claim,
    mean_ci_n,
    paired,
    range_claim,
)
from delayed_rl.experiments.runner import (
    Claim,
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    running_average,
)
from delayed_rl.experiments.training import thesis_hyperparameters

#: (side, mean delay λ, steps a run) of the two worlds.
SETTINGS = ((9, 13, 1_000_000), (7, 8, 300_000))
QUICK_SIZE, QUICK_LAM, QUICK_STEPS = 7, 8, 30_000
#: The three delay distributions of each world, all of mean λ (:func:`make_delay`).
DELAYS = ("Poisson", "geometric", "bimodal")
LAMBDA_MAX = 50
"""The longest delay any learner models: MMQ's λ̂max, DeconvQ's ``max_delay``, expected credit's
last lag."""
#: The seven learners, in the tables' order (:func:`make_agent`).
AGENTS = (
    "Q",
    "MMQ",
    "expected credit",
    "DeconvQ known",
    "DeconvQ learned",
    "oracle",
    "Q undelayed",
)
LOOP_FRACTION = 0.95
"""A greedy average this close to the optimum means the optimal loop: on 9×9, over 1000 steps the
17-step loop scores 58 rewards (0.580, 0.986 of 10/17), the next shortest, 19 steps, 0.895 of it."""
SNAPSHOTS = 50
"""Greedy snapshots a run takes: one every ``max(1, steps // SNAPSHOTS)`` steps."""
WALK_STEPS = 1000
WINDOW_DIVISOR = 10
"""MMQ's runs keep a greedy window of ``steps // WINDOW_DIVISOR`` steps (100k of 1M): the
averaged table ``future-work``'s greedy-window variant reads (:func:`make_agent`)."""
AVERAGED = "window_"
"""The prefix of :func:`measure`'s readouts of the averaged table (MMQ's ``greedy_window``)."""
WARM_UP = 2000
"""Steps of the untimed warm-up run before each timed one (:func:`warm_up`): past DeconvQ's
first solve, so every kernel of the run is loaded."""
#: The claims' rules: a share of seeds optimal, a relative reward gap, a relative delay error
#: and the share of second-half snapshots that are optimal.
SEED_SHARE, REWARD_TOLERANCE, DELAY_TOLERANCE, STABLE_SHARE = 0.95, 0.05, 0.10, 0.90


def make_delay(kind: str, lam: float) -> Delay:
    """The delay of mean ``lam``: ``"Poisson"``, ``"geometric"`` or ``"bimodal"`` (½ at 0, ½ at 2λ).

    Raises:
        TypeError: ``kind`` is not a string, or ``lam`` (bimodal) not an integer.
        ValueError: ``kind`` is not one of :data:`DELAYS`, or ``lam`` is out of range.
    """
    check_choice("kind", kind, DELAYS)
    if kind == "Poisson":
        return Poisson(lam)
    if kind == "geometric":
        return Geometric(1.0 / (lam + 1.0))  # mean (1 − p) / p = λ
    lam = check_int("lam", lam, 1)
    pmf = np.zeros(2 * lam + 1)
    pmf[0] = pmf[-1] = 0.5
    return Empirical(pmf)


def setting_label(size: int, kind: str, lam: float) -> str:
    """A setting's name in the tables and figures, e.g. ``"7×7 Poisson(8)"``."""
    names = {
        "Poisson": f"Poisson({lam:g})",
        "geometric": f"geometric (mean {lam:g})",
        "bimodal": f"bimodal {{0, {2 * lam:g}}}",
    }
    return f"{size}×{size} {names[kind]}"


def grid_tasks(config: Config, agents: Sequence[str]) -> list[dict]:
    """One task per (setting, agent, seed): :data:`SETTINGS` × :data:`DELAYS`, or the quick one.

    ``config.steps`` replaces every setting's own step count.

    Returns:
        Dicts with ``setting`` (its label), ``size``, ``lam``, ``delay`` (the kind), ``agent``,
        ``steps`` and ``seed``.
    """
    if config.quick:
        worlds, kinds = [(QUICK_SIZE, QUICK_LAM, QUICK_STEPS)], ("Poisson",)
    else:
        worlds, kinds = SETTINGS, DELAYS
    return [
        {
            "setting": setting_label(size, kind, lam),
            "size": size,
            "lam": lam,
            "delay": kind,
            "agent": agent,
            "steps": config.steps or steps,
            "seed": config.base_seed + i,
        }
        for size, lam, steps in worlds
        for kind in kinds
        for agent in agents
        for i in range(config.seeds)
    ]


def tasks(config: Config) -> list[dict]:
    """Every (setting, agent, seed) of the seven :data:`AGENTS` (see :func:`grid_tasks`)."""
    return grid_tasks(config, AGENTS)


def grid(size: int, delay: Delay | None = None, record_arrivals: bool = False) -> gym.Env:
    """``delayed_rl/GridWorld-v0`` of side ``size``, its reward delayed by ``delay`` (if any).

    Args:
        size: the grid's side.
        delay: the reward delay (``None``: undelayed).
        record_arrivals: report ``info["reward_arrivals"]`` (what the oracle reads); the
            :class:`~delayed_rl.wrappers.RewardDelay` is then put on top of ``gym.make``'s env.
    """
    import delayed_rl  # noqa: F401  (registers the ids)

    if record_arrivals:
        from delayed_rl.wrappers import RewardDelay

        return RewardDelay(
            gym.make("delayed_rl/GridWorld-v0", size=size), delay, record_arrivals=True
        )
    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=delay)


def hyperparameters(seed: int) -> dict[str, Any]:
    """The thesis's grid-world hyper-parameters (:mod:`.training`), seeded."""
    return thesis_hyperparameters(seed)


def make_agent(name: str, size: int, delay: Delay, seed: int, steps: int | None = None) -> Any:
    """One of :data:`AGENTS` on its own ``size`` grid under ``delay`` (see the module docstring).

    Given the run's ``steps``, MMQ also keeps the averaged table of a greedy window of
    ``steps // WINDOW_DIVISOR`` steps (``greedy_window``), which changes nothing of how it learns
    or acts: :func:`measure` reads both greedy policies off the one run.

    Raises:
        TypeError: ``name`` is not a string, or ``steps`` not an integer.
        ValueError: ``name`` is not one of :data:`AGENTS`, or ``steps`` < 1.
    """
    from delayed_rl import agents

    check_choice("agent", name, AGENTS)
    steps = check_int("steps", steps, 1, optional=True)
    common = hyperparameters(seed)
    if name == "Q undelayed":
        return agents.QLearning(grid(size), **common)
    if name == "oracle":
        return agents.OracleQLearning(grid(size, delay, record_arrivals=True), **common)
    env = grid(size, delay)
    if name == "Q":
        return agents.QLearning(env, **common)
    if name == "MMQ":
        window = None if steps is None else max(1, steps // WINDOW_DIVISOR)
        return agents.MultipleModelQLearning(
            env, max_delay_estimate=LAMBDA_MAX, greedy_window=window, **common
        )
    if name == "expected credit":
        return agents.ExpectedCreditQLearning(env, delay=delay, max_delay=LAMBDA_MAX, **common)
    known = delay if name == "DeconvQ known" else None
    return agents.DeconvolutionQLearning(env, delay=known, max_delay=LAMBDA_MAX, **common)


def optimal_average(size: int) -> float:
    """The optimal loop's reward per step on the ``size`` grid: ``10 / (2(size − 1) + 1)``."""
    return 10.0 / (2 * (size - 1) + 1)


@functools.lru_cache(maxsize=8)
def _dynamics(size: int) -> tuple[list[list[int]], list[list[float]], int]:
    """The undelayed grid's ``next_state`` and ``reward_table`` (as lists) and its start cell."""
    env = grid(size).unwrapped
    return env.next_state.tolist(), env.reward_table.tolist(), int(env.start_state)


def walk_average(policy: Sequence[int] | np.ndarray, size: int, steps: int = WALK_STEPS) -> float:
    """Average reward of the deterministic ``policy`` walked ``steps`` steps from the start cell.

    The undelayed grid's dynamics are deterministic, so this is what
    :func:`~delayed_rl.experiments.training.greedy_average_reward` measures, for any policy.

    Args:
        policy: the action of every cell (0-based, row-major).
        size: the grid's side.
        steps: how many steps to walk.
    """
    check_int("steps", steps, 1)
    return _walk_average(tuple(np.asarray(policy, dtype=np.int64).tolist()), size, steps)


@functools.lru_cache(maxsize=4096)
def _walk_average(actions: tuple[int, ...], size: int, steps: int) -> float:
    """:func:`walk_average` of one policy (cached: a settled run snapshots the same policy)."""
    next_state, reward, state = _dynamics(size)
    total = 0.0
    for _ in range(steps):
        action = actions[state]
        total += reward[state][action]
        state = next_state[state][action]
    return total / steps


def is_optimal(policy: Sequence[int] | np.ndarray, size: int) -> bool:
    """Whether ``policy``'s 1000-step walk scores ``LOOP_FRACTION`` of the optimal loop."""
    return walk_average(policy, size) >= LOOP_FRACTION * optimal_average(size)


def greedy_policy(agent: Any, averaged: bool = False) -> np.ndarray:
    """The agent's deterministic greedy action in every state.

    MMQ's is read off its current Q-table (the thesis's readout), or with ``averaged`` off the
    averaged table of its ``greedy_window`` (``greedy_table``); any other agent's is
    ``predict(..., deterministic=True)``.

    Raises:
        TypeError: ``averaged`` is not a bool.
    """
    averaged = check_bool("averaged", averaged)
    if hasattr(agent, "greedy_table"):
        return greedy_actions(np.asarray(agent.greedy_table if averaged else agent.q_table))
    states = np.arange(agent.observation_space.n)
    return np.asarray(agent.predict(states, deterministic=True)[0])


def train_with_snapshots(
    agent: Any, steps: int, size: int, keep_obs: bool = False
) -> dict[str, Any]:
    """Train ``agent`` for ``steps`` in pieces, recording whether its greedy policy is optimal.

    ``learn(..., reset_num_timesteps=False)`` continues the run (clock, episode, pending rewards,
    random streams, the acting-model counts), so the pieces train exactly as one
    ``learn(steps)`` call.

    Args:
        agent: the agent to train (on its env).
        steps: how many steps in all.
        size: the grid's side, for the greedy walks.
        keep_obs: also return ``obs``, the observation of every step.

    Returns:
        ``rewards`` (the undelayed reward of every step), ``learn_seconds`` (the wall time of
        the ``learn`` calls), ``snapshot_steps``, ``snapshot_optimal`` (bool) and
        ``snapshot_greedy`` (the walk's average) per snapshot, ``path`` (``learn``'s last), and
        ``obs`` with ``keep_obs``. An agent with a ``greedy_window`` has its averaged table's
        snapshots too, as ``window_snapshot_optimal`` and ``window_snapshot_greedy``.
    """
    steps = check_int("steps", steps, 1)
    interval = max(1, steps // SNAPSHOTS)
    readouts = {"": False}
    if getattr(agent, "greedy_window", None) is not None:
        readouts[AVERAGED] = True
    rewards, observations, marks = [], [], []
    optimal: dict[str, list[bool]] = {prefix: [] for prefix in readouts}
    greedy: dict[str, list[float]] = {prefix: [] for prefix in readouts}
    seconds, done = 0.0, 0
    while done < steps:
        piece = min(interval, steps - done)
        started = time.perf_counter()
        agent.learn(piece, log_interval=None, record=True, reset_num_timesteps=done == 0)
        seconds += time.perf_counter() - started
        done += piece
        rewards.append(agent.training_log["undelayed_reward"])
        if keep_obs:
            observations.append(agent.training_log["obs"])
        marks.append(done)
        for prefix, averaged in readouts.items():
            average = walk_average(greedy_policy(agent, averaged), size)
            greedy[prefix].append(average)
            optimal[prefix].append(average >= LOOP_FRACTION * optimal_average(size))
    out: dict[str, Any] = {
        "rewards": np.concatenate(rewards),
        "learn_seconds": seconds,
        "snapshot_steps": np.asarray(marks, dtype=np.int64),
        "path": agent.last_learn_path,
    }
    for prefix in readouts:
        out[f"{prefix}snapshot_optimal"] = np.asarray(optimal[prefix], dtype=bool)
        out[f"{prefix}snapshot_greedy"] = np.asarray(greedy[prefix])
    if keep_obs:
        out["obs"] = np.concatenate(observations)
    return out


def second_half_share(
    snapshot_steps: np.ndarray, snapshot_optimal: np.ndarray, steps: int
) -> float:
    """The share of the snapshots after half of ``steps`` whose greedy policy is optimal.

    With no snapshot after half the steps (fewer than two snapshots), the last one's.
    """
    late = np.asarray(snapshot_steps) > steps / 2
    if not late.any():
        late[-1] = True
    return float(np.asarray(snapshot_optimal)[late].mean())


def delay_estimate(agent: Any) -> dict[str, Any]:
    """What ``agent`` believes of the delay: DeconvQ's pmf, MMQ's acting share (else nothing).

    Returns:
        ``estimate_support`` (the delays the estimate is over), ``estimate`` (a distribution
        over them: DeconvQ's ``delay_pmf``, MMQ's ``acting_delay_share``) and ``mean_delay``
        (its mean), or ``{}`` for agents that hold no estimate.
    """
    if hasattr(agent, "delay_pmf"):
        pmf = np.asarray(agent.delay_pmf)
        support = np.arange(pmf.size)
        return {"estimate_support": support, "estimate": pmf, "mean_delay": float(agent.mean_delay)}
    if hasattr(agent, "acting_delay_share") and len(agent.delay_estimates) > 1:
        share = np.asarray(agent.acting_delay_share)
        support = np.asarray(agent.delay_estimates, dtype=np.int64)
        return {
            "estimate_support": support,
            "estimate": share,
            "mean_delay": float(np.sum(share * support)),
        }
    return {}


def measure(agent: Any, task: dict) -> dict[str, Any]:
    """Train ``agent`` for ``task["steps"]`` on ``task["size"]``'s grid and measure the run.

    Returns:
        ``steps`` and ``curve`` (the running average reward), ``average`` (the training mean
        reward), ``greedy`` (the final greedy 1000-step average) and ``optimal``, the snapshot
        arrays of :func:`train_with_snapshots`, ``second_half_optimal`` (the share of snapshots
        after half the steps that are optimal), ``ns_per_step``, ``path``, and the
        :func:`delay_estimate`. With a ``greedy_window``, the averaged table's readouts too:
        ``greedy``, ``optimal``, ``second_half_optimal`` and the snapshot arrays prefixed
        :data:`AVERAGED` (:func:`averaged_readout` puts them in place of the others).
    """
    run = train_with_snapshots(agent, task["steps"], task["size"])
    rewards = run.pop("rewards")
    steps, curve = running_average(rewards)
    out = {
        "steps": steps,
        "curve": curve,
        "average": float(rewards.mean()),
        "ns_per_step": 1e9 * run.pop("learn_seconds") / task["steps"],
        **run,
        **delay_estimate(agent),
    }
    for prefix in ("", AVERAGED):
        if f"{prefix}snapshot_optimal" in run:
            snapshots = run[f"{prefix}snapshot_optimal"]
            out[f"{prefix}greedy"] = float(run[f"{prefix}snapshot_greedy"][-1])
            out[f"{prefix}optimal"] = bool(snapshots[-1])
            out[f"{prefix}second_half_optimal"] = second_half_share(
                run["snapshot_steps"], snapshots, task["steps"]
            )
    return out


def current_readout(result: dict[str, Any]) -> dict[str, Any]:
    """A :func:`measure` result with the readouts of the current table only (as MMQ acts)."""
    return {key: value for key, value in result.items() if not key.startswith(AVERAGED)}


def averaged_readout(result: dict[str, Any]) -> dict[str, Any]:
    """A :func:`measure` result whose greedy readouts are the averaged table's (greedy window).

    Raises:
        ValueError: the run kept no averaged table.
    """
    averaged = {k[len(AVERAGED) :]: v for k, v in result.items() if k.startswith(AVERAGED)}
    if not averaged:
        raise ValueError("the run kept no averaged table (an MMQ run without greedy_window)")
    return {**current_readout(result), **averaged}


_WARMED: set[str] = set()
"""The kinds of agent already warmed up in this process (see :func:`warm_up`)."""


def warm_up(make: Callable[[], Any], steps: int, kind: str) -> None:
    """Train a throw-away agent ``make()`` for ``min(steps, WARM_UP)`` steps, untimed, once.

    The first ``learn`` of a compiled agent in a process loads its kernels (seconds); the
    warm-up pays that, so ns/step measures training alone. It is done once per ``kind`` of
    agent (its kernels) in a process: a worker's later runs of that kind find them loaded.
    """
    if kind not in _WARMED:
        make().learn(min(steps, WARM_UP), log_interval=None)
        _WARMED.add(kind)


def run_task(task: dict) -> dict:
    """Train one agent of :data:`AGENTS` in its setting and :func:`measure` it."""
    delay = make_delay(task["delay"], task["lam"])
    size, seed, steps = task["size"], task["seed"], task["steps"]
    warm_up(lambda: make_agent(task["agent"], size, delay, seed + 1, steps), steps, task["agent"])
    return measure(make_agent(task["agent"], size, delay, seed, steps), task)


def shared_run(task: dict) -> SharedRun | None:
    """The one run behind a world's undelayed Q-learning (the same under every delay kind).

    MMQ's tasks read its current table (:func:`current_readout`); every other task is its own
    run.
    """
    if task["agent"] == "MMQ":
        return SharedRun(run_task, task, current_readout)
    if task["agent"] != "Q undelayed":
        return None
    kind = DELAYS[0]
    label = setting_label(task["size"], kind, task["lam"])
    return SharedRun(run_task, {**task, "delay": kind, "setting": label})


#: Compiled training cost per step (µs) of each learner on these grids, for scheduling only.
STEP_MICROSECONDS = {"DeconvQ learned": 1.8, "DeconvQ known": 0.9, "MMQ": 0.8}


def cost(task: dict) -> float:
    """A task's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 0.7 µs)."""
    return 1e-6 * task["steps"] * STEP_MICROSECONDS.get(task["agent"], 0.7)


# ---------------------------------------------------------------------- summaries
def group_runs(task_list: list[dict], results: list[dict]) -> dict[str, dict[str, list[tuple]]]:
    """``{setting: {agent: [(task, result), ...]}}``, in the order of ``task_list``."""
    groups: dict[str, dict[str, list[tuple]]] = {}
    for task, result in zip(task_list, results, strict=True):
        groups.setdefault(task["setting"], {}).setdefault(task["agent"], []).append((task, result))
    return groups


def agent_stats(runs: list[tuple[dict, dict]]) -> dict[str, Any]:
    """One row of the table: one agent's metrics in one setting, over its seeds.

    Args:
        runs: the agent's ``(task, result)`` pairs, one per seed.

    Returns:
        ``optimal_seeds`` and ``seeds`` (k of n), then ``(mean, ci95, n)`` of ``greedy``,
        ``average`` (training), ``second_half_optimal``, ``ns_per_step`` and, when the agent
        estimates the delay, ``mean_delay``; with ``true_mean_delay``.
    """
    task0 = runs[0][0]
    results = [result for _, result in runs]
    row: dict[str, Any] = {
        "optimal_seeds": int(sum(r["optimal"] for r in results)),
        "seeds": len(results),
    }
    for key in ("greedy", "average", "second_half_optimal", "ns_per_step"):
        row[key] = mean_ci_n([r[key] for r in results])
    if all("mean_delay" in r for r in results):
        row["mean_delay"] = mean_ci_n([r["mean_delay"] for r in results])
    row["true_mean_delay"] = make_delay(task0["delay"], task0["lam"]).mean
    row["paths"] = sorted({r["path"] for r in results})
    return row


def result_table(groups: dict[str, dict[str, list[tuple]]]) -> list[dict[str, Any]]:
    """The full table for ``summary.json``: one :func:`agent_stats` row per (setting, agent)."""
    table = []
    for setting, by_agent in groups.items():
        for agent, runs in by_agent.items():
            row = agent_stats(runs)
            flat: dict[str, Any] = {"setting": setting, "agent": agent}
            for key, value in row.items():
                if isinstance(value, tuple):
                    flat[key], flat[f"{key}_ci95"], flat[f"{key}_n"] = value
                else:
                    flat[key] = value
            table.append(flat)
    return table


def optimal_seeds_claim(
    agent: str, runs: list[tuple], thesis: str, low: float = SEED_SHARE, high: float = 1.0
) -> Claim:
    """``agent``'s seeds whose final greedy policy is optimal, k of n: the share in [low, high].

    The count rule (:func:`~delayed_rl.experiments.common.count_claim`): the Wilson 95 %
    interval of the share against the band, ``[SEED_SHARE, 1]`` by default.
    """
    flags = [bool(result["optimal"]) for _, result in runs]
    return count_claim(
        f"{runs[0][0]['setting']}: {agent} seeds whose greedy policy is optimal",
        thesis,
        sum(flags),
        len(flags),
        low,
        high,
        note=f"optimal: a 1000-step greedy walk ≥ {LOOP_FRACTION} of the loop",
    )


def _by_seed(runs: list[tuple], key: str) -> dict[int, float]:
    return {task["seed"]: result[key] for task, result in runs}


def paired_gap_claim(
    quantity: str, thesis: str, runs: list[tuple], baseline: list[tuple], key: str = "average"
) -> Claim:
    """``runs`` above ``baseline`` on ``key``: the direction rule on the paired-by-seed difference."""
    gaps = paired(_by_seed(runs, key), _by_seed(baseline, key))
    return direction_claim(quantity, thesis, mean_ci_n(gaps), "above", note="paired by seed")


def relative_gap_claim(
    quantity: str, thesis: str, runs: list[tuple], baseline: list[tuple], tolerance: float
) -> Claim:
    """``runs``' training reward within ``tolerance`` of ``baseline``'s, relative, by seed.

    The statistic is ``(ours_s − theirs_s) / mean(theirs)`` per seed ``s``, tested against the
    band 0 ± ``tolerance``. A baseline that earns nothing on average (mean ≤ 0) leaves no
    relative gap: NaN, and the claim is inconclusive.
    """
    ours, theirs = _by_seed(runs, "average"), _by_seed(baseline, "average")
    seeds = [seed for seed in ours if seed in theirs]
    scale = float(np.mean([theirs[s] for s in seeds])) if seeds else math.nan
    if not seeds or not scale > 0:
        stats = (math.nan, math.nan, len(seeds))
    else:
        stats = mean_ci_n([g / scale for g in paired(ours, theirs)])
    return band_claim(
        quantity, thesis, stats, 0.0, tolerance, note="(ours − theirs) / mean(theirs), by seed"
    )


def delay_claim(quantity: str, runs: list[tuple]) -> Claim:
    """The estimated mean delay against the true mean ± ``DELAY_TOLERANCE`` of it."""
    task0 = runs[0][0]
    true = make_delay(task0["delay"], task0["lam"]).mean
    stats = mean_ci_n([result["mean_delay"] for _, result in runs])
    return band_claim(
        quantity, f"extension: the true mean {true:g}", stats, true, DELAY_TOLERANCE * true
    )


def stability_claim(
    agent: str, runs: list[tuple], thesis: str, low: float = STABLE_SHARE, high: float = 1.0
) -> Claim:
    """``agent``'s share of second-half greedy snapshots that are optimal, in [low, high].

    Per seed, the share of its snapshots after half the steps that are optimal; the 95 % CI
    of its mean over the seeds against the band (``[STABLE_SHARE, 1]`` by default).
    """
    stats = mean_ci_n([result["second_half_optimal"] for _, result in runs])
    return range_claim(
        f"{runs[0][0]['setting']}: {agent} share of second-half greedy snapshots optimal",
        thesis,
        stats,
        low,
        high,
        note="per seed, the share of its snapshots after half the steps that are optimal",
    )


def _setting_claims(setting: str, by_agent: dict[str, list[tuple]]) -> list[Claim]:
    """The claims of one setting (see the module docstring), for the agents it ran."""
    claims = []
    poisson = "Poisson" in setting
    mmq_thesis = (
        "near-optimal greedy policy (Figs. 5.9, Table 5.1: 9×9, Poisson(13))"
        if poisson
        else "extension: as under Poisson (Fig. 5.9)"
    )
    deconv = by_agent.get("DeconvQ learned")
    if deconv:
        claims.append(optimal_seeds_claim("DeconvQ learned", deconv, "extension: ≥ 95 % of seeds"))
        if "oracle" in by_agent:
            claims.append(
                relative_gap_claim(
                    f"{setting}: DeconvQ learned training reward relative to the oracle's",
                    "extension: within 5 % of the oracle's",
                    deconv,
                    by_agent["oracle"],
                    REWARD_TOLERANCE,
                )
            )
        claims.append(delay_claim(f"{setting}: DeconvQ learned mean delay", deconv))
    mmq = by_agent.get("MMQ")
    if mmq:
        claims.append(optimal_seeds_claim("MMQ", mmq, mmq_thesis))
        claims.append(
            stability_claim("MMQ", mmq, "extension: a settled greedy policy (≥ 90 % optimal)")
        )
        if "Q" in by_agent:
            claims.append(
                paired_gap_claim(
                    f"{setting}: MMQ minus delayed Q training reward",
                    "MMQ above Q (Fig. 5.9)" if poisson else "extension: MMQ above Q",
                    mmq,
                    by_agent["Q"],
                )
            )
    return claims


def curves_of(task_list: list[dict], results: list[dict]) -> list[Curve]:
    """The learning curves and the snapshot optimality of every run, for ``curves.csv``."""
    curves = []
    for task, result in zip(task_list, results, strict=True):
        condition = f"{task['setting']} | {task['agent']}"
        curves.append(Curve(condition, task["seed"], result["steps"], result["curve"]))
        curves.append(
            Curve(
                condition,
                task["seed"],
                result["snapshot_steps"],
                result["snapshot_optimal"].astype(np.float64),
                "greedy_optimal",
            )
        )
    return curves


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims per setting, the full table (``extra["table"]``) and the figures."""
    groups = group_runs(task_list, results)
    claims = [c for setting, by_agent in groups.items() for c in _setting_claims(setting, by_agent)]
    extra = {
        "table": result_table(groups),
        "rules": {
            "loop_fraction": LOOP_FRACTION,
            "seed_share": SEED_SHARE,
            "reward_tolerance": REWARD_TOLERANCE,
            "delay_tolerance": DELAY_TOLERANCE,
            "stable_share": STABLE_SHARE,
            "snapshots": SNAPSHOTS,
            "lambda_max": LAMBDA_MAX,
        },
    }
    figures = setting_figures(groups, estimators=("DeconvQ learned", "MMQ"))
    return Summary(claims, curves_of(task_list, results), figures, extra)


# ---------------------------------------------------------------------- figures
def slug(setting: str) -> str:
    """A file-name form of a setting's label: ``"7×7 Poisson(8)"`` → ``"7x7_poisson"``."""
    size, kind = setting.split(" ", 1)
    return f"{size.replace('×', 'x')}_{kind.split('(')[0].split(' ')[0].lower()}"


def band_plot(
    path: Path,
    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]],
    title: str,
    xlabel: str,
    ylabel: str,
    ylim: tuple[float, float] | None = None,
    reference: tuple[float, str] | None = None,
) -> None:
    """Mean curve with a 95 % band per group; optional y-limits and a dashed reference line.

    Args:
        path: where to save the PNG.
        groups: ``{label: [(x, y), ...]}``, one pair per seed, the same ``x`` within a label.
        title: the title.
        xlabel: the x-axis label.
        ylabel: the y-axis label.
        ylim: the y-axis limits (``None``: the curves after their first 5 % and the reference
            line when there is one, else matplotlib's).
        reference: ``(y, label)`` of a horizontal dashed line, e.g. the optimum.
    """
    plt = plotting._pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 4.5))
    for label, runs in groups.items():
        x = runs[0][0]
        values = np.vstack([y for _, y in runs]).astype(float)
        mean = values.mean(axis=0)
        (line,) = ax.plot(x, mean, label=plotting.band_label(label, len(runs)))
        if len(runs) > 1:
            half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(runs))
            ax.fill_between(x, mean - half, mean + half, alpha=0.18, color=line.get_color())
    if reference is not None:
        ax.axhline(reference[0], color="black", linestyle="--", linewidth=1, label=reference[1])
    if ylim is None and reference is not None:  # the optimum in view, the first 5 % cut off
        settled = [y[x >= 0.05 * x[-1]] for runs in groups.values() for x, y in runs]
        low = min(float(np.min(y)) for y in settled if y.size)
        high = max(reference[0], max(float(np.max(y)) for y in settled if y.size))
        ylim = (low - 0.05 * (high - low), high + 0.08 * (high - low))
    if ylim is not None:
        ax.set_ylim(*ylim)
    plotting.outside_legend(ax)
    plotting._finish(fig, ax, path, title, xlabel, ylabel)


def estimate_plot(
    path: Path,
    estimates: dict[str, list[tuple[np.ndarray, np.ndarray]]],
    true_pmf: np.ndarray,
    title: str,
) -> None:
    """Delay estimates (mean over seeds with a 95 % band) over the true pmf's bars.

    Estimates over a coarser grid than every integer (MMQ with ``delay_step`` > 1) are drawn per
    unit of delay (divided by their spacing), so every curve is on the pmf's scale.

    Args:
        path: where to save the PNG.
        estimates: ``{label: [(support, distribution), ...]}``, one pair per seed.
        true_pmf: the true delay pmf on ``0, 1, ..., len − 1``.
        title: the title.
    """
    plt = plotting._pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 4.5))
    ax.bar(np.arange(true_pmf.size), true_pmf, color="0.8", width=1.0, label="true pmf")
    top = float(true_pmf.max())
    for label, runs in estimates.items():
        support = np.asarray(runs[0][0], dtype=float)
        spacing = float(np.diff(support).min()) if support.size > 1 else 1.0
        values = np.vstack([y for _, y in runs]) / spacing
        mean = values.mean(axis=0)
        (line,) = ax.plot(
            support, mean, marker=".", markersize=3, label=plotting.band_label(label, len(runs))
        )
        if len(runs) > 1:
            half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(runs))
            lower = np.maximum(mean - half, 0)
            ax.fill_between(support, lower, mean + half, alpha=0.25, color=line.get_color())
            top = max(top, float((mean + half).max()))
        top = max(top, float(mean.max()))
    ax.set_xlim(-1, max(true_pmf.size, LAMBDA_MAX + 1))
    ax.set_ylim(0, 1.1 * top)
    plotting.outside_legend(ax)
    plotting._finish(fig, ax, path, title, "delay (steps)", "probability (pmf) or share of steps")


def setting_figures(
    groups: dict[str, dict[str, list[tuple]]],
    estimators: Sequence[str],
    same_curves: Sequence[str] = (),
) -> dict[str, Callable[[Path], None]]:
    """Per setting: learning curves, the delay estimates of ``estimators``, optimal snapshots.

    Args:
        groups: what :func:`group_runs` returns.
        estimators: the agents whose delay estimates are drawn (those that have one).
        same_curves: agents left out of the learning curves because they train exactly as
            another one (the title says so).
    """
    figures = {}
    for setting, by_agent in groups.items():
        task0 = next(iter(by_agent.values()))[0][0]
        size, name = task0["size"], slug(setting)
        optimum = (optimal_average(size), f"optimal loop ({optimal_average(size):.3f})")
        curves = {
            a: [(r["steps"], r["curve"]) for _, r in runs]
            for a, runs in by_agent.items()
            if a not in same_curves
        }
        left_out = [a for a in same_curves if a in by_agent]
        suffix = f"\n({', '.join(left_out)}: the same curve as the thesis rule)" if left_out else ""
        thesis = ""  # the thesis's Poisson statement, in words (Fig. 5.9 gives no value here)
        if "Poisson" in setting:
            above = ", above Q" if "Q" in by_agent else ""
            thesis = f"\nthesis (Poisson, Fig. 5.9): MMQ near-optimal{above}"
        snaps = {
            a: [(r["snapshot_steps"], r["snapshot_optimal"]) for _, r in runs]
            for a, runs in by_agent.items()
        }
        figures[f"learning_curves_{name}"] = plotting.figure(
            band_plot,
            curves,
            f"{setting}: average reward during learning{thesis}{suffix}",
            "time step",
            "average reward (undelayed)",
            None,
            optimum,
        )
        figures[f"optimal_snapshots_{name}"] = plotting.figure(
            band_plot,
            snaps,
            f"{setting}: share of seeds whose greedy policy is optimal{thesis}",
            "time step",
            "share of seeds optimal",
            (-0.05, 1.05),
        )
        estimates = {
            a: [(r["estimate_support"], r["estimate"]) for _, r in by_agent[a]]
            for a in estimators
            if a in by_agent and all("estimate" in r for _, r in by_agent[a])
        }
        if estimates:
            delay = make_delay(task0["delay"], task0["lam"])
            true_pmf = np.asarray(delay.pmf(np.arange(LAMBDA_MAX + 1)), dtype=float)
            labels = {"MMQ": "MMQ acting share", "DeconvQ learned": "DeconvQ learned pmf"}
            estimates = {labels.get(a, a): runs for a, runs in estimates.items()}
            figures[f"delay_estimate_{name}"] = plotting.figure(
                estimate_plot,
                estimates,
                true_pmf,
                f"{setting}: delay estimates against the true pmf",
            )
    return figures


EXPERIMENT = Experiment(
    name="anonymous-delay",
    thesis="beyond the thesis (its future work; Figs. 5.9, Table 5.1 for MMQ)",
    description="Q-learning, MMQ (Λ = {0..50}), expected-credit Q-learning and deconvolution "
    "Q-learning (delay known or learned on 0..50) against the oracle (told each reward's "
    "transition) and undelayed Q-learning, on the 9×9 grid (λ = 13, 1M steps) and the 7×7 grid "
    "(λ = 8, 300k steps) under Poisson, geometric and bimodal (½ at 0, ½ at 2λ) delays of mean "
    "λ; α = 0.1, γ = 0.9, ε = 0.1, q_init = 25. Greedy policies walked 1000 steps (optimal: ≥ "
    "0.95 of the loop), snapshotted 50 times a run; delay estimates; ns/step. The full table "
    "is summary.json's `table`.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=20,
    shared_run=shared_run,
    cost=cost,
)

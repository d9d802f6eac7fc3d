"""``late-observations`` (beyond the thesis): SAC when observations and actions arrive late.

Each setting is Pendulum-v1 (200-step episodes) under random observation and action delays,
observations arriving by the stale-sensor rule (:class:`~delayed_rl.wrappers.ObservationDelay`),
SAC with SB3's defaults for 20k steps (:data:`SETTINGS`):

- ``pendulum-small``: observation delay U{0..3}, action delay U{1..2} (the view keeps K = 5
  actions);
- ``pendulum-large``: U{0..6} and U{1..4} (K = 10).

The methods (:mod:`~delayed_rl.experiments.framework.late_training`): the undelayed oracle,
naive SAC on the delayed stream, augmented SAC on the delay-aware view, and
:class:`~delayed_rl.deep.HindsightSAC` (the delay-specific learner), 5 seeds each, and a random
policy. A score is the mean return of 10 deterministic episodes of the env the method acts in;
its *gain* is ``(score − random) / (oracle − random)`` with the random policy's and the oracle's
mean scores.

The claims, fixed before the run:

- small setting: HindsightSAC reaches gain ≥ 0.9 on ≥ 4 of 5 seeds at 20k steps (a rule on the
  seeds, with the share's Wilson interval beside it);
- large setting: HindsightSAC's gain minus augmented SAC's, paired by seed, has its 95 % CI above
  0 at 20k steps;
- the moonshot, reported either way: HindsightSAC's mean gain in the large setting above 0.8.

Every (setting, method) also has a reference row of its gain. ``--quick``: the small setting
for 1000 steps, 2 seeds. Runs are kept as they finish, so an interrupted run resumes. It needs
the ``sb3`` extra.
"""

from __future__ import annotations

import math
from typing import Any

from delayed_rl.delays import Uniform
from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework.deep_training import require_sb3
from delayed_rl.experiments.framework.gain_settings import (
    gain_tasks,
    group_results,
    learning_curves,
    method_gains,
)
from delayed_rl.experiments.framework.late_training import (
    METHODS,
    random_score,
    train_and_score,
)
from delayed_rl.experiments.framework.runner import (
    Config,
    Experiment,
    SharedRun,
    Summary,
)


def _pendulum(observation: tuple[int, int], action: tuple[int, int]) -> dict[str, Any]:
    return {
        "env_id": "Pendulum-v1",
        "episode_steps": 200,
        "observation_delay": Uniform(*observation).to_dict(),
        "action_delay": Uniform(*action).to_dict(),
        "arrival": "stale",
        "steps": 20_000,
        "eval_every": 2000,
    }


#: Each setting's run fields (see the module docstring).
SETTINGS: dict[str, dict[str, Any]] = {
    "pendulum-small": _pendulum((0, 3), (1, 2)),
    "pendulum-large": _pendulum((0, 6), (1, 4)),
}
QUICK = {"pendulum-small": (1000, 500)}
"""The quick run's settings: their (steps, eval_every)."""
EVAL_EPISODES = 10
RANDOM_EPISODES = 100
"""Episodes that score the random policy (its mean is the gain's zero)."""
LABELS = {
    "oracle": "oracle (undelayed)",
    "naive": "naive SAC",
    "augmented": "augmented SAC",
    "hindsight": "HindsightSAC",
}
_RUN_FIELDS = (
    "env_id",
    "episode_steps",
    "observation_delay",
    "action_delay",
    "arrival",
    "steps",
    "eval_every",
)


def tasks(config: Config) -> list[dict]:
    """Every (setting, method, seed), and a ``random`` task per (setting, seed).

    Raises:
        ImportError: torch or stable-baselines3 is missing (the ``sb3`` extra).
    """
    require_sb3()
    return gain_tasks(config, SETTINGS, QUICK, (*METHODS, "random"))


def shared_run(task: dict) -> SharedRun:
    """The run behind a task, without what it does not depend on.

    The oracle's run has no delay (the settings share it); the random policy's depends only on
    the env and the seed.
    """
    if task["method"] in ("oracle", "random"):
        fields = {key: task[key] for key in ("env_id", "episode_steps", "seed")}
        if task["method"] == "random":
            return SharedRun(random_score, {**fields, "eval_episodes": RANDOM_EPISODES})
        fields.update(method="oracle", steps=task["steps"], eval_every=task["eval_every"])
        return SharedRun(train_and_score, {**fields, "eval_episodes": EVAL_EPISODES})
    run = {key: task[key] for key in (*_RUN_FIELDS, "method", "seed")}
    return SharedRun(train_and_score, {**run, "eval_episodes": EVAL_EPISODES})


def run_task(task: dict) -> dict:
    """A task's result, run on its own (:func:`shared_run`)."""
    return shared_run(task).alone()


def cost(task: dict) -> float:
    """Estimated core-seconds: SAC about 10 ms a step (for scheduling only)."""
    return 1.0 if task["method"] == "random" else 0.01 * task["steps"]


def _setting_claims(setting: str, gains: dict) -> list[rules.Claim]:
    """The target claims of ``setting`` (see the module docstring)."""
    if setting == "pendulum-small":
        return [
            rules.seed_rule_claim(
                f"{setting}: HindsightSAC, seeds with gain ≥ 0.9",
                "target: gain ≥ 0.9 on ≥ 4 of 5 seeds at 20k steps",
                list(gains["hindsight"].values()),
                0.9,
                math.ceil(0.8 * len(gains["hindsight"])),
            )
        ]
    if setting == "pendulum-large":
        paired = rules.paired(gains["hindsight"], gains["augmented"])
        return [
            rules.direction_claim(
                f"{setting}: HindsightSAC − augmented SAC gain",
                "target: above 0 (paired by seed) at 20k steps",
                rules.mean_ci_n(paired),
                "above",
            ),
            rules.direction_claim(
                f"{setting}: HindsightSAC gain (moonshot)",
                "moonshot: above 0.8",
                rules.mean_ci_n(list(gains["hindsight"].values())),
                "above",
                0.8,
            ),
        ]
    return []


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims, reference rows of every gain, the table and a learning-curve figure a setting."""
    grouped = group_results(task_list, results)
    claims, curves, figures, table = [], [], {}, {}
    for setting, by_method in grouped.items():
        gains, low, high = method_gains(by_method)
        claims += _setting_claims(setting, gains)
        table[setting] = {}
        for method in METHODS:
            values = list(gains[method].values())
            claims.append(
                rules.reference_row(f"{setting}: {LABELS[method]} gain", rules.mean_ci_n(values))
            )
            runs = by_method[method]
            scores = [r["score"] for r in runs.values()]
            table[setting][method] = {
                "seeds": sorted(runs),
                "score": dict(zip(("mean", "ci95"), rules.mean_ci_n(scores)[:2], strict=True)),
                "gain": dict(zip(("mean", "ci95"), rules.mean_ci_n(values)[:2], strict=True)),
                "gains": values,
                "scores": scores,
            }
        table[setting]["random"] = {"score": low}
        runs_curves, figures[f"curves_{setting}"] = learning_curves(
            setting, by_method, LABELS, low, "the env each method acts in"
        )
        curves += runs_curves
    return Summary(claims, curves, figures, {"table": table, "settings": SETTINGS})


EXPERIMENT = Experiment(
    name="late-observations",
    thesis="beyond the thesis (late observations and actions)",
    description="SB3's SAC on Pendulum-v1 under random observation and action delays (U{0..3} "
    "and U{1..2}; U{0..6} and U{1..4}), stale-sensor arrivals: the undelayed oracle, naive SAC, "
    "augmented SAC on the delay-aware view and HindsightSAC, 5 seeds, 20k steps; scores of 10 "
    "greedy episodes of the env each acts in, gains against a random policy and the oracle.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
    cost=cost,
    resumable=True,
)

"""Grid-world runs normalised by undelayed Q-learning (the thesis's Eq. 5.3).

The grid-world experiments ``delay-sweep``, ``world-size`` and ``estimate-error`` share one
design: for every seed and world size, an undelayed Q-learning *reference* run, and delayed
runs whose average reward is divided by the reference's. :func:`grid_tasks` builds those tasks,
:func:`grid_task` runs one (it is those experiments' ``run_task``), and :func:`normalised`
pairs each delayed run with its reference.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence

import numpy as np

from delayed_rl.experiments.framework.claims import mean_ci_n
from delayed_rl.experiments.framework.experiment import Config, Curve, running_average
from delayed_rl.experiments.framework.training import grid_env, train


def grid_tasks(config: Config, steps: int, runs: Sequence[dict]) -> list[dict]:
    """The tasks of a normalised grid-world experiment, for every seed of ``config``.

    Per seed, and per world size in the order ``runs`` first name it: the undelayed Q-learning
    reference run in that world, then each of ``runs`` in that world.

    Args:
        config: the seeds (``config.seeds`` of them, from ``config.base_seed``).
        steps: training steps of every run.
        runs: one dict per delayed condition: ``size`` (the world's side), ``lam`` (the Poisson
            mean delay), ``delay_estimates`` (Λ, ``[0]`` for Q-learning) and
            ``condition`` (its label), plus any keys its experiment's ``summarize`` reads.

    Returns:
        The task dicts :func:`grid_task` runs, each with its ``steps`` and ``seed``; reference
        runs have ``reference=True``.
    """
    sizes = list(dict.fromkeys(run["size"] for run in runs))
    out = []
    for i in range(config.seeds):
        seed = config.base_seed + i
        for size in sizes:
            reference = {"size": size, "lam": 0, "delay_estimates": [0], "condition": "undelayed"}
            out.append({**reference, "steps": steps, "seed": seed, "reference": True})
            out += [{**run, "steps": steps, "seed": seed} for run in runs if run["size"] == size]
    return out


def grid_task(task: dict) -> dict:
    """Train on ``GridWorld(size)`` with Poisson(``lam``) delays and ``delay_estimates``.

    Returns:
        The learning curve (``steps``, ``curve``: the running average reward) and the
        ``average`` reward over the whole run, from the undelayed reward stream.
    """
    agent = train(
        grid_env(task["size"], task["lam"]), task["delay_estimates"], task["steps"], task["seed"]
    )
    rewards = agent.training_log["undelayed_reward"]
    steps, curve = running_average(rewards)
    return {"steps": steps, "curve": curve, "average": float(rewards.mean())}


def _references(tasks: list[dict], results: list[dict]) -> dict:
    """The undelayed reference runs' results, keyed by ``(size, seed)``."""
    return {
        (task["size"], task["seed"]): result
        for task, result in zip(tasks, results, strict=True)
        if task.get("reference")
    }


def normalised(tasks: list[dict], results: list[dict]) -> dict:
    """Eq. 5.3 per delayed task: its average reward over that of the matching undelayed run.

    The curve is normalised step by step (NaN while the reference has earned nothing yet).

    Returns:
        ``{condition: [(seed, steps, normalised curve, normalised average), ...]}``, the
        conditions in the order of ``tasks``.
    """
    reference = _references(tasks, results)
    out = defaultdict(list)
    for task, result in zip(tasks, results, strict=True):
        if task.get("reference"):
            continue
        base = reference[(task["size"], task["seed"])]
        with np.errstate(divide="ignore", invalid="ignore"):
            curve = np.where(base["curve"] > 0, result["curve"] / base["curve"], np.nan)
        out[task["condition"]].append(
            (task["seed"], result["steps"], curve, result["average"] / base["average"])
        )
    return out


def curves_and_means(
    per_condition: dict,
) -> tuple[list[Curve], dict[str, tuple[float, float, int]]]:
    """Curves for the CSV and (mean, 95 % CI, n) of the normalised average per condition.

    Args:
        per_condition: what :func:`normalised` returns.
    """
    curves, stats = [], {}
    for condition, runs in per_condition.items():
        for seed, steps, curve, _ in runs:
            curves.append(Curve(condition, seed, steps, curve, "normalised_average_reward"))
        stats[condition] = mean_ci_n([average for *_, average in runs])
    return curves, stats


def learning_curve_groups(per_condition: dict) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """``{condition: [(steps, normalised curve), ...]}``: the groups a learning-curve figure draws.

    Args:
        per_condition: what :func:`normalised` returns.
    """
    return {c: [(steps, curve) for _, steps, curve, _ in runs] for c, runs in per_condition.items()}

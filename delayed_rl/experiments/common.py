"""Pieces shared by the grid-world experiments: a task runner and the normalisation of Eq. 5.3."""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from delayed_rl.experiments.runner import Claim, Curve, mean_ci95, running_average
from delayed_rl.experiments.training import grid_env, train


def grid_task(task: dict) -> dict:
    """Train on ``GridWorld(size)`` with Poisson(``lam``) delays and estimates ``lags``."""
    agent = train(grid_env(task["size"], task["lam"]), task["lags"], task["steps"], task["seed"])
    rewards = agent.training_log["undelayed_reward"]
    steps, curve = running_average(rewards)
    return {"steps": steps, "curve": curve, "average": float(rewards.mean())}


def normalised(tasks: list[dict], results: list[dict], reference: dict) -> dict:
    """Eq. 5.3 per task: its average reward over that of the matching undelayed run.

    ``reference`` maps ``(size, seed)`` to the undelayed Q-learning result of that world and seed.
    Returns ``{condition: [(seed, steps, normalised curve, normalised average)]}``.
    """
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


def references(tasks: list[dict], results: list[dict]) -> dict:
    """The undelayed runs, keyed by ``(size, seed)``."""
    return {
        (task["size"], task["seed"]): result
        for task, result in zip(tasks, results, strict=True)
        if task.get("reference")
    }


def curves_and_means(
    per_condition: dict,
) -> tuple[list[Curve], dict[str, tuple[float, float, int]]]:
    """Curves for the CSV and (mean, 95 % CI, n) of the normalised average per condition."""
    curves, stats = [], {}
    for condition, runs in per_condition.items():
        for seed, steps, curve, _ in runs:
            curves.append(Curve(condition, seed, steps, curve, "normalised_average_reward"))
        mean, ci = mean_ci95([average for *_, average in runs])
        stats[condition] = (mean, ci, len(runs))
    return curves, stats


def claim(
    quantity: str, thesis: str, stats: tuple[float, float, int], ok: bool, note: str = ""
) -> Claim:
    """A report row with verdict ``agrees`` or ``differs``."""
    mean, ci, n = stats
    return Claim(quantity, thesis, mean, ci, n, "agrees" if ok else "differs", note)

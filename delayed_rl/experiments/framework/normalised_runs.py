"""Grid-world runs normalised by undelayed Q-learning (the thesis's Eq. 5.3).

The grid-world experiments ``delay-sweep``, ``world-size`` and ``estimate-error`` share one
design: for every seed and world size, an undelayed Q-learning *reference* run, and delayed
runs whose average reward is divided by the reference's. :func:`grid_tasks` builds those tasks
(:func:`delay_grid_tasks` for a sweep of mean delays),
:func:`grid_task` runs one (it is those experiments' ``run_task``), and :func:`normalised`
pairs each delayed run with its reference; the experiments pivot its results by their own
fields (:func:`~.results.pivot`), into :func:`condition_means` and :func:`learning_curve_groups`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from delayed_rl.experiments.framework.claims import mean_ci_n
from delayed_rl.experiments.framework.experiment import Config, Curve, running_average
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.task import Task, optional
from delayed_rl.experiments.framework.training import grid_env, train


@dataclasses.dataclass(frozen=True, kw_only=True)
class GridTask(Task):
    """A run of a normalised grid-world experiment: Q-learning under Poisson reward delays.

    Attributes:
        condition: the run's label.
        size: the world's side.
        lam: the Poisson mean delay λ (0: undelayed).
        delay_estimates: the delay estimates Λ the agent models (``(0,)``: Q-learning).
        steps: training steps.
        reference: whether it is the undelayed Q-learning run the others are normalised by
            (optional: left out of the task's JSON when false).
    """

    condition: str
    size: int
    lam: int
    delay_estimates: tuple[int, ...]
    steps: int
    reference: bool = optional(False)


def grid_tasks(
    config: Config,
    steps: int,
    runs: Sequence[Mapping[str, Any]],
    kind: type[GridTask] = GridTask,
) -> list[GridTask]:
    """The tasks of a normalised grid-world experiment, for every seed of ``config``.

    Per seed, and per world size in the order ``runs`` first name it: the undelayed Q-learning
    reference run in that world, then each of ``runs`` in that world.

    Args:
        config: the seeds (``config.seeds`` of them, from ``config.base_seed``).
        steps: training steps of every run.
        runs: the fields of each delayed condition's tasks (all but ``steps`` and ``seed``).
        kind: the experiment's task type.

    Returns:
        The tasks :func:`grid_task` runs; reference runs have ``reference=True``.
    """
    sizes = list(dict.fromkeys(run["size"] for run in runs))
    out = []
    for i in range(config.seeds):
        seed = config.base_seed + i
        for size in sizes:
            out.append(
                kind(
                    condition="undelayed",
                    size=size,
                    lam=0,
                    delay_estimates=(0,),
                    steps=steps,
                    seed=seed,
                    reference=True,
                )
            )
            out += [kind(**run, steps=steps, seed=seed) for run in runs if run["size"] == size]
    return out


def delay_grid_tasks(
    config: Config,
    sizes: Sequence[int],
    lams: tuple[Sequence[int], Sequence[int]],
    steps: tuple[int, int],
    condition: Callable[[int, int], str],
) -> list[GridTask]:
    """Q-learning under each Poisson mean delay λ in each world, with :func:`grid_tasks`' references.

    Args:
        config: the seeds, and whether the run is quick.
        sizes: the worlds' sides.
        lams: the mean delays λ of a full run and of a quick one.
        steps: the steps of a run, full and quick (:meth:`~.experiment.Config.run_steps`).
        condition: a run's label from its world's side and its λ.
    """
    runs = [
        {"size": size, "lam": lam, "delay_estimates": (0,), "condition": condition(size, lam)}
        for size in sizes
        for lam in (lams[1] if config.quick else lams[0])
    ]
    return grid_tasks(config, config.run_steps(*steps), runs)


def grid_task(task: GridTask) -> dict:
    """Train on ``GridWorld(size)`` with Poisson(``lam``) delays and ``delay_estimates``.

    Returns:
        The learning curve (``steps``, ``curve``: the running average reward) and the
        ``average`` reward over the whole run, from the undelayed reward stream.
    """
    agent = train(grid_env(task.size, task.lam), list(task.delay_estimates), task.steps, task.seed)
    rewards = agent.training_log["undelayed_reward"]
    steps, curve = running_average(rewards)
    return {"steps": steps, "curve": curve, "average": float(rewards.mean())}


def _is_reference(task: GridTask) -> bool:
    return task.reference


def normalised(tasks: Sequence[GridTask], results: list[dict]) -> tuple[list[GridTask], list[dict]]:
    """Eq. 5.3 per delayed task: its average reward over that of the matching undelayed run.

    Each delayed task is matched with the reference run of its world size and seed. The curve
    is normalised step by step (NaN while the reference has earned nothing yet).

    Returns:
        The delayed tasks (the reference runs left out), in the order of ``tasks``, and one
        result per delayed task: its ``steps``, normalised ``curve`` and normalised
        ``average``, ready for :func:`~.results.pivot`.
    """
    references = pivot(tasks, results, by=("size",), where=_is_reference)
    delayed, out = [], []
    for task, result in zip(tasks, results, strict=True):
        if task.reference:
            continue
        base = references[task.size][task.seed]
        with np.errstate(divide="ignore", invalid="ignore"):
            curve = np.where(base["curve"] > 0, result["curve"] / base["curve"], np.nan)
        delayed.append(task)
        out.append(
            {
                "steps": result["steps"],
                "curve": curve,
                "average": result["average"] / base["average"],
            }
        )
    return delayed, out


def normalised_curves(tasks: Sequence[GridTask], normalised_results: list[dict]) -> list[Curve]:
    """The normalised curves for the CSV, condition by condition (each task's ``condition``).

    Args:
        tasks: the delayed tasks and their normalised results, as :func:`normalised` returns them.
        normalised_results: see ``tasks``.
    """
    return [
        Curve(condition, seed, run["steps"], run["curve"], "normalised_average_reward")
        for condition, runs in pivot(tasks, normalised_results, by=("condition",)).items()
        for seed, run in runs.items()
    ]


def condition_means(groups: dict) -> dict:
    """(mean, 95 % CI, n) of the normalised average of each group of :func:`~.results.pivot`.

    Args:
        groups: ``{key: {seed: normalised result}}``, a pivot of :func:`normalised`'s results.
    """
    return {
        key: mean_ci_n([run["average"] for run in runs.values()]) for key, runs in groups.items()
    }


def learning_curve_groups(groups: dict) -> dict:
    """``{key: [(steps, normalised curve), ...]}``: the groups a learning-curve figure draws.

    Args:
        groups: ``{key: {seed: normalised result}}``, a pivot of :func:`normalised`'s results.
    """
    return {
        key: [(run["steps"], run["curve"]) for run in runs.values()] for key, runs in groups.items()
    }

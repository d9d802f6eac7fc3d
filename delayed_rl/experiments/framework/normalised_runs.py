"""Grid-world runs normalised by undelayed Q-learning (the thesis's Eq. 5.3).

The grid-world experiments ``delay-sweep``, ``world-size`` and ``estimate-error`` share one
design: for every seed and world size, an undelayed Q-learning *reference* run, and delayed
runs whose average reward is divided by the reference's. :func:`grid_tasks` builds those tasks
(:func:`delay_grid_tasks` for a sweep of mean delays),
:func:`grid_task` runs one (it is those experiments' ``run_task``), and
:meth:`NormalisedRuns.of` pairs each delayed run with its reference and groups them by the
experiment's own fields.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from delayed_rl.experiments.framework.claims import mean_ci_n
from delayed_rl.experiments.framework.experiment import Config, Curve, running_average
from delayed_rl.experiments.framework.results import curve_groups, pivot
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


@dataclasses.dataclass(frozen=True)
class NormalisedRuns:
    """The delayed runs of a normalised grid-world experiment, grouped by task fields.

    Built by :meth:`of` from all the tasks and results; every view groups the runs by the
    fields ``by`` (:func:`~.results.pivot`), then by seed.

    Attributes:
        tasks: the delayed tasks (the reference runs left out), in the order given.
        results: one result per delayed task: its ``steps``, normalised ``curve`` and
            normalised ``average``.
        by: the task fields the runs are grouped by, e.g. ``("size", "lam")``.
    """

    tasks: list[GridTask]
    results: list[dict]
    by: tuple[str, ...]

    @classmethod
    def of(
        cls, tasks: Sequence[GridTask], results: list[dict], by: tuple[str, ...]
    ) -> NormalisedRuns:
        """Eq. 5.3 per delayed task: its average reward over that of the matching undelayed run.

        Each delayed task is matched with the reference run of its world size and seed. The
        curve is normalised step by step (NaN while the reference has earned nothing yet).

        Args:
            tasks: every task of the experiment, reference runs included.
            results: one result per task, as :func:`grid_task` returns it.
            by: the task fields the views group by.
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
        return cls(delayed, out, by)

    def groups(self) -> dict:
        """``{key: {seed: normalised result}}``, ``key`` the values of :attr:`by`."""
        return pivot(self.tasks, self.results, by=self.by)

    def averages(self) -> dict:
        """``{key: {seed: normalised average reward}}``: the per-seed values claims pair."""
        return pivot(self.tasks, self.results, by=self.by, value="average")

    def means(self) -> dict:
        """``{key: (mean, 95 % CI, n)}`` of the normalised average reward over the seeds."""
        return {key: mean_ci_n(list(runs.values())) for key, runs in self.averages().items()}

    def curve_groups(self) -> dict:
        """``{key: [(steps, normalised curve), ...]}``: the groups a learning-curve figure draws."""
        return curve_groups(self.groups())

    def curves(self) -> list[Curve]:
        """The normalised curves for the CSV, condition by condition (each task's ``condition``)."""
        return [
            Curve(condition, seed, run["steps"], run["curve"], "normalised_average_reward")
            for condition, runs in pivot(self.tasks, self.results, by=("condition",)).items()
            for seed, run in runs.items()
        ]

"""What an experiment is: its configuration, tasks, shared runs, claims, curves and summary.

An experiment module defines an :class:`Experiment`: ``tasks(config)`` (one task per
(condition, seed), a frozen dataclass of its own :class:`~.task.Task` type), ``run_task(task)``
or ``shared_run(task)`` (a task's dict of results, or the run that gives it) and
``summarize(tasks, results, config)`` (the claims checked against the thesis, as :class:`Claim`
rows, with curves and figures). :func:`~delayed_rl.experiments.framework.pool.run_experiment` runs the tasks on a
worker pool, each with its own seed, and
:func:`~delayed_rl.experiments.framework.report.write_outputs` writes the output folder; tasks
that need the same computation name it as one :class:`SharedRun`, run once. A claim's verdict
is one of :data:`VERDICTS`.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

import numpy as np

from delayed_rl._validation import check_bool, check_choice, check_int, check_limit
from delayed_rl.agents.common.hyperparameters import MAX_SEED_VALUE
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.experiments.framework.task import Task
from delayed_rl.parallel.pools import BACKENDS, MAX_SEED_COUNT, check_workers

AGREES, DIFFERS, INCONCLUSIVE, REFERENCE = "agrees", "differs", "inconclusive", "reference"


VERDICTS = (AGREES, DIFFERS, INCONCLUSIVE, REFERENCE)
"""A claim's possible verdicts.

A verdict is computed from the measurement's 95 % interval and the thesis's value by the rule
its ``criterion`` states (the helpers of :mod:`.claims` build every row and its criterion):

- ``agrees``: the interval lies inside the thesis's band, or wholly on the claimed side;
- ``differs``: it lies wholly outside the band, or wholly on the other side;
- ``inconclusive``: it straddles an edge (too few seeds, or too much spread, to tell), or the
  measurement could not be formed (NaN);
- ``reference``: the row is a number shown for context (e.g. undelayed Q-learning's reward)
  with no thesis value to test. Such rows stay in the report's table, beside the claims they
  explain, and are never counted as agreeing.

A deterministic measurement (e.g. ``roulette``'s hand-traced Q-tables, the same for every seed)
has a CI of 0 and ``n`` = 1: its interval is a point, so it is never ``inconclusive``.
"""


@dataclass
class Config:
    """How to run an experiment.

    Attributes:
        seeds: the number of seeds, independent runs per condition (``None``: the experiment's
            default, see :func:`~delayed_rl.experiments.framework.pool.run_experiment`).
        steps: training steps per run (``None``: the experiment's thesis-scale default).
        quick: a scaled-down version that runs in seconds (fewer steps, seeds and conditions).
        workers: parallel worker processes (1 runs in this process).
        backend: ``"loky"`` (joblib's process pool), ``"ray"`` or ``"dask"``.
        base_seed: the first seed; run ``i`` uses ``base_seed + i``.

    Raises:
        TypeError: a field has the wrong type (e.g. ``seeds="3"``).
        ValueError: a field is out of range (e.g. ``workers=0``; ``seeds`` above
            :data:`MAX_SEED_COUNT`, ``steps`` above ``MAX_TIMESTEPS`` = 2**40, ``workers`` above
            :data:`MAX_WORKERS`, ``base_seed`` above ``MAX_SEED_VALUE`` = 2**63 − 1) or ``backend``
            is unknown.
    """

    seeds: int | None = None
    steps: int | None = None
    quick: bool = False
    workers: int = 1
    backend: str = "loky"
    base_seed: int = 0

    def __post_init__(self) -> None:
        self.seeds = check_limit(
            "seeds", check_int("seeds", self.seeds, 1, optional=True), MAX_SEED_COUNT
        )
        self.steps = check_limit(
            "steps", check_int("steps", self.steps, 1, optional=True), MAX_TIMESTEPS
        )
        self.quick = check_bool("quick", self.quick)
        self.workers = check_workers("workers", self.workers)
        self.backend = check_choice("backend", self.backend, BACKENDS)
        self.base_seed = check_limit(
            "base_seed", check_int("base_seed", self.base_seed, 0), MAX_SEED_VALUE
        )

    def run_steps(self, full: int, quick: int) -> int:
        """The steps of a run: :attr:`steps` when set, else ``quick`` if :attr:`quick`, else ``full``."""
        return self.steps or (quick if self.quick else full)


@dataclass
class Claim:
    """One thesis number beside the measurement: a row of ``report.md``.

    Attributes:
        quantity: what is measured.
        thesis: the thesis's value or statement, with its figure or table.
        mean: the measurement (a share ``k / n`` for counts).
        ci95: the half-width of its 95 % interval.
        n: the number of runs (seeds) behind it.
        verdict: one of :data:`VERDICTS`.
        criterion: the rule of the verdict in words: what would make the row disagree.
        note: anything else the report should say about the row.
        low: the lower end of the 95 % interval the verdict read (``None``: ``mean − ci95``;
            an asymmetric interval, such as a share's Wilson interval, sets it).
        high: the upper end (``None``: ``mean + ci95``).

    Raises:
        ValueError: ``verdict`` is not one of :data:`VERDICTS`.
    """

    quantity: str
    thesis: str
    mean: float
    ci95: float
    n: int
    verdict: str
    criterion: str = ""
    note: str = ""
    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        check_choice("verdict", self.verdict, VERDICTS)
        self.mean, self.ci95 = float(self.mean), float(self.ci95)
        self.low = self.mean - self.ci95 if self.low is None else float(self.low)
        self.high = self.mean + self.ci95 if self.high is None else float(self.high)

    def interval_text(self) -> str:
        """The measurement as the report prints it: ``mean ± ci``, or ``mean [low, high]``."""
        symmetric = math.isclose(self.low, self.mean - self.ci95, abs_tol=1e-9) and math.isclose(
            self.high, self.mean + self.ci95, abs_tol=1e-9
        )
        if symmetric or math.isnan(self.mean):
            return f"{self.mean:.3f} ± {self.ci95:.3f}"
        return f"{self.mean:.3f} [{self.low:.3f}, {self.high:.3f}]"


@dataclass
class Curve:
    """A curve of one run: ``values`` at ``steps`` for one condition and seed."""

    condition: str
    seed: int
    steps: np.ndarray
    values: np.ndarray
    metric: str = "average_reward"


@dataclass
class Summary:
    """What an experiment's ``summarize`` returns."""

    claims: list[Claim]
    curves: list[Curve]
    figures: dict[str, Callable[[Path], None]] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)


class SharedRun(NamedTuple):
    """The computation behind a task, where tasks (of one experiment or several) share one.

    :func:`~delayed_rl.experiments.framework.pool.run_experiments` runs each distinct ``(run, task)``
    once and hands every task behind it ``view(result)``.

    **Pooled runs.** With ``pooled`` the name of a list in ``task`` (its *items*: say, the
    steps at which a training run is read), runs of the same function whose tasks differ only
    in that list are one run, on the union of their items (each once, sorted by their canonical
    JSON). ``run`` then returns a dict whose entry ``pooled`` holds one result per item of the
    task it was given, in that task's order; each task sees the result it would have had alone:
    that list cut down to its own items, in its own order (then its ``view``). So one
    experiment's run can extend another's, e.g. a 500k-step training run that a second
    experiment reads at 150k steps, instead of both training from scratch. For that to hold,
    an item's result must not depend on which other items the run has, nor on their order, and
    the result's other entries must not depend on the items at all.

    Attributes:
        run: a picklable top-level function of one task, returning the run's result.
        task: what ``run`` is called with: a task of the experiment's :class:`~.task.Task`
            type, or a JSON-like dict for a run whose task has another shape (the line
            follower's training run, say); its canonical JSON is the run's identity.
        view: picks the task's result out of the run's (``None``: the whole result); with
            ``pooled``, out of the task's own part of it.
        pooled: the name of the list in ``task`` whose items runs pool (``None``: none).
    """

    run: Callable[[Any], dict]
    task: Task | dict[str, Any]
    view: Callable[[dict], dict] | None = None
    pooled: str | None = None

    def alone(self) -> dict:
        """The task's result from a run of its own, in this process: ``view(run(task))``."""
        result = self.run(self.task)
        return result if self.view is None else self.view(result)


EXTRA_PACKAGES = {
    "sb3": ("torch", "stable-baselines3"),
    "multiagent": ("pettingzoo", "supersuit"),
}
"""The packages of each extra an experiment may need (:attr:`Experiment.extras`)."""


@dataclass(kw_only=True)
class Experiment:
    """An experiment, the thesis's or beyond it.

    Attributes:
        name: the name ``delayed-rl bench NAME`` takes.
        thesis: the thesis's figure or table it reproduces.
        description: the report's first paragraph.
        tasks: one task per (condition, seed), from the :class:`Config`: frozen dataclasses of
            the experiment's :class:`~.task.Task` type.
        run_task: a picklable top-level function of one task, returning its result (``None``:
            every task's run is its :attr:`shared_run`, which must then give one).
        summarize: the claims, curves and figures, from the tasks and their results.
        default_seeds: the seeds of a full run.
        quick_seeds: the seeds of a ``quick`` run.
        shared_run: the :class:`SharedRun` behind a task whose run another task (of this
            experiment or another) also needs, else ``None`` (``shared_run`` itself ``None``:
            every task is its own run, ``run_task(task)``).
        resumable: keep each run's result as it finishes, in ``OUT/runs/`` of the experiment's
            output folder, and read it back instead of running it again when the experiment is
            run into the same folder (its results must be JSON: dicts, lists, numbers, text).
            A run is found by its function and task, so a changed setting runs afresh; delete
            ``OUT/runs/`` to run everything again.
        extras: the install extras it needs beyond the core (keys of :data:`EXTRA_PACKAGES`),
            checked by :meth:`check_extras` before its tasks are made.
    """

    name: str
    thesis: str
    description: str
    tasks: Callable[[Config], Sequence[Task]]
    summarize: Callable[[Sequence[Any], list[dict], Config], Summary]
    default_seeds: int
    run_task: Callable[[Any], dict] | None = None
    quick_seeds: int = 2
    shared_run: Callable[[Any], SharedRun | None] | None = None
    resumable: bool = False
    extras: tuple[str, ...] = ()

    def check_extras(self) -> None:
        """Raise an ImportError naming the extras when a package of :attr:`extras` is missing."""
        packages = [package for extra in self.extras for package in EXTRA_PACKAGES[extra]]
        for package in packages:
            try:
                importlib.import_module(package.replace("-", "_"))
            except ImportError as error:
                listed = packages[-1]
                if len(packages) > 1:
                    listed = f"{', '.join(packages[:-1])} and {listed}"
                raise ImportError(
                    f"the {self.name} experiment needs {listed}: "
                    f'pip install "delayed-rl[{",".join(self.extras)}]"'
                ) from error

    def __post_init__(self) -> None:
        if self.run_task is None and self.shared_run is None:
            raise TypeError(f"the {self.name} experiment needs a run_task or a shared_run")
        for extra in self.extras:
            check_choice("extras[]", extra, tuple(EXTRA_PACKAGES))

    def run_of(self, task: Task) -> SharedRun:
        """The run behind ``task``: its :attr:`shared_run`, else ``run_task`` on the task itself."""
        shared = None if self.shared_run is None else self.shared_run(task)
        if shared is not None:
            return shared
        if self.run_task is None:
            raise ValueError(f"the {self.name} experiment's shared_run gave no run for {task!r}")
        return SharedRun(self.run_task, task)

    def run_alone(self, task: Task) -> dict:
        """``task``'s result from a run of its own, in this process (:meth:`run_of`)."""
        return self.run_of(task).alone()

    def task_cost(self, task: Task | dict) -> float:
        """``task``'s estimated core-seconds: its :meth:`~.task.Task.cost` (a dict task: 1 µs)."""
        return float(task.cost()) if isinstance(task, Task) else 1e-6


TaskType = TypeVar("TaskType", bound=Task)


def seed_tasks(
    config: Config, agents: Sequence[str], kind: type[TaskType], **fields: object
) -> list[TaskType]:
    """One task per (seed, agent): ``kind(agent=agent, seed=seed, **fields)``, seed-major.

    Seeds run from ``config.base_seed``, ``config.seeds`` of them.
    """
    return [
        kind(agent=agent, seed=config.base_seed + i, **fields)
        for i in range(config.seeds)
        for agent in agents
    ]


def running_average(rewards: np.ndarray, points: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """The average reward from step 1 to step t (the thesis's learning curves), at ``points`` t.

    Args:
        rewards: the reward of every step, in order.
        points: how many steps t to sample, spread evenly from 1 to ``rewards.size`` (fewer
            when the run is shorter than that).

    Returns:
        The steps t (``int64``, increasing) and the average reward up to each.
    """
    check_int("points", points, 1)
    steps = np.unique(np.linspace(1, rewards.size, points).astype(np.int64))
    cumulative = np.cumsum(rewards)
    return steps, cumulative[steps - 1] / steps


def step_count(steps: int) -> str:
    """``steps`` as the experiments' descriptions write it: ``1M``, ``150k``, else ``1,500``."""
    if steps % 1_000_000 == 0:
        return f"{steps // 1_000_000}M"
    if steps % 1_000 == 0:
        return f"{steps // 1_000}k"
    return f"{steps:,}"

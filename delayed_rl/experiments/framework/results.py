"""The experiments' results by condition and seed: one pivot for every ``summarize``.

An experiment's ``summarize`` gets its tasks and their results as two parallel lists.
:func:`pivot` turns them into ``{condition: {seed: value}}``, the condition being any of the
tasks' fields (``by=("agent",)``, ``by=("setting", "method")``...), the value the whole result,
one of its entries or any function of it; :func:`common_seeds` gives the seeds that several such
groups share, the ones a paired comparison reads; :func:`curve_groups` reads such groups' runs
as the ``(x, y)`` pairs a learning-curve figure draws. All keep the order of the tasks, so the
statistics (and the tables, curves and figures drawn from them) come out in the order the tasks
were made.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from delayed_rl.experiments.framework.task import Task

__all__ = ["common_seeds", "curve_groups", "pivot"]


def pivot(
    tasks: Sequence[Task],
    results: Sequence[Any],
    by: Sequence[str] = ("method",),
    value: str | Callable[[Any], Any] | None = None,
    where: Callable[[Any], bool] | None = None,
    nested: bool = False,
) -> dict[Any, Any]:
    """The results by the tasks' fields ``by``, then by seed: ``{key: {seed: value}}``.

    Keys and seeds are in the order the tasks first name them.

    Args:
        tasks: the experiment's tasks (:class:`~.task.Task`), each with the fields of ``by``.
        results: one result per task, in the same order.
        by: the fields that tell the groups apart. With one field a group's key is that field's
            value (``{"MMQ": {0: ..., 1: ...}}``), with several the tuple of their values.
        value: what to keep of a result: all of it (``None``), its entry of that name (a
            string), or what a function makes of it.
        where: keep only the tasks (and their results) for which it is true (``None``: all).
        nested: with several fields, one level of dicts per field instead of tuple keys:
            ``{setting: {method: {seed: value}}}``.

    Returns:
        ``{key: {seed: value}}`` (``nested``: ``{key1: {key2: ... {seed: value}}}``).

    Raises:
        ValueError: ``tasks`` and ``results`` differ in length, ``by`` names no field, or two
            of the kept tasks have the same key and seed.

    >>> import dataclasses
    >>> @dataclasses.dataclass(frozen=True)
    ... class AgentTask(Task):
    ...     agent: str
    >>> tasks = [AgentTask(agent="Q", seed=0), AgentTask(agent="MMQ", seed=0), AgentTask(agent="Q", seed=1)]
    >>> pivot(tasks, [{"r": 1}, {"r": 2}, {"r": 3}], by=("agent",), value="r")
    {'Q': {0: 1, 1: 3}, 'MMQ': {0: 2}}
    """
    if isinstance(by, str) or not by:
        raise ValueError(f"by must name one field or more (a tuple of names), got {by!r}")
    if len(tasks) != len(results):
        raise ValueError(f"{len(tasks)} tasks but {len(results)} results")
    pick: Callable[[Any], Any]
    if value is None:
        pick = _whole
    elif isinstance(value, str):
        name = value

        def pick(result: Any) -> Any:
            return result[name]
    else:
        pick = value
    out: dict[Any, Any] = {}
    for task, result in zip(tasks, results, strict=True):
        if where is not None and not where(task):
            continue
        keys = [getattr(task, field) for field in by]
        if nested:
            group = out
            for key in keys:
                group = group.setdefault(key, {})
        else:
            group = out.setdefault(keys[0] if len(keys) == 1 else tuple(keys), {})
        seed = task.seed
        if seed in group:
            raise ValueError(f"two tasks with {dict(zip(by, keys, strict=True))} and seed {seed}")
        group[seed] = pick(result)
    return out


def _whole(result: Any) -> Any:
    return result


def common_seeds(*groups: Mapping[int, Any]) -> list[int]:
    """The seeds present in every one of ``groups`` (``{seed: value}`` each), in the first's order.

    >>> common_seeds({0: "a", 1: "b", 2: "c"}, {2: "x", 1: "y"})
    [1, 2]
    """
    if not groups:
        return []
    first, *rest = groups
    return [seed for seed in first if all(seed in group for group in rest)]


def curve_groups(
    groups: Mapping[Any, Mapping[int, Mapping[str, Any]]], x: str = "steps", y: str = "curve"
) -> dict[Any, list[tuple[np.ndarray, np.ndarray]]]:
    """``{key: [(run[x], run[y]), ...]}``, as arrays: each group's runs, by seed, as curves.

    ``groups`` is ``{key: {seed: result}}`` (a :func:`pivot`'s); the pairs are what the
    learning-curve figures draw, one per seed, in the seeds' order.

    >>> curve_groups({"Q": {0: {"steps": [1, 2], "curve": [0.5, 0.7]}}})
    {'Q': [(array([1, 2]), array([0.5, 0.7]))]}

    Raises:
        ValueError: a run has no ``x`` or no ``y`` entry (the message names the run).
    """
    for key, runs in groups.items():
        for seed, run in runs.items():
            if x not in run or y not in run:
                raise ValueError(
                    f"curve_groups needs the entries x={x!r} and y={y!r} of every run, "
                    f"got {sorted(run)} in group {key!r}, seed {seed}"
                )
    return {
        key: [(np.asarray(run[x]), np.asarray(run[y])) for run in runs.values()]
        for key, runs in groups.items()
    }

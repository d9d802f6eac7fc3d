"""The experiments' results helper: pivots by task fields and seed, and the seeds groups share."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from delayed_rl.experiments.framework.results import common_seeds, curve_groups, pivot
from delayed_rl.experiments.framework.task import Task


@dataclasses.dataclass(frozen=True, kw_only=True)
class MethodTask(Task):
    """A (setting, method, seed)."""

    setting: str
    method: str


TASKS = [
    MethodTask(setting="a", method="x", seed=1),
    MethodTask(setting="a", method="y", seed=1),
    MethodTask(setting="b", method="x", seed=1),
    MethodTask(setting="a", method="x", seed=0),
]
RESULTS = [{"score": 1.0}, {"score": 2.0}, {"score": 3.0}, {"score": 4.0}]


def test_pivot_keeps_the_order_of_the_tasks():
    by_method = pivot(TASKS, RESULTS, by=("method",), value="score", where=_in_a)
    assert by_method == {"x": {1: 1.0, 0: 4.0}, "y": {1: 2.0}}
    assert list(by_method["x"]) == [1, 0]


def _in_a(task: MethodTask) -> bool:
    return task.setting == "a"


def test_pivot_by_several_fields_keys_by_tuples_or_nests():
    flat = pivot(TASKS, RESULTS, by=("setting", "method"))
    assert list(flat) == [("a", "x"), ("a", "y"), ("b", "x")]
    assert flat[("a", "x")] == {1: RESULTS[0], 0: RESULTS[3]}
    nested = pivot(
        TASKS, RESULTS, by=("setting", "method"), value=lambda r: -r["score"], nested=True
    )
    assert nested == {"a": {"x": {1: -1.0, 0: -4.0}, "y": {1: -2.0}}, "b": {"x": {1: -3.0}}}


def test_pivot_refuses_what_it_cannot_pivot():
    with pytest.raises(ValueError, match="seed 1"):
        pivot(TASKS, RESULTS, by=("setting",))
    with pytest.raises(ValueError, match="tasks but"):
        pivot(TASKS, RESULTS[:2])
    with pytest.raises(ValueError, match="by must"):
        pivot(TASKS, RESULTS, by="method")


def test_common_seeds_are_in_the_first_groups_order():
    assert common_seeds({3: 0, 1: 0, 2: 0}, {1: 0, 2: 0}, {2: 0, 1: 0, 5: 0}) == [1, 2]
    assert common_seeds({4: 0}) == [4] and common_seeds() == []


def test_curve_groups_reads_each_runs_pair_as_arrays_in_seed_order():
    groups = {"a": {2: {"steps": [1, 2], "score": [3.0, 4.0]}, 0: {"steps": [1], "score": [5.0]}}}
    first, second = curve_groups(groups, y="score")["a"]
    assert first[1].tolist() == [3.0, 4.0] and second[0].tolist() == [1]
    assert isinstance(first[0], np.ndarray)


def test_curve_groups_names_a_run_without_the_entries_it_reads():
    with pytest.raises(ValueError, match=r"y='curve'.*group 'a', seed 2"):
        curve_groups({"a": {2: {"steps": [1]}}})

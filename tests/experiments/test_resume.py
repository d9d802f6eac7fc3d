"""Resumable experiments: each run kept as it finishes, read back instead of run again."""

from __future__ import annotations

import dataclasses
import json

import pytest

from delayed_rl.experiments import LONG_NAMES, NAMES, Config, run_experiment, run_experiments
from delayed_rl.experiments.framework.experiment import Claim, Experiment, Summary, seed_tasks
from delayed_rl.experiments.framework.task import Task


@dataclasses.dataclass(frozen=True, kw_only=True)
class ToyTask(Task):
    """A toy experiment's task."""

    agent: str


CALLS: list[ToyTask] = []


def square_run(task: ToyTask) -> dict:
    """A run that records that it ran."""
    CALLS.append(task)
    return {"value": task.seed**2 + 0.5, "curve": [1.0, 2.5]}


def _tasks(config: Config) -> list[ToyTask]:
    return seed_tasks(config, ["a", "b"], ToyTask)


def _summarize(tasks: list[ToyTask], results: list[dict], config: Config) -> Summary:
    total = sum(result["value"] for result in results)
    return Summary([Claim("total", "none", total, 0.0, len(results), "reference")], [])


def _experiment(resumable: bool) -> Experiment:
    return Experiment(
        name="toy",
        thesis="none",
        description="a toy",
        tasks=_tasks,
        run_task=square_run,
        summarize=_summarize,
        default_seeds=3,
        resumable=resumable,
    )


def test_a_resumed_experiment_reads_its_kept_runs_instead_of_running_them(tmp_path):
    CALLS.clear()
    first = run_experiment(_experiment(True), Config(seeds=3), tmp_path, False)
    assert len(CALLS) == 6 and len(list((tmp_path / "runs").glob("*.json"))) == 6
    CALLS.clear()
    again = run_experiment(_experiment(True), Config(seeds=3), tmp_path, False)
    assert CALLS == []
    assert again.claims[0].mean == first.claims[0].mean == 2 * (0 + 1 + 4 + 1.5)
    CALLS.clear()  # more seeds: only the new runs run
    run_experiment(_experiment(True), Config(seeds=4), tmp_path, False)
    assert [task.seed for task in CALLS] == [3, 3]


def test_an_experiment_that_is_not_resumable_keeps_nothing(tmp_path):
    CALLS.clear()
    run_experiment(_experiment(False), Config(seeds=2), tmp_path, False)
    run_experiment(_experiment(False), Config(seeds=2), tmp_path, False)
    assert len(CALLS) == 8 and not (tmp_path / "runs").exists()


def test_a_kept_run_is_found_by_its_task_so_a_changed_task_runs_again(tmp_path):
    CALLS.clear()
    run_experiment(_experiment(True), Config(seeds=1), tmp_path, False)
    CALLS.clear()
    run_experiment(_experiment(True), Config(seeds=1, base_seed=1), tmp_path, False)
    assert [task.seed for task in CALLS] == [1, 1]


@pytest.mark.parametrize(
    "damage",
    [
        lambda text: text[: len(text) // 2],  # cut short
        lambda text: "\xff not json",
        lambda text: json.dumps({**json.loads(text), "run": "another run"}),
        lambda text: json.dumps({**json.loads(text), "seconds": "soon"}),
        lambda text: json.dumps({**json.loads(text), "result": [1, 2]}),
        lambda text: "[]",
    ],
)
def test_a_damaged_kept_run_stops_the_experiment_naming_its_file(tmp_path, damage):
    run_experiment(_experiment(True), Config(seeds=1), tmp_path, False)
    path = sorted((tmp_path / "runs").glob("*.json"))[0]
    path.write_text(damage(path.read_text()))
    with pytest.raises(ValueError, match=f"{path.name}.*delete it"):
        run_experiment(_experiment(True), Config(seeds=1), tmp_path, False)


def test_kept_runs_go_in_each_experiment_folder_when_run_together(tmp_path):
    CALLS.clear()
    run_experiments([_experiment(True)], Config(seeds=1), tmp_path, False)
    assert len(list((tmp_path / "toy" / "runs").glob("*.json"))) == 2


def test_the_long_experiments_are_named_experiments():
    assert set(LONG_NAMES) < set(NAMES) and "deep-rl" in LONG_NAMES

"""Running experiments together: each distinct run once, longest first, each summary as it ends."""

from __future__ import annotations

import dataclasses
import functools
import re
import sys

import numpy as np
import pytest

from delayed_rl.experiments import Config, get_experiment, run_experiment, run_experiments
from delayed_rl.experiments.beyond import future_work as fw
from delayed_rl.experiments.framework import delay_settings as settings
from delayed_rl.experiments.framework import snapshot_runs as snapshots
from delayed_rl.experiments.framework.experiment import Experiment, SharedRun, Summary
from delayed_rl.experiments.framework.pool import pool_key, run_key
from delayed_rl.experiments.framework.task import Task

CALLS: list[dict] = []


def square(task: dict) -> dict:
    """A run that records that it ran."""
    CALLS.append(task)
    return {"value": task["x"] ** 2, "x": task["x"]}


def negated(result: dict) -> dict:
    return {**result, "value": -result["value"]}


def _summarize(tasks, results, config):
    return Summary([], [], extra={"values": [r["value"] for r in results], "tasks": tasks})


def _experiment(name: str, xs: list[int], shared_run=None) -> Experiment:
    return Experiment(
        name=name,
        thesis="-",
        description="-",
        tasks=lambda config: [{"name": name, "x": x} for x in xs],
        run_task=square,
        summarize=_summarize,
        default_seeds=1,
        shared_run=shared_run,
    )


@dataclasses.dataclass(frozen=True, kw_only=True)
class CostlyTask(Task):
    """A task whose run costs ten core-seconds per ``x``."""

    x: int

    def cost(self) -> float:
        return 10.0 * self.x


def square_of_x(task: CostlyTask) -> dict:
    """:func:`square` of a :class:`CostlyTask`."""
    return square({"x": task.x})


def _by_x(task: dict) -> SharedRun:
    """Every task with the same ``x`` is one run, whatever experiment it belongs to."""
    return SharedRun(square, {"x": task["x"]})


def _by_x_negated(task: dict) -> SharedRun:
    return SharedRun(square, {"x": task["x"]}, negated)


def test_a_run_shared_by_tasks_and_experiments_runs_once_and_each_task_gets_its_view():
    CALLS.clear()
    first = _experiment("first", [1, 2, 3, 2], _by_x)
    second = _experiment("second", [3, 4], _by_x_negated)
    one, two = run_experiments([first, second], Config(workers=1), progress=False)
    assert sorted(task["x"] for task in CALLS) == [1, 2, 3, 4]
    assert one.extra["values"] == [1, 4, 9, 4] and two.extra["values"] == [-9, -16]
    assert (one.extra["runs"], one.extra["shared_runs"]) == (3, 1)
    assert (two.extra["runs"], two.extra["shared_runs"]) == (2, 1)
    assert one.extra["tasks"][3] == {"name": "first", "x": 2}  # each experiment keeps its tasks


def test_runs_start_longest_first_and_experiments_are_summarized_as_they_finish():
    CALLS.clear()
    done = []
    slow = dataclasses.replace(
        _experiment("slow", []),
        tasks=lambda config: [CostlyTask(x=x, seed=0) for x in (5, 6)],
        run_task=square_of_x,
    )
    fast = _experiment("fast", [1, 2, 3])
    summaries = run_experiments(
        [fast, slow], Config(workers=1), progress=False, on_done=lambda e, s: done.append(e.name)
    )
    assert [task["x"] for task in CALLS] == [6, 5, 1, 2, 3]  # by cost; ties in task order
    assert done == ["slow", "fast"]
    assert [s.extra["values"] for s in summaries] == [[1, 4, 9], [25, 36]]  # the given order
    assert all(s.extra["run_seconds"] >= 0 for s in summaries)


def test_without_shared_runs_every_distinct_task_is_its_own_run():
    CALLS.clear()
    summary = run_experiment(_experiment("plain", [2, 3, 2]), Config(workers=1), progress=False)
    assert len(CALLS) == 2 and summary.extra["values"] == [4, 9, 4]  # identical tasks: one run
    assert (summary.extra["runs"], summary.extra["shared_runs"]) == (2, 0)


def test_run_key_is_the_function_and_the_task_in_canonical_form():
    assert run_key(SharedRun(square, {"a": 1, "b": [1, 2]})) == run_key(
        SharedRun(square, {"b": [1, 2], "a": 1}, negated)
    )
    assert run_key(SharedRun(square, {"a": 1})) != run_key(SharedRun(negated, {"a": 1}))
    assert run_key(SharedRun(square, {"a": 1})) != run_key(SharedRun(square, {"a": 2}))


def powers(task: dict) -> dict:
    """A pooled run: ``x`` to each power in ``task["powers"]``, one result per item."""
    CALLS.append(task)
    return {"powers": [task["x"] ** power for power in task["powers"]], "x": task["x"]}


def _pooling(task: dict) -> SharedRun:
    return SharedRun(powers, {"x": task["x"], "powers": task["powers"]}, None, "powers")


def _powers_experiment(name: str, tasks: list[dict]) -> Experiment:
    return Experiment(
        name=name,
        thesis="-",
        description="-",
        tasks=lambda config: tasks,
        run_task=powers,
        summarize=lambda tasks, results, config: Summary([], [], extra={"results": results}),
        default_seeds=1,
        shared_run=_pooling,
    )


def test_pooled_runs_run_once_on_the_union_and_each_task_gets_its_own_part():
    CALLS.clear()
    first = _powers_experiment("first", [{"x": 2, "powers": [3, 1]}, {"x": 3, "powers": [2]}])
    second = _powers_experiment("second", [{"x": 2, "powers": [2, 3]}])
    one, two = run_experiments([first, second], Config(workers=1), progress=False)
    assert sorted((task["x"], task["powers"]) for task in CALLS) == [(2, [1, 2, 3]), (3, [2])]
    assert one.extra["results"] == [{"powers": [8, 2], "x": 2}, {"powers": [9], "x": 3}]
    assert two.extra["results"] == [{"powers": [4, 8], "x": 2}]  # in each task's own order
    assert (one.extra["runs"], one.extra["shared_runs"]) == (2, 1)
    CALLS.clear()
    alone = run_experiment(second, Config(workers=1), progress=False)
    assert CALLS == [{"x": 2, "powers": [2, 3]}] and alone.extra["results"] == two.extra["results"]


def test_pool_key_ignores_only_the_pooled_items():
    def key(task: dict, pooled: str | None = "powers") -> str:
        return pool_key(SharedRun(powers, task, None, pooled))

    assert key({"x": 1, "powers": [1]}) == key({"x": 1, "powers": [2, 3]})
    assert key({"x": 1, "powers": [1]}) != key({"x": 2, "powers": [1]})
    assert key({"x": 1, "powers": [1]}, None) == run_key(SharedRun(powers, {"x": 1, "powers": [1]}))
    with pytest.raises(ValueError, match="has no entry 'powers' to pool"):
        key({"x": 1})
    with pytest.raises(TypeError, match="pooled entry 'powers' must be a list or a tuple, got 3"):
        key({"x": 1, "powers": 3})
    with pytest.raises(TypeError, match="pooled must be None or a task entry's name, got 1"):
        key({"x": 1, "powers": [1]}, 1)
    with pytest.raises(ValueError, match="not JSON-like"):  # the items too
        key({"x": 1, "powers": [object()]})


def test_a_task_may_name_an_item_twice():
    CALLS.clear()
    experiment = _powers_experiment("twice", [{"x": 2, "powers": [3, 1, 3]}])
    (result,) = run_experiment(experiment, Config(workers=1), progress=False).extra["results"]
    assert CALLS == [{"x": 2, "powers": [1, 3]}] and result == {"powers": [8, 2, 8], "x": 2}


def not_a_dict(task: dict) -> list:
    """A pooled run that returns its items' results bare."""
    return [task["x"]] * len(task["powers"])


def broken_powers(task: dict) -> dict:
    """A pooled run that returns one result too few."""
    return {"powers": [task["x"]] * (len(task["powers"]) - 1)}


@pytest.mark.parametrize(
    ("run", "message"),
    [
        (not_a_dict, r"test_pool\.not_a_dict.* returned a list, not a dict"),
        (broken_powers, r"one result per item \(2\); .*broken_powers.* returned list of 1"),
    ],
)
def test_a_pooled_run_must_return_a_dict_with_one_result_per_item(run, message):
    experiment = _powers_experiment("broken", [{"x": 2, "powers": [1, 2]}])
    experiment.shared_run = lambda task: SharedRun(run, task, None, "powers")
    with pytest.raises(ValueError, match=message):
        run_experiment(experiment, Config(workers=1), progress=False)


class _Runner:
    def run(self, task: dict) -> dict:
        return task


@pytest.mark.parametrize(
    "function",
    [lambda task: task, functools.partial(square), _Runner().run, _Runner()],
    ids=["lambda", "partial", "bound method", "callable"],
)
def test_a_run_must_be_a_module_level_function(function):
    with pytest.raises(TypeError, match="module-level function"):
        run_key(SharedRun(function, {"x": 1}))


def test_a_task_must_be_json_like():
    with pytest.raises(ValueError, match="not JSON-like"):
        run_key(SharedRun(square, {"x": object()}))
    with pytest.raises(ValueError, match="not JSON-like"):
        run_key(SharedRun(square, {1: "a", "b": 2}))  # keys that cannot be sorted


def test_experiments_run_together_must_have_distinct_names():
    with pytest.raises(ValueError, match=r"distinct names, got \['twin'\]"):
        run_experiments([_experiment("twin", [1]), _experiment("twin", [2])], Config(workers=1))


def test_outputs_go_to_a_folder_per_experiment(tmp_path):
    run_experiments([_experiment("first", [1])], Config(workers=1), tmp_path, progress=False)
    assert (tmp_path / "first" / "report.md").exists()


def _quick_task(agent: str) -> dict:
    config = Config(quick=True, seeds=1, steps=6_000)
    return next(t for t in settings.setting_tasks(config, (agent,)))


def test_the_greedy_window_changes_nothing_of_how_mmq_learns():
    """MMQ's shared run (with the averaged table) trains as the thesis rule alone does."""
    task = _quick_task(fw.THESIS)
    delay = settings.make_delay(task.delay, task.lam)
    alone = snapshots.measure(
        fw.make_variant(fw.THESIS, task.size, delay, task.steps, 0), task.steps, task.size
    )
    shared = fw.run_task(task)
    np.testing.assert_array_equal(shared["curve"], alone["curve"])
    np.testing.assert_array_equal(shared["snapshot_optimal"], alone["snapshot_optimal"])
    np.testing.assert_array_equal(shared["estimate"], alone["estimate"])
    assert snapshots.AVERAGED not in shared


def test_the_greedy_window_variant_reads_the_averaged_table_of_the_same_run():
    task = dataclasses.replace(_quick_task(fw.GREEDY_ONLY[0]), agent=fw.GREEDY_ONLY[0])
    delay = settings.make_delay(task.delay, task.lam)
    agent = fw.make_variant(task.agent, task.size, delay, task.steps, task.seed)
    own = snapshots.train_with_snapshots(agent, task.steps, task.size)
    window = fw.run_task(task)
    np.testing.assert_array_equal(
        window["snapshot_greedy"], own[snapshots.AVERAGED]["snapshot_greedy"]
    )
    assert window["greedy"] == snapshots.walk_average(
        snapshots.greedy_policy(agent, averaged=True), 7
    )
    assert (
        window["curve"].tolist()
        == fw.run_task(dataclasses.replace(task, agent=fw.THESIS))["curve"].tolist()
    )
    with pytest.raises(ValueError, match="no averaged table"):
        snapshots.averaged_readout(snapshots.current_readout(window))


@pytest.mark.experiment
def test_future_work_run_with_anonymous_delay_shares_mmq_runs_and_claims_the_same(tmp_path):
    config = Config(quick=True, steps=4_000)
    alone = run_experiment(get_experiment("future-work"), Config(quick=True, steps=4_000))
    both = run_experiments(
        [get_experiment("anonymous-delay"), get_experiment("future-work")], config, progress=False
    )
    assert [c.mean for c in both[1].claims] == [c.mean for c in alone.claims]
    assert both[1].extra["shared_runs"] == both[1].extra["runs"] - 4 * 2  # 4 variants of their own
    assert alone.extra["runs"] == 5 * 2 and alone.extra["shared_runs"] == 0


def _figured_summary(tasks, results, config):
    """A summary with a figure drawn by a closure (as the experiments' are)."""
    values = [r["value"] for r in results]

    def draw(path):
        path.write_text(f"figure of {values}")

    return Summary([], [], figures={"plot": draw}, extra={"values": values})


@pytest.mark.cold_cache
def test_files_are_written_in_background_processes_and_reported_once_written(tmp_path):
    """With several experiments and workers, each one's files are on disk when on_done sees it."""
    done = []

    def seen(experiment, summary):
        folder = tmp_path / experiment.name
        done.append((experiment.name, (folder / "report.md").exists(), (folder / "plot.png")))

    experiments = [
        Experiment(
            name=name,
            thesis="-",
            description="-",
            tasks=lambda config, xs=xs: [{"x": x} for x in xs],
            run_task=square,
            summarize=_figured_summary,
            default_seeds=1,
        )
        for name, xs in (("a", [1, 2]), ("b", [3]), ("c", [4, 5, 6]))
    ]
    summaries = run_experiments(experiments, Config(workers=2), tmp_path, False, seen)
    assert sorted(name for name, _, _ in done) == ["a", "b", "c"]
    assert all(report for _, report, _ in done)
    assert [p.read_text() for _, _, p in sorted(done)] == [
        "figure of [1, 4]",
        "figure of [9]",
        "figure of [16, 25, 36]",
    ]
    assert [s.extra["values"] for s in summaries] == [[1, 4], [9], [16, 25, 36]]


@pytest.mark.cold_cache
def test_a_failed_background_write_is_raised(tmp_path):
    (tmp_path / "a").write_text("a file where the folder should go")
    experiments = [_experiment(name, [1]) for name in ("a", "b")]
    with pytest.raises(FileExistsError):
        run_experiments(experiments, Config(workers=2), tmp_path, progress=False)


@pytest.mark.cold_cache
def test_a_summary_that_cannot_be_sent_is_written_here(tmp_path):
    """A figure holding an object pickling refuses is drawn in this process, not lost."""
    import threading

    lock = threading.Lock()

    def locked_summary(tasks, results, config):
        def draw(path):
            with lock:
                path.write_text("drawn here")

        return Summary([], [], figures={"plot": draw})

    experiments = [
        Experiment(
            name=name,
            thesis="-",
            description="-",
            tasks=lambda config: [{"x": 1}],
            run_task=square,
            summarize=locked_summary,
            default_seeds=1,
        )
        for name in ("a", "b")
    ]
    run_experiments(experiments, Config(workers=2), tmp_path, progress=False)
    assert (tmp_path / "a" / "plot.png").read_text() == "drawn here"
    assert (tmp_path / "b" / "plot.png").read_text() == "drawn here"


def test_an_experiment_without_run_task_runs_each_task_through_its_shared_run():
    experiment = dataclasses.replace(_experiment("shared only", [2, 3], _by_x), run_task=None)
    summary = run_experiment(experiment, Config(seeds=1))
    assert summary.extra["values"] == [4, 9]
    assert experiment.run_alone({"name": "shared only", "x": 5})["value"] == 25
    with pytest.raises(TypeError, match="the none experiment needs a run_task or a shared_run"):
        dataclasses.replace(experiment, name="none", shared_run=None)
    gives_none = dataclasses.replace(experiment, name="gaps", shared_run=lambda task: None)
    with pytest.raises(ValueError, match="the gaps experiment's shared_run gave no run"):
        gives_none.run_of({"x": 1})


@pytest.mark.parametrize(
    ("extras", "missing", "needs"),
    [
        (("one",), "fake_b", 'json and fake-b: pip install "delayed-rl[one]"'),
        (("one", "two"), "fake_c", 'json, fake-b and fake-c: pip install "delayed-rl[one,two]"'),
        (("two",), "fake_c", 'fake-c: pip install "delayed-rl[two]"'),
    ],
)
def test_a_missing_extra_is_named_before_any_task_is_made(monkeypatch, extras, missing, needs):
    from delayed_rl.experiments.framework import experiment as framework

    # stand-in extras, so that no real package is imported: json is there, fake-b and fake-c
    # are made present below, and then the one that is missing
    extra_packages = {"one": ("json", "fake-b"), "two": ("fake-c",)}
    monkeypatch.setattr(framework, "EXTRA_PACKAGES", extra_packages)
    for name in ("fake_b", "fake_c"):
        monkeypatch.setitem(sys.modules, name, object())
    made = []
    experiment = dataclasses.replace(
        _experiment("needy", [1]), extras=extras, tasks=lambda config: made.append(config) or []
    )
    monkeypatch.setitem(sys.modules, missing, None)  # what a missing package looks like
    with pytest.raises(ImportError, match=re.escape(f"the needy experiment needs {needs}")):
        run_experiment(experiment, Config(seeds=1))
    assert made == []


def test_an_unknown_extra_is_refused_by_name():
    with pytest.raises(ValueError, match="extras.*must be one of .*'sb3'.*got 'sb4'"):
        dataclasses.replace(_experiment("typo", [1]), extras=("sb4",))

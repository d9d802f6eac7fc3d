"""Running experiments: each run once, on one pool of workers, the most costly first.

:func:`run_experiments` (what ``delayed-rl bench all`` calls) runs each *distinct* run behind
the experiments' tasks once (a :class:`~.experiment.SharedRun` several tasks need is run once,
its result handed to each), all on one pool, longest first; :func:`run_experiment` runs one
experiment. A resumable experiment keeps each run's result as it finishes and reads it back.
:func:`run_key` is a run's identity.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent import futures
from pathlib import Path
from typing import Any

from delayed_rl._validation import check_bool
from delayed_rl.experiments.framework.experiment import Config, Experiment, SharedRun, Summary
from delayed_rl.experiments.framework.report import json_default, write_outputs
from delayed_rl.experiments.framework.task import Task
from delayed_rl.parallel.pools import iter_tasks, process_pool
from delayed_rl.parallel.progress import RunProgress


def run_key(run: SharedRun) -> str:
    """A run's identity: its function's qualified name and its task in canonical JSON.

    Tasks are compared as JSON: a :class:`~.task.Task` is its :meth:`~.task.Task.to_json`, a
    tuple the list of its items, an integer key the string of it.

    Raises:
        TypeError: ``run.run`` is not a module-level function (a lambda, a closure, a bound
            method or a ``functools.partial`` has no name that tells one computation from
            another, nor one a worker process can import).
        ValueError: ``run.task`` cannot be written as JSON.
    """
    function = run.run
    module = sys.modules.get(getattr(function, "__module__", None) or "")
    name = getattr(function, "__qualname__", "")
    if module is None or "<" in name or getattr(module, name, None) is not function:
        raise TypeError(
            f"a run must be a module-level function (run_task, or a SharedRun's run), got "
            f"{function!r}"
        )
    try:
        task = _canonical(run.task)
    except (TypeError, ValueError) as error:
        raise ValueError(f"the task {run.task!r} of {name} is not JSON-like: {error}") from None
    return f"{function.__module__}.{name}:{task}"


def pool_key(run: SharedRun) -> str:
    """The identity of the run that ``run`` pools into: :func:`run_key` less its pooled items.

    Without ``run.pooled`` it is :func:`run_key`.

    Raises:
        TypeError: as :func:`run_key`; or ``run.pooled`` is not a string, or the task's entry
            of that name is not a list or a tuple.
        ValueError: as :func:`run_key`; or the task has no entry named ``run.pooled``.
    """
    whole = run_key(run)  # the items too must be JSON-like
    if run.pooled is None:
        return whole
    _items(run)
    rest = {name: value for name, value in _entries(run.task).items() if name != run.pooled}
    return f"{run_key(run._replace(task=rest))} pooling {run.pooled}"


def _entries(task: Task | Mapping[str, Any]) -> Mapping[str, Any]:
    """A task's entries by name: a :class:`~.task.Task`'s JSON fields, or the dict itself."""
    return task.to_json() if isinstance(task, Task) else task


def _items(run: SharedRun) -> Sequence[Any]:
    """The task's entry ``run.pooled``, checked (see :func:`pool_key`)."""
    if not isinstance(run.pooled, str):
        raise TypeError(f"pooled must be None or a task entry's name, got {run.pooled!r}")
    entries = _entries(run.task)
    if run.pooled not in entries:
        raise ValueError(f"the task {run.task!r} has no entry {run.pooled!r} to pool")
    items = entries[run.pooled]
    if not isinstance(items, list | tuple):
        raise TypeError(f"the pooled entry {run.pooled!r} must be a list or a tuple, got {items!r}")
    return items


def _canonical(value: Any) -> str:
    """``value`` in canonical JSON (keys sorted): what tells tasks and pooled items apart."""
    return json.dumps(value, sort_keys=True, default=json_default)


def _pooled(runs: Sequence[SharedRun]) -> SharedRun:
    """The one run that ``runs`` (of one :func:`pool_key`) pool into: the union of their items."""
    first = runs[0]
    if first.pooled is None:
        return first
    union = {_canonical(item): item for run in runs for item in _items(run)}
    items = [union[key] for key in sorted(union)]
    if isinstance(first.task, Task):
        task: Task | Mapping[str, Any] = dataclasses.replace(
            first.task, **{first.pooled: tuple(items)}
        )
    else:
        task = {**first.task, first.pooled: items}
    return first._replace(task=task, view=None)


def _own_result(run: SharedRun, pooled: SharedRun, result: dict) -> dict:
    """The result ``run`` would have had alone, out of the result of the run it pooled into.

    Raises:
        ValueError: the pooled run's result does not hold one entry per item.
    """
    if run.pooled is None:
        return result
    items = _items(pooled)
    parts = result.get(run.pooled) if isinstance(result, dict) else result
    if not isinstance(result, dict) or not isinstance(parts, list) or len(parts) != len(items):
        got = f"{type(parts).__name__}" + (f" of {len(parts)}" if isinstance(parts, list) else "")
        raise ValueError(
            f"a pooled run must return a dict whose {run.pooled!r} holds one result per item "
            f"({len(items)}); {run_key(pooled)} returned "
            + (got if isinstance(result, dict) else f"a {type(result).__name__}, not a dict")
        )
    where = {_canonical(item): index for index, item in enumerate(items)}
    own = [parts[where[_canonical(item)]] for item in _items(run)]
    return {**result, run.pooled: own}


def _timed(job: tuple[Callable[[Any], dict], Any]) -> tuple[dict, float]:
    """``(run(task), seconds it took)`` of a ``(run, task)`` job, timed where it runs."""
    run, task = job
    started = time.perf_counter()
    result = run(task)
    return result, time.perf_counter() - started


@dataclasses.dataclass(eq=False)
class _Plan:
    """One experiment's part of a schedule: its tasks, the run behind each, what is missing."""

    experiment: Experiment
    config: Config
    tasks: list[Task]
    runs: list[SharedRun]
    keys: list[str]
    out: Path | None
    missing: int = 0


def run_experiment(
    experiment: Experiment, config: Config, out: Path | str | None = None, progress: bool = True
) -> Summary:
    """Run ``experiment`` and, if ``out`` is given, write its files there.

    Args:
        experiment: what to run.
        config: how to run it; ``config.seeds`` is set to the experiment's default
            (``quick_seeds`` with ``config.quick``, else ``default_seeds``) when ``None``.
        out: the output folder (``None``: write nothing, return the summary only).
        progress: report the progress: print a line saying how many runs start on how many
            workers, then count the runs on stderr as they finish
            (:class:`~delayed_rl.parallel.progress.RunProgress`: tqdm's bar, else a line per
            run).

    Returns:
        The experiment's summary, with ``extra["wall_time_s"]`` the seconds it took (and the
        other costs :func:`run_experiments` lists).
    """
    check_bool("progress", progress)
    _default_seeds(experiment, config)
    plan = _plan(experiment, config, None if out is None else Path(out))
    return _run([plan], config, progress, None)[0]


def run_experiments(
    experiments: Sequence[Experiment],
    config: Config,
    out: Path | str | None = None,
    progress: bool = True,
    on_done: Callable[[Experiment, Summary], None] | None = None,
) -> list[Summary]:
    """Run ``experiments`` together; write each into ``out/NAME``.

    :func:`run_experiments` (what ``delayed-rl bench all`` calls) gathers the runs behind every task
    of the experiments it is given (:meth:`~.experiment.Experiment.run_of`) and runs each *distinct* run
    once: a :class:`~.experiment.SharedRun` that several tasks need, of one experiment or of several, is
    run once and its result handed to each of them (through its ``view``). Two runs are the same
    when they call the same function with the same task (compared in canonical JSON); runs that
    *pool* a list of their task (``SharedRun.pooled``, e.g. the steps at which a training run is
    read) are one run when their tasks differ only in that list, run on the union of its items.

    All runs go to one pool, ordered by their estimated cost (:meth:`~.task.Task.cost`),
    longest first, so the workers are never left idle behind one experiment's slowest run before the
    next experiment starts, and the last runs to start are short ones. Each experiment is
    summarized as soon as its last run is in, while the workers go on with the other experiments'
    runs; with several experiments and workers its files (figures take seconds) are written by a
    pool of as many background processes, so the experiments that finish last are drawn side by
    side. Results do not depend on the order or the number of workers: every task carries its own
    seed. With ``progress``, a bar on stderr counts the distinct runs as they finish, in whatever
    order the workers finish them.

    A *resumable* experiment (:attr:`~.experiment.Experiment.resumable`) keeps each run's result as it
    finishes, as ``OUT/runs/<hash>.json`` stating the run it holds (written whole or not at all), and
    a later call into the same folder reads those instead of running them: an experiment longer than
    a sitting runs in parts. A kept file that is not a run's result stops the call, naming it.

    Each summary's ``extra`` records what the experiment cost (a kept run counts its first time):

    - ``run_seconds``: the core-seconds of its runs, as timed in the workers (a run it shares with
      another experiment counts in full in each, a pooled run too: an experiment whose run another
      extends counts the longer run);
    - ``runs``: how many distinct runs it needed, ``shared_runs`` how many of them another of the
      experiments run together also needed;
    - ``wall_time_s``: seconds from the start until its summary was made (run alone: the
      experiment's wall time).

    Tasks that share a run receive the same result object (through their views): an experiment's
    ``summarize`` reads its results and must not change them.

    Args:
        experiments: what to run.
        config: how; each experiment runs with a copy whose ``seeds``, when ``None``, is its own
            default (:func:`run_experiment`).
        out: the parent of the output folders, one per experiment named after it (``None``:
            write nothing).
        progress: report the progress, as :func:`run_experiment` does; the bar counts the
            distinct runs of all the experiments together.
        on_done: called with each experiment and its summary, in the order they finish, after
            its files are written.

    Returns:
        The summaries, in the order of ``experiments``.

    Raises:
        ValueError: two experiments have the same name (their folders and runs would mix).
    """
    check_bool("progress", progress)
    names = [experiment.name for experiment in experiments]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise ValueError(f"experiments must have distinct names, got {repeated} more than once")
    plans = []
    for experiment in experiments:
        own = dataclasses.replace(config)
        _default_seeds(experiment, own)
        plans.append(_plan(experiment, own, None if out is None else Path(out) / experiment.name))
    return _run(plans, config, progress, on_done)


def _default_seeds(experiment: Experiment, config: Config) -> None:
    if config.seeds is None:
        config.seeds = experiment.quick_seeds if config.quick else experiment.default_seeds


def _plan(experiment: Experiment, config: Config, out: Path | None) -> _Plan:
    experiment.check_extras()
    tasks = experiment.tasks(config)
    runs = [experiment.run_of(task) for task in tasks]
    return _Plan(experiment, config, tasks, runs, [pool_key(run) for run in runs], out)


def _run(
    plans: list[_Plan],
    config: Config,
    progress: bool,
    on_done: Callable[[Experiment, Summary], None] | None,
) -> list[Summary]:
    """Run every plan's distinct runs in one pool, longest first, summarizing each plan when done."""
    started = time.perf_counter()
    pooling: dict[str, list[SharedRun]] = {}
    costs: dict[str, float] = {}
    users: dict[str, list[_Plan]] = {}
    for plan in plans:
        for task, run, key in zip(plan.tasks, plan.runs, plan.keys, strict=True):
            pooling.setdefault(key, []).append(run)
            costs[key] = max(costs.get(key, 0.0), plan.experiment.task_cost(task))
        for key in dict.fromkeys(plan.keys):
            users.setdefault(key, []).append(plan)
        plan.missing = len(set(plan.keys))
    runs = {key: _pooled(pooled) for key, pooled in pooling.items()}
    order = sorted(runs, key=lambda key: -costs[key])  # stable: equal costs keep task order
    results: dict[str, dict] = {}
    seconds: dict[str, float] = {}
    stores = {key: _stores(users[key]) for key in order}
    order = _resume(order, runs, users, stores, results, seconds)
    if progress:
        names = ", ".join(plan.experiment.name for plan in plans)
        tasks = sum(len(plan.tasks) for plan in plans)
        kept = f", {len(results)} kept from an earlier run" if results else ""
        print(
            f"[{names}] {len(order)} runs ({tasks} tasks{kept}) on {config.workers} worker(s)...",
            flush=True,
        )
    summaries: dict[int, Summary] = {}
    unfinished = {key: len(plans_of) for key, plans_of in users.items()}

    def finish(plan: _Plan) -> None:
        summaries[id(plan)] = summary = _summarize(plan, runs, results, seconds, users, started)
        writer.write(plan, summary)
        for key in set(plan.keys):  # drop the results no other plan still needs
            unfinished[key] -= 1
            if not unfinished[key]:
                results.pop(key)

    local_cores = min(config.workers, len(plans), os.cpu_count() or 1)  # (a cluster's are not)
    label = plans[0].experiment.name if len(plans) == 1 else f"{len(plans)} experiments"
    with RunProgress(len(order), label, progress and bool(order)) as counter:

        def done(experiment: Experiment, summary: Summary) -> None:
            with counter.paused():  # what on_done prints does not run into the bar
                on_done(experiment, summary)

        with _Writer(local_cores, None if on_done is None else done) as writer:
            for plan in plans:
                if not plan.missing:
                    finish(plan)
            jobs = [(runs[key].run, runs[key].task) for key in order]
            pending = iter_tasks(_timed, jobs, config.workers, config.backend)
            for index, (result, spent) in pending:  # in the order the runs finish
                counter.tick()
                key = order[index]
                results[key], seconds[key] = result, spent
                _keep_result(stores[key], runs[key], result, spent)
                for plan in users[key]:
                    plan.missing -= 1
                    if not plan.missing:
                        finish(plan)
                writer.report(wait=False)
    return [summaries[id(plan)] for plan in plans]


def _resume(
    order: list[str],
    runs: dict[str, SharedRun],
    users: dict[str, list[_Plan]],
    stores: dict[str, list[Path]],
    results: dict[str, dict],
    seconds: dict[str, float],
) -> list[str]:
    """Fill ``results`` and ``seconds`` with the kept runs; return the keys still to run."""
    for key in order:
        kept = _kept_result(stores[key], runs[key])
        if kept is not None:
            results[key], seconds[key] = kept
            for plan in users[key]:
                plan.missing -= 1
    return [key for key in order if key not in results]


def _stores(plans: list[_Plan]) -> list[Path]:
    """The folders that keep a run's result: ``OUT/runs`` of each resumable plan that writes."""
    return [
        plan.out / "runs" for plan in plans if plan.experiment.resumable and plan.out is not None
    ]


def _kept_path(folder: Path, run: SharedRun) -> tuple[Path, str]:
    """Where ``run``'s result is kept in ``folder``, and the identity the file must state."""
    identity = run_key(run)
    return folder / f"{hashlib.sha256(identity.encode()).hexdigest()[:32]}.json", identity


def _kept_result(folders: list[Path], run: SharedRun) -> tuple[dict, float] | None:
    """``(result, seconds)`` of ``run`` kept in one of ``folders``, else ``None``.

    Raises:
        ValueError: a kept file is not what :func:`_keep_result` writes for this run (not JSON,
            another run's, fields missing): it names the file, to be deleted.
    """
    for folder in folders:
        path, identity = _kept_path(folder, run)
        try:
            payload = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            continue
        except (OSError, UnicodeDecodeError, ValueError) as error:
            raise ValueError(f"the kept run {path} cannot be read ({error}): delete it") from None
        ok = isinstance(payload, dict) and payload.get("run") == identity
        ok = ok and isinstance(payload.get("result"), dict)
        ok = ok and isinstance(payload.get("seconds"), float) and payload["seconds"] >= 0
        if not ok:
            raise ValueError(f"the kept run {path} is not this run's result: delete it")
        return payload["result"], payload["seconds"]
    return None


def _keep_result(folders: list[Path], run: SharedRun, result: dict, seconds: float) -> None:
    """Write ``run``'s result into each of ``folders``, whole or not at all (a rename)."""
    for folder in folders:
        path, identity = _kept_path(folder, run)
        folder.mkdir(parents=True, exist_ok=True)
        payload = {"run": identity, "seconds": float(seconds), "result": result}
        partial = path.with_suffix(f".{os.getpid()}.part")
        partial.write_text(json.dumps(payload, default=json_default), encoding="utf-8")
        os.replace(partial, path)


class _Writer:
    """Writes each finished experiment's files, in background processes when several may be due.

    An experiment's figures take seconds to draw, and the last experiments to finish finish
    together: drawn one after another in this process, they would leave the workers idle at the
    end. With ``processes`` > 1 the files are written by a pool of that many processes on this
    machine (loky's, which carries the figures' closures), side by side and beside the runs; a
    summary that cannot be sent to another process is written here. ``on_done`` is called here,
    in the order the writes end, once the experiment's files are on disk. On an error (an
    interrupt included) the writes still running are abandoned.
    """

    def __init__(self, processes: int, on_done: Callable[[Experiment, Summary], None] | None):
        self.on_done = on_done
        self.pool: Any = None
        if processes > 1:
            self.pool = process_pool(processes)
        self.writing: list[tuple[Any, _Plan, Summary]] = []

    def __enter__(self) -> _Writer:
        return self

    def __exit__(self, *error: object) -> None:
        try:
            if error[0] is None:
                self.report(wait=True)
        finally:
            if self.pool is not None:
                failed = error[0] is not None
                self.pool.shutdown(wait=not failed, kill_workers=failed)

    def write(self, plan: _Plan, summary: Summary) -> None:
        """Write the plan's files (in the background with a pool), then report it."""
        if plan.out is not None and self.pool is not None and _sendable(plan, summary):
            job = self.pool.submit(write_outputs, plan.experiment, plan.config, summary, plan.out)
            self.writing.append((job, plan, summary))
            return
        if plan.out is not None:
            write_outputs(plan.experiment, plan.config, summary, plan.out)
        if self.on_done is not None:
            self.on_done(plan.experiment, summary)

    def report(self, wait: bool) -> None:
        """Call ``on_done`` for the writes that ended (all of them with ``wait``); raise theirs."""
        while self.writing:
            ended = [entry for entry in self.writing if entry[0].done()]
            if not ended and not wait:
                return
            if not ended:
                futures.wait([job for job, _, _ in self.writing], return_when="FIRST_COMPLETED")
                continue
            for entry in ended:
                self.writing.remove(entry)
                job, plan, summary = entry
                job.result()  # a write's error is raised here
                if self.on_done is not None:
                    self.on_done(plan.experiment, summary)


def _sendable(plan: _Plan, summary: Summary) -> bool:
    """Whether a write of the plan's summary can go to another process (loky's pickler)."""
    from joblib.externals.loky.backend.reduction import dumps

    try:
        dumps((plan.experiment, plan.config, summary))
    except Exception:  # any object pickling refuses: a lock, a generator, an open file...
        return False
    return True


def _summarize(
    plan: _Plan,
    runs: dict[str, SharedRun],
    results: dict[str, dict],
    seconds: dict[str, float],
    users: dict[str, list[_Plan]],
    started: float,
) -> Summary:
    """The plan's summary from its runs' results (each its own part, through its task's view).

    ``runs`` are the runs as run (pooled), by key; the summary's extra records the costs.
    """
    task_results = []
    for run, key in zip(plan.runs, plan.keys, strict=True):
        result = _own_result(run, runs[key], results[key])
        task_results.append(result if run.view is None else run.view(result))
    summary = plan.experiment.summarize(plan.tasks, task_results, plan.config)
    distinct = set(plan.keys)
    summary.extra["run_seconds"] = round(sum(seconds[key] for key in distinct), 2)
    summary.extra["runs"] = len(distinct)
    summary.extra["shared_runs"] = sum(len(users[key]) > 1 for key in distinct)
    summary.extra["wall_time_s"] = round(time.perf_counter() - started, 2)
    return summary

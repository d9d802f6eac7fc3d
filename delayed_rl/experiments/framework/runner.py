"""The shared experiment runner: seeds in parallel, curves, summaries, figures and a report.

An experiment module defines an :class:`Experiment`: its name, the thesis figure it reproduces,
``tasks(config)`` (one picklable task per (condition, seed)), ``run_task(task)`` (a dict of
results, numbers or numpy arrays) and ``summarize(tasks, results, config)`` (the claims checked
against the thesis, as :class:`Claim` rows, plus curves and figures).
:func:`~delayed_rl.experiments.framework.pool.run_experiment` runs the tasks through joblib — on its
default ``loky`` process pool, or handed to Ray or Dask — and :func:`write_outputs` writes
``curves.csv``, ``summary.json``, the figures and ``report.md`` into the output folder. Tasks
that need the same computation (of one experiment or several) name it as one
:class:`SharedRun`, run once.

Every task carries its own seed, so results do not depend on the number of workers.

**Verdicts.** A claim's verdict is one of :data:`VERDICTS`, computed from the measurement's
95 % interval and the thesis's value by the rule its ``criterion`` states (the helpers of
:mod:`.claims` build every row and its criterion):

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

from __future__ import annotations

import contextlib
import csv
import json
import math
import socket
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from delayed_rl._validation import check_bool, check_choice, check_int, check_real
from delayed_rl.agents.common.hyperparameters import MAX_SEED, check_limit
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS, MAX_TIMESTEPS_TEXT

#: The joblib backends :func:`run_tasks` can hand the runs to.
BACKENDS = ("loky", "ray", "dask")
MAX_SEEDS = 10_000
"""The most seeds (runs per condition) an experiment or a sweep runs."""
MAX_WORKERS = 1024
"""The most parallel workers asked for (a process or a cluster task each)."""
AGREES, DIFFERS, INCONCLUSIVE, REFERENCE = "agrees", "differs", "inconclusive", "reference"
#: A claim's possible verdicts (see the module docstring).
VERDICTS = (AGREES, DIFFERS, INCONCLUSIVE, REFERENCE)
# Student t 0.975 quantiles for 1..30 degrees of freedom (no scipy at run time).
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179,
         2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064,
         2.060, 2.056, 2.052, 2.048, 2.045, 2.042)  # fmt: skip


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
            :data:`MAX_SEEDS`, ``steps`` above ``MAX_TIMESTEPS`` = 2**40, ``workers`` above
            :data:`MAX_WORKERS`, ``base_seed`` above ``MAX_SEED`` = 2**63 − 1) or ``backend``
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
            "seeds", check_int("seeds", self.seeds, 1, optional=True), MAX_SEEDS, MAX_SEEDS_TEXT
        )
        self.steps = check_limit(
            "steps",
            check_int("steps", self.steps, 1, optional=True),
            MAX_TIMESTEPS,
            MAX_TIMESTEPS_TEXT,
        )
        self.quick = check_bool("quick", self.quick)
        self.workers = check_workers("workers", self.workers)
        self.backend = check_choice("backend", self.backend, BACKENDS)
        self.base_seed = check_limit(
            "base_seed", check_int("base_seed", self.base_seed, 0), MAX_SEED, MAX_SEED_TEXT
        )


MAX_SEEDS_TEXT = f"MAX_SEEDS = {MAX_SEEDS:,} (delayed_rl.experiments.framework.runner)"
MAX_WORKERS_TEXT = f"MAX_WORKERS = {MAX_WORKERS} (delayed_rl.experiments.framework.runner)"
MAX_SEED_TEXT = "MAX_SEED = 2**63 - 1 (delayed_rl.agents.common.hyperparameters)"


def check_workers(name: str, workers: Any) -> int:
    """Return ``workers``, an integer in ``[1, MAX_WORKERS]``, after checking it.

    Raises:
        TypeError: it is not an integer.
        ValueError: it is below 1 or above :data:`MAX_WORKERS`.
    """
    return check_limit(name, check_int(name, workers, 1), MAX_WORKERS, MAX_WORKERS_TEXT)


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
        task: what ``run`` is called with (JSON-like: its canonical form is the run's identity).
        view: picks the task's result out of the run's (``None``: the whole result); with
            ``pooled``, out of the task's own part of it.
        pooled: the name of the list in ``task`` whose items runs pool (``None``: none).
    """

    run: Callable[[dict], dict]
    task: dict
    view: Callable[[dict], dict] | None = None
    pooled: str | None = None

    def alone(self) -> dict:
        """The task's result from a run of its own, in this process: ``view(run(task))``."""
        result = self.run(self.task)
        return result if self.view is None else self.view(result)


def default_cost(task: dict) -> float:
    """A task's estimated cost for scheduling: its ``steps`` (1 without), at a microsecond each."""
    return 1e-6 * float(task.get("steps", 1))


@dataclass
class Experiment:
    """A thesis experiment (see the module docstring).

    Attributes:
        name: the name ``delayed-rl bench NAME`` takes.
        thesis: the thesis's figure or table it reproduces.
        description: the report's first paragraph.
        tasks: one task per (condition, seed), from the :class:`Config`.
        run_task: a picklable top-level function of one task, returning its result.
        summarize: the claims, curves and figures, from the tasks and their results.
        default_seeds: the seeds of a full run.
        quick_seeds: the seeds of a ``quick`` run.
        shared_run: the :class:`SharedRun` behind a task whose run another task (of this
            experiment or another) also needs, else ``None`` (``shared_run`` itself ``None``:
            every task is its own run, ``run_task(task)``).
        cost: a task's estimated core-seconds, which only orders the runs (longest first, so
            that no long run starts last); ``None``: :func:`default_cost`.
        resumable: keep each run's result as it finishes, in ``OUT/runs/`` of the experiment's
            output folder, and read it back instead of running it again when the experiment is
            run into the same folder (its results must be JSON: dicts, lists, numbers, text).
            A run is found by its function and task, so a changed setting runs afresh; delete
            ``OUT/runs/`` to run everything again.
    """

    name: str
    thesis: str
    description: str
    tasks: Callable[[Config], list[dict]]
    run_task: Callable[[dict], dict]
    summarize: Callable[[list[dict], list[dict], Config], Summary]
    default_seeds: int
    quick_seeds: int = 2
    shared_run: Callable[[dict], SharedRun | None] | None = None
    cost: Callable[[dict], float] | None = None
    resumable: bool = False

    def run_of(self, task: dict) -> SharedRun:
        """The run behind ``task``: its :attr:`shared_run`, else ``run_task`` on the task itself."""
        shared = None if self.shared_run is None else self.shared_run(task)
        return SharedRun(self.run_task, task) if shared is None else shared

    def task_cost(self, task: dict) -> float:
        """``task``'s estimated core-seconds: its :attr:`cost`, else :func:`default_cost`."""
        return float((self.cost or default_cost)(task))


def seed_tasks(config: Config, agents: Sequence[str], **fields: object) -> list[dict]:
    """One task per (seed, agent): ``{"agent", "seed", **fields}``, seed-major.

    Seeds run from ``config.base_seed``, ``config.seeds`` of them.
    """
    return [
        {"agent": agent, "seed": config.base_seed + i, **fields}
        for i in range(config.seeds)
        for agent in agents
    ]


def mean_ci95(values: Sequence[float]) -> tuple[float, float]:
    """Mean and the half-width of a 95 % Student-t confidence interval (0 for one value)."""
    values = np.asarray(values, dtype=float)
    n = values.size
    if n == 0:
        return math.nan, math.nan
    if n == 1:
        return float(values[0]), 0.0
    return float(values.mean()), float(t975(n - 1) * values.std(ddof=1) / math.sqrt(n))


def t975(df: int) -> float:
    """Student's t 0.975 quantile with ``df`` (≥ 1) degrees of freedom."""
    if df <= len(_T975):
        return _T975[df - 1]
    # Cornish–Fisher expansion of the normal quantile, accurate to 1e-3 beyond 30 df
    z = 1.959964
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)


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


def run_tasks(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None = None,
) -> list[dict]:
    """Run ``tasks`` with ``workers`` processes on ``backend``; return the results in their order.

    See :func:`iter_tasks` for the arguments and errors.
    """
    results: list[Any] = [None] * len(tasks)
    for index, result in iter_tasks(run_task, tasks, workers, backend, address):
        results[index] = result
    return results


def iter_tasks(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None = None,
) -> Iterator[tuple[int, dict]]:
    """Run ``tasks`` in parallel: an iterator of ``(index, result)``, one as each task finishes.

    Results come in the order the tasks finish, so a caller can keep each as soon as it is
    done. ``loky`` and ``dask`` run through joblib; ``ray`` through Ray's own tasks (one CPU
    each), as its joblib backend returns nothing before every task is done. The arguments are
    checked at once; the backend starts (a local Ray or Dask cluster, the connection to one at
    ``address``) when the first result is asked for.

    Args:
        run_task: a picklable function of one task (a module's top-level function).
        tasks: the tasks.
        workers: how many tasks run at once; ``None``: as many as the backend has cores. With
            ``backend="loky"`` and 1 worker the tasks run in this process, one after another.
        backend: ``"loky"`` (joblib's process pool on this machine), ``"ray"`` or ``"dask"``.
        address: a running cluster of ``backend`` to send the tasks to. Ray:
            ``ray.init(address=address)`` (e.g. ``"auto"``, ``"ray://host:10001"``), unless Ray
            is initialized already in this process, which is then used as it is; without an
            address, ``ray.init()`` starts a local Ray (or the one initialized is used).
            Dask: a ``Client(address)`` of the scheduler (e.g. ``"tcp://host:8786"``), closed
            afterwards (not the cluster); without one, a local cluster of ``workers``
            processes that lives as long as the tasks.

    Raises:
        TypeError: ``workers`` is not an integer (or ``None``), ``backend`` or ``address`` not a
            string.
        ValueError: ``workers`` < 1, ``backend`` is not one of :data:`BACKENDS`, or an
            ``address`` is given for ``loky``.
        RuntimeError: the backend's package (Ray, Dask) is not installed, or the backend
            could not start (or reach the cluster at ``address``): the message names the
            backend and the error it raised. Raised when the first result is asked for.
    """
    check_choice("backend", backend, BACKENDS)
    if workers is not None:
        check_workers("workers", workers)
    if address is not None:
        if not isinstance(address, str):
            raise TypeError(f"address must be a string, got {address!r} ({type(address).__name__})")
        if backend == "loky":
            raise ValueError(f"address is for the ray and dask backends, not {backend!r}")
    if workers == 1 and backend == "loky":
        return _in_process_results(run_task, tasks)
    if backend == "ray":
        return _ray_results(run_task, tasks, workers, address)
    return _joblib_results(run_task, tasks, workers, backend, address)


def tqdm_installed() -> bool:
    """Whether tqdm is installed (an optional dependency), so :class:`RunProgress` draws a bar."""
    return _tqdm() is not None


def _tqdm() -> Any:
    """``tqdm.auto.tqdm`` (a terminal's bar, or a notebook's), or ``None`` without tqdm."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm


class RunProgress:
    """The progress of ``total`` runs on stderr: tqdm's bar, else a line per finished run.

    A context manager: ``with RunProgress(total, label, enabled) as progress:``, then
    :meth:`tick` once per finished run (as :func:`iter_tasks` yields it), and print to the
    terminal inside :meth:`paused`. tqdm's bar (tqdm is optional, in the ``dev`` extra) shows
    the runs done out of ``total``, the time elapsed and the time left, and stays drawn, as it
    ends, on a line of its own; without tqdm each :meth:`tick` prints
    ``[label] done/total runs done``.

    Args:
        total: how many runs there are.
        label: the bar's name (``sweep``, an experiment's name).
        enabled: show anything at all (``False``: every method does nothing).

    Attributes:
        done: how many runs have been counted so far.
    """

    def __init__(self, total: int, label: str, enabled: bool):
        self.total, self.label, self.done = total, label, 0
        tqdm = _tqdm() if enabled else None
        self._bar = None
        if tqdm is not None:
            self._bar = tqdm(total=total, desc=label, unit="run", file=sys.stderr)
        self._lines = enabled and self._bar is None

    def __enter__(self) -> RunProgress:
        return self

    def __exit__(self, *error: object) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def tick(self) -> None:
        """Count one more run done."""
        self.done += 1
        if self._bar is not None:
            self._bar.update()
        elif self._lines:
            print(f"[{self.label}] {self.done}/{self.total} runs done", file=sys.stderr, flush=True)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """A context in which to print to the terminal: the bar is cleared, then drawn again."""
        if self._bar is None:
            yield
            return
        self._bar.clear()
        try:
            yield
        finally:
            sys.stdout.flush()
            self._bar.refresh()


def _in_process_results(
    run_task: Callable[[dict], dict], tasks: list[dict]
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` in this process, one task after another."""
    for index, task in enumerate(tasks):
        yield index, run_task(task)


def _indexed(run_task: Callable[[dict], dict], index: int, task: dict) -> tuple[int, dict]:
    """``(index, run_task(task))``: a result that says which task it is."""
    return index, run_task(task)


def _joblib_results(
    run_task: Callable[[dict], dict],
    tasks: list[dict],
    workers: int | None,
    backend: str,
    address: str | None,
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` on joblib's ``loky`` or ``dask`` backend."""
    import joblib

    with contextlib.ExitStack() as cleanup:
        if backend == "dask":
            cleanup.enter_context(_dask_client(workers, address))  # closed after
        with joblib.parallel_config(backend=backend, n_jobs=-1 if workers is None else workers):
            parallel = joblib.Parallel(return_as="generator_unordered")
            calls = (joblib.delayed(_indexed)(run_task, i, task) for i, task in enumerate(tasks))
            yield from parallel(calls)


def _dask_client(workers: int | None, address: str | None) -> Any:
    """A Dask client of the scheduler at ``address``, else of a local cluster of ``workers``."""
    try:
        from dask.distributed import Client
    except ImportError as error:
        raise RuntimeError("backend 'dask' needs Dask: pip install 'dask[distributed]'") from error
    try:
        if address is not None:
            return Client(address)  # closing it leaves the cluster, which is not ours, running
        return Client(processes=True, n_workers=workers)
    except Exception as error:  # Dask raises OSError, TimeoutError, ValueError...
        raise RuntimeError(_not_started("dask", address, error)) from error


#: How long a cluster's address may take to answer before the backend is said not to start.
CONNECT_TIMEOUT = 10.0


def _check_reachable(backend: str, address: str | None) -> None:
    """Refuse at once a ``host:port`` (or ``ray://host:port``) address that nobody answers.

    (Ray's own connection waits for minutes for an address that does not answer.) Other
    addresses (``"auto"``, ``None``) are left to the backend.

    Raises:
        RuntimeError: nothing accepted a TCP connection at the address within
            :data:`CONNECT_TIMEOUT` seconds.
    """
    if address is None:
        return
    host, _, port = address.removeprefix(f"{backend}://").rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT).close()
    except (OSError, ValueError, OverflowError) as error:
        raise RuntimeError(_not_started(backend, address, error)) from None


def _not_started(backend: str, address: str | None, error: BaseException) -> str:
    """The message for a backend that could not start (or reach the cluster at ``address``)."""
    where = f"the cluster at {address!r}" if address is not None else "a local cluster"
    reason = " ".join(str(error).split()) or type(error).__name__
    return f"backend {backend!r} could not start on {where}: {type(error).__name__}: {reason}"


def _ray_results(
    run_task: Callable[[dict], dict], tasks: list[dict], workers: int | None, address: str | None
) -> Iterator[tuple[int, dict]]:
    """:func:`iter_tasks` on Ray: at most ``workers`` tasks in flight (``None``: all of them)."""
    try:
        import ray
    except ImportError as error:
        raise RuntimeError("backend 'ray' needs Ray: pip install 'ray[default]'") from error
    if not ray.is_initialized():
        _check_reachable("ray", address)
        try:
            ray.init(address=address)
        except Exception as error:  # Ray raises ConnectionError, RuntimeError, plain Exception...
            raise RuntimeError(_not_started("ray", address, error)) from error
    remote = ray.remote(num_cpus=1)(_indexed)
    waiting = list(enumerate(tasks))[::-1]
    running: list[Any] = []
    try:
        while waiting or running:
            while waiting and (workers is None or len(running) < workers):
                running.append(remote.remote(run_task, *waiting.pop()))
            done, running = ray.wait(running, num_returns=1)
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayTaskError as error:
                raise error.cause from None  # the task's own exception, not Ray's wrapper
    finally:
        for ref in running:
            ray.cancel(ref)


def write_outputs(experiment: Experiment, config: Config, summary: Summary, out: Path) -> None:
    """Write ``curves.csv``, ``summary.json``, the figures and ``report.md`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "curves.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["experiment", "condition", "seed", "metric", "step", "value"])
        for curve in summary.curves:
            for step, value in zip(curve.steps.tolist(), curve.values.tolist(), strict=True):
                writer.writerow(
                    [experiment.name, curve.condition, curve.seed, curve.metric, step, value]
                )
    payload = {
        "experiment": experiment.name,
        "thesis": experiment.thesis,
        "config": asdict(config),
        "claims": [asdict(claim) for claim in summary.claims],
        **summary.extra,
    }
    (out / "summary.json").write_text(json.dumps(payload, indent=2, default=_json_default))
    figures = []
    for name, draw in summary.figures.items():
        try:
            draw(out / f"{name}.png")
            figures.append(f"{name}.png")
        except ImportError:
            figures.append(f"{name}.png (not drawn: install the plot extra, matplotlib)")
    (out / "report.md").write_text(render_report(experiment, config, summary, figures))


def write_index(
    out: Path, ran: Sequence[tuple[Experiment, Summary]], wall_seconds: float | None = None
) -> Path:
    """Write ``out/index.md``: every experiment run, what it cost, its verdicts and its report.

    ``delayed-rl reproduce`` writes it after the last experiment: one table of every
    experiment's verdict counts and cost, each linking to its ``NAME/report.md``. The cost is
    the core-seconds of the experiment's runs (``extra["run_seconds"]``, a run shared between
    experiments counted in each, marked in the ``shared runs`` column), as they ran together on
    one pool (:mod:`.pool`).

    Args:
        out: the folder of the experiments' folders.
        ran: each experiment with its summary, in the table's order.
        wall_seconds: the wall time of the whole run, for the last line (``None``: left out).

    Returns:
        The file written.

    Raises:
        TypeError, ValueError: ``wall_seconds`` is not ``None`` or a real number ≥ 0.
    """
    wall_seconds = check_real("wall_seconds", wall_seconds, 0.0, optional=True)
    lines = [
        "# Reproduction: every experiment",
        "",
        "| experiment | thesis | runs | shared runs | core-seconds | "
        + " | ".join(VERDICTS)
        + " | report |",
        "|---|---|---|---|---|" + "---|" * len(VERDICTS) + "---|",
    ]
    for experiment, summary in ran:
        extra = summary.extra
        counts = [str(sum(c.verdict == v for c in summary.claims)) for v in VERDICTS]
        link = f"[{experiment.name}/report.md]({experiment.name}/report.md)"
        lines.append(
            f"| `{experiment.name}` | {experiment.thesis} | {extra.get('runs', '?')} | "
            f"{extra.get('shared_runs', 0)} | {float(extra.get('run_seconds', 0.0)):.1f} | "
            + " | ".join(counts)
            + f" | {link} |"
        )
    if wall_seconds is not None:
        lines += ["", f"Wall time: {wall_seconds:.1f} s ({wall_seconds / 60:.1f} min)."]
    path = out / "index.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def _cost_text(summary: Summary) -> str:
    """What the experiment cost, for its report: runs, shared runs, core-seconds, wall time."""
    extra = summary.extra
    if "run_seconds" not in extra:
        return f"wall time: {extra.get('wall_time_s', '?')} s."
    return (
        f"cost: {extra['runs']} runs ({extra['shared_runs']} shared with the other experiments "
        f"run with it), {extra['run_seconds']} core-seconds; done {extra['wall_time_s']} s "
        "after the start."
    )


def render_report(
    experiment: Experiment, config: Config, summary: Summary, figures: list[str]
) -> str:
    """The Markdown report: per claim, the thesis value, the measurement, verdict and criterion.

    The measurement is its mean ± 95 % CI, or its mean and the ends of an asymmetric 95 %
    interval in brackets (a share's Wilson interval).
    """
    lines = [
        f"# {experiment.name} — {experiment.thesis}",
        "",
        experiment.description,
        "",
        f"Seeds: {config.seeds} (from {config.base_seed}); steps: "
        f"{config.steps or 'thesis default'}; quick: {config.quick}; {_cost_text(summary)}",
        "",
        "| quantity | thesis value | measured mean ± 95 % CI | seeds | verdict | criterion |",
        "|---|---|---|---|---|---|",
    ]
    for claim in summary.claims:
        lines.append(
            f"| {claim.quantity} | {claim.thesis} | {claim.interval_text()} | "
            f"{claim.n} | {claim.verdict} | {claim.criterion} |"
        )
    counts = {v: sum(c.verdict == v for c in summary.claims) for v in VERDICTS}
    lines += ["", "Verdicts: " + ", ".join(f"{k} {v}" for k, v in counts.items()) + "."]
    notes = [f"- {claim.quantity}: {claim.note}" for claim in summary.claims if claim.note]
    if notes:
        lines += ["", "Notes:", *notes]
    drawn = [figure for figure in figures if figure.endswith(".png")]
    missing = [figure for figure in figures if not figure.endswith(".png")]
    if drawn:
        lines += ["", "## Figures", ""]
        lines += [f"![{Path(figure).stem}]({figure})\n" for figure in drawn]
    if missing:
        lines += ["", "Figures not drawn:", *[f"- {figure}" for figure in missing]]
    return "\n".join(lines) + "\n"

"""Sweeps of your own: agents × envs × delay distributions × seeds, defined in one file.

``delayed-rl sweep FILE`` (or :func:`load_sweep` and :func:`run_sweep`) trains every agent on
every env under every delay for every seed, evaluates each greedily, and writes the runs, their
summary and a figure per env. The parts: :mod:`~delayed_rl.sweep.reading` reads a file with
limits, :mod:`~delayed_rl.sweep.schema` checks it into a :class:`~delayed_rl.sweep.schema.Sweep`,
:mod:`~delayed_rl.sweep.runs` trains and evaluates one run, :mod:`~delayed_rl.sweep.results`
reads, resumes and summarizes ``results.csv``. The file format, the columns, resuming and
determinism: the docs' sweeps page (``docs/sweeps.md``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from delayed_rl.parallel.pools import iter_tasks
from delayed_rl.parallel.progress import RunProgress
from delayed_rl.sweep.reading import read_sweep_file
from delayed_rl.sweep.results import (
    EXTRA_COLUMNS,
    RESULT_COLUMNS,
    RESULTS_FILE,
    SUMMARY_COLUMNS,
    _in_sweep_order,
    agent_delay_table,
    append_result,
    draw_figures,
    figure_name,
    plot_env,
    read_results,
    render_summary,
    run_key,
    summarize,
    write_results,
    write_summary_csv,
)
from delayed_rl.sweep.runs import (
    EVAL_SEED_OFFSET,
    MAX_EVAL_EPISODE_STEPS,
    RunError,
    UndelayedRewardTally,
    check_sweep,
    evaluate,
    make_env,
    make_model,
    resolve_placeholders,
    reward_delay,
    run_sweep_task,
    train,
)
from delayed_rl.sweep.schema import (
    DEFAULT_EVAL_EPISODES,
    DEFAULT_SEEDS,
    DEFAULT_STEPS,
    DELAY_KINDS,
    PLACEHOLDERS,
    SB3_ALGORITHMS,
    SB3_PREFIX,
    Evaluation,
    Sweep,
    SweepAgent,
    SweepDelay,
    SweepEnv,
    parse_sweep,
)

__all__ = [
    "DEFAULT_EVAL_EPISODES",
    "DEFAULT_SEEDS",
    "DEFAULT_STEPS",
    "DELAY_KINDS",
    "EVAL_SEED_OFFSET",
    "EXTRA_COLUMNS",
    "MAX_EVAL_EPISODE_STEPS",
    "PLACEHOLDERS",
    "RESULTS_FILE",
    "RESULT_COLUMNS",
    "SB3_ALGORITHMS",
    "SB3_PREFIX",
    "SUMMARY_COLUMNS",
    "Evaluation",
    "RunError",
    "Sweep",
    "SweepAgent",
    "SweepDelay",
    "SweepEnv",
    "SweepOutcome",
    "UndelayedRewardTally",
    "agent_delay_table",
    "append_result",
    "check_sweep",
    "draw_figures",
    "evaluate",
    "figure_name",
    "load_sweep",
    "make_env",
    "make_model",
    "parse_sweep",
    "plot_env",
    "read_results",
    "read_sweep_file",
    "render_summary",
    "resolve_placeholders",
    "reward_delay",
    "run_key",
    "run_sweep",
    "run_sweep_task",
    "summarize",
    "train",
    "write_results",
    "write_summary_csv",
]


# ---------------------------------------------------------------------------------- loading
def load_sweep(path: str | Path, check: bool = True) -> Sweep:
    """Read, parse and (with ``check``) try out a sweep file: :func:`parse_sweep`, :func:`check_sweep`.

    Args:
        path: the ``.yaml``, ``.yml`` or ``.json`` file.
        check: build every (agent, env, delay) once before returning, so that an argument the
            agent refuses, or an env it cannot use, fails now rather than in the middle.

    Raises:
        OSError, RuntimeError: see :func:`read_sweep_file` (and, with ``check``, a missing
            extra such as stable-baselines3).
        TypeError, ValueError: the file is wrong; the message starts with its path.
    """
    data = read_sweep_file(path)
    try:
        sweep = parse_sweep(data, name=Path(path).stem, source=str(path))
        if check:
            check_sweep(sweep)
    except TypeError as error:
        raise TypeError(f"{path}: {error}") from None
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    return sweep


# ---------------------------------------------------------------------------------- running
@dataclass
class SweepOutcome:
    """What :func:`run_sweep` did.

    Attributes:
        out: the output folder.
        runs: the sweep's runs.
        ran: how many of them ran now.
        skipped: how many were already in ``results.csv``.
        wall_s: the seconds it took.
        summary: the rows of ``summary.csv``.
        figures: per env label, its figure's file name (or why it was not drawn).
    """

    out: Path
    runs: int
    ran: int
    skipped: int
    wall_s: float
    summary: list[dict[str, Any]] = field(default_factory=list)
    figures: dict[str, str] = field(default_factory=dict)


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    workers: int | None = None,
    backend: str = "loky",
    address: str | None = None,
    progress: bool = False,
) -> SweepOutcome:
    """Run the runs of ``sweep`` that ``out/results.csv`` lacks; write the results and summary.

    Args:
        sweep: what :func:`load_sweep` (or :func:`parse_sweep`) returned.
        out: the output folder (made if missing); ``results.csv`` there is resumed.
        workers: runs in parallel (``None``: 1 with ``loky``, which runs them in this process;
            every core of the cluster with ``ray`` and ``dask``).
        backend: ``"loky"`` (joblib's process pool), ``"ray"`` or ``"dask"``.
        address: an existing Ray or Dask cluster to run on (``None``: a local one); see
            :func:`~delayed_rl.parallel.pools.iter_tasks`.
        progress: show the progress on stderr (:class:`~delayed_rl.parallel.progress.RunProgress`:
            tqdm's bar, else a count line per run).

    Returns:
        What was run and written.

    Raises:
        TypeError, ValueError: a bad argument, or ``out/results.csv`` is not a sweep's.
        RunError: a run failed (the rows of the runs that finished are kept).
        RuntimeError: the backend's package (Ray, Dask) is not installed.
    """
    if workers is None and backend == "loky":
        workers = 1
    out = Path(out)
    results = out / RESULTS_FILE
    tasks = sweep.runs()
    existing = read_results(results)
    done = {run_key(row) for row in existing}
    pending = [task for task in tasks if run_key(task) not in done]
    finished = iter_tasks(run_sweep_task, pending, workers, backend, address)  # checks the rest
    out.mkdir(parents=True, exist_ok=True)
    write_results(results, existing)  # a clean file to append to, without a row cut short
    started = time.perf_counter()
    if pending:  # (no backend starts for nothing)
        with RunProgress(len(pending), "sweep", progress) as counter:
            for _, row in finished:
                append_result(results, row)
                counter.tick()
    ours, others = _in_sweep_order(read_results(results), tasks)
    write_results(results, [*ours, *others])
    summary = summarize(ours)
    write_summary_csv(out / "summary.csv", summary)
    figures = draw_figures(out, summary)
    (out / "summary.md").write_text(render_summary(sweep, summary, figures), encoding="utf-8")
    return SweepOutcome(
        out=out,
        runs=len(tasks),
        ran=len(pending),
        skipped=len(tasks) - len(pending),
        wall_s=round(time.perf_counter() - started, 2),
        summary=summary,
        figures=figures,
    )

"""Sweeps of your own: agents × envs × delay distributions × seeds, defined in one file.

``delayed-rl sweep FILE`` (or :func:`load_sweep` and :func:`run_sweep`) answers "which agent
copes with which delay on my envs?": it trains every agent on every env under every delay for
every seed, runs each trained agent's greedy policy, and writes into the output folder
``results.csv`` (one row per run), ``summary.csv`` and ``summary.md`` (mean and 95 % confidence
interval over the seeds) and one figure per env, ``eval_reward_<env>.png``.

**The sweep file.** YAML (``.yaml`` or ``.yml``; reading it needs the ``sweep`` extra, PyYAML)
or JSON (``.json``), holding one mapping with the keys below. Every key and value is checked
before anything runs: a value of the wrong type is a ``TypeError``, a wrong value (an unknown
name, a number out of range, an unknown key anywhere) a ``ValueError``, and the message names
the field (``agents[1].kwargs.gamma``), the value and what is allowed. A key given twice in
one mapping is refused (YAML's merge key ``<<`` keeps its meaning), and so is a file that would
make the reader work far beyond a sweep's needs: over 1 MB, nested over 32 levels, or standing
for over 100 000 values once YAML's aliases are expanded
(:mod:`delayed_rl.sweep.reading`). A sweep has at most 100 000 runs.

``agents`` (required)
    A non-empty list. Each entry is an agent's name, or a mapping with the keys

    - ``name`` (required): one of the library's agents — ``q`` (:class:`~delayed_rl.agents.QLearning`),
      ``fixed`` (:class:`~delayed_rl.agents.FixedDelayQLearning`, which needs
      ``delay_estimate``), ``mmq`` (:class:`~delayed_rl.agents.MultipleModelQLearning`),
      ``deconv`` (:class:`~delayed_rl.agents.DeconvolutionQLearning`), ``oracle``
      (:class:`~delayed_rl.agents.OracleQLearning`) and ``expected-credit``
      (:class:`~delayed_rl.agents.ExpectedCreditQLearning`, which needs ``delay``) — or a
      stable-baselines3 algorithm, ``sb3:A2C``, ``sb3:DDPG``, ``sb3:DQN``, ``sb3:PPO``,
      ``sb3:SAC`` or ``sb3:TD3`` (the ``sb3`` extra);
    - ``kwargs``: the agent's constructor arguments (default none). For the library's agents,
      any argument of the class but ``env`` and ``seed`` (the sweep sets those), e.g.
      ``{learning_rate: 0.1, q_init: 5, max_delay_estimate: 10}``; for SB3, the algorithm's
      (``policy`` defaults to ``MlpPolicy``), e.g. ``{n_steps: 256, learning_rate: 0.001}``;
    - ``label``: its name in the results (default: ``name``); two entries of the same name
      need labels of their own;
    - ``steps``: training steps of its runs (default: the env's ``steps``, else the sweep's);
    - ``envs``: the labels of the envs it runs on (default: all), e.g. to keep tabular agents
      off ``CartPole-v1``.

    *The run's delay as an argument.* A ``kwargs`` value that is one of these strings is
    replaced, in each run, by the run's reward delay (the delay entry's ``reward``;
    ``Constant(0)`` when the entry delays no reward):

    - ``$delay``: the distribution itself, a :class:`~delayed_rl.delays.Delay` (for
      ``expected-credit``'s ``delay``, or ``deconv``'s to know the delay instead of learning it);
    - ``$delay_mean``: its mean, a float;
    - ``$delay_steps``: its mean rounded to an integer (for ``fixed``'s ``delay_estimate``).

    The ``oracle`` needs to know which transition emitted each reward: its envs get a
    :class:`~delayed_rl.wrappers.RewardDelay` with ``record_arrivals=True`` by themselves.

``envs`` (required)
    A non-empty list. Each entry is a Gymnasium id (``delayed_rl/GridWorld-5x5-v0``,
    ``Taxi-v4``, ``CartPole-v1``, or ``module:Id`` to import your own), or a mapping with the
    keys

    - ``id`` (required): the id;
    - ``kwargs``: ``gym.make``'s keyword arguments (default none), e.g. ``{size: 7}``; the
      delays come from ``delays``, so ``reward_delay``, ``observation_delay`` and
      ``action_delay`` are not allowed here;
    - ``label``: its name in the results (default: ``id``);
    - ``steps``: training steps on it (default: the sweep's; an agent's ``steps`` wins);
    - ``eval_episodes`` or ``eval_steps``: how to evaluate on it (default: the sweep's).

``delays`` (required)
    A non-empty list. Each entry is

    - a number λ ≥ 0: rewards delayed by Poisson(λ) steps (``0``: undelayed);
    - a distribution's description, as :meth:`Delay.to_dict() <delayed_rl.delays.Delay.to_dict>`
      writes it and :func:`~delayed_rl.delays.as_delay` reads it: ``{type: Geometric, p: 0.25}``,
      ``{type: Constant, k: 2}``, ``{type: Uniform, low: 0, high: 6}``,
      ``{type: Empirical, pmf: [0.5, 0.3, 0.2]}``, ``{type: Poisson, lam: 3}``: on the rewards;
    - or a mapping with any of the keys ``reward``, ``observation`` and ``action`` (at least
      one), each a number or a description as above — what is delayed, stacked as
      :func:`~delayed_rl.wrappers.wrap_delays` stacks them — and ``label``.

    Its label (default: the distribution, ``Poisson(lam=3)``, prefixed by what it delays when
    that is not only the reward, e.g. ``observation Poisson(lam=2)``) names it in the results.

``seeds`` (default 3)
    A count ``n`` (seeds ``0 .. n − 1``) or a list of distinct integers in ``[0, 2**32 − 1]``
    (:data:`~delayed_rl.sweep.schema.MAX_SWEEP_SEED`), at most
    :data:`~delayed_rl.experiments.runner.MAX_SEEDS` (10 000) of them. Seed ``s`` seeds
    the agent (``seed=s``: its random choices and its training env's first reset, delays
    included); the evaluation env is reset with seed ``s`` + :data:`EVAL_SEED_OFFSET`.

``steps`` (default 100 000)
    Training steps per run (``learn(steps)``; SB3's on-policy algorithms round up to whole
    rollouts), at most ``learn()``'s bound, 2**40.

``eval_episodes`` or ``eval_steps`` (default ``eval_episodes: 10``)
    The greedy evaluation after training (``predict(obs, deterministic=True)``, no learning,
    on a fresh env under the same delays): that many whole episodes (at most 10**6), or that
    many steps (at most 10**9).
    Continuing envs, whose episodes never end (the grid worlds), need ``eval_steps``; an
    episode longer than :data:`MAX_EVAL_EPISODE_STEPS` fails its run.

``name`` (default: the file's name without its suffix)
    The title of ``summary.md``.

An example (``examples/sweep.yaml`` is a commented one that runs in about a minute):

.. code-block:: yaml

    name: delayed rewards on two small worlds
    agents:
      - q
      - {name: mmq, kwargs: {max_delay_estimate: 10}}
      - {name: expected-credit, kwargs: {delay: $delay, max_delay: 30}}
      - {name: fixed, label: fixed at the mean, kwargs: {delay_estimate: $delay_steps}}
    envs:
      - {id: delayed_rl/GridWorld-5x5-v0, eval_steps: 1000}
      - {id: Taxi-v4, steps: 200000}
    delays:
      - 3
      - {type: Geometric, p: 0.25}
      - {observation: 1, label: observations one step late}
    seeds: 3
    steps: 30000
    eval_episodes: 20

YAML anchors share settings between entries (``kwargs: &tabular {q_init: 5}``, then
``kwargs: {<<: *tabular, max_delay_estimate: 10}``).

**Results.** ``results.csv`` has one row per run, with the columns :data:`RESULT_COLUMNS` —
``agent``, ``env``, ``delay`` (the labels), ``seed``, ``steps``, ``train_reward`` (the mean
undelayed reward per step during training: the agent's ``rollout/undelayed_reward_per_step``,
or for SB3 every step its env took), ``eval_reward`` (the greedy evaluation's mean undelayed
return per episode, or its mean undelayed reward per step with ``eval_steps``) and ``wall_s``
(the run's seconds) — then ``eval_unit`` (``episode`` or ``step``: which of the two
``eval_reward`` is) and ``run_id`` (a hash of the run's whole configuration: agent and its
arguments, env and its arguments, delays, seed, steps, evaluation). ``summary.csv`` has, per
(agent, env, delay), the seeds and the mean and 95 % CI half-width (Student t,
:func:`~delayed_rl.experiments.runner.mean_ci95`) of both rewards; ``summary.md`` shows the
evaluation and training rewards as an agent × delay table per env, the best agent per delay in
bold, beside the env's figure (the ``plot`` extra, matplotlib: mean and 95 % CI bars of the
evaluation reward by delay, one colour per agent).

**Resuming.** Each run's row is appended to ``results.csv`` as it finishes. Rerunning a sweep
with the same output folder skips the runs already there — matched by agent, env, delay, seed
and ``run_id``, so a run whose configuration changed (more steps, another argument) runs again
— and appends the rest; an interrupted sweep keeps what finished. Rows of runs no longer in
the file are kept in ``results.csv`` (after the sweep's own, which are in the file's order:
agent, env, delay, seed), but left out of the summary. The file is checked row by row before
a sweep resumes from it (:func:`~delayed_rl.sweep.results.check_result_row`): a
row cut short at the end of the file (the sweep stopped while writing it) is left out with a
warning and its run runs again; any other bad row (a value that does not parse, ``nan``, a
wrong number of values) stops the sweep with an error naming the file, the line and the
column, for you to correct or delete.

**Determinism and backends.** Every run builds its env and agent from its own configuration
and seed, so the numbers (all but ``wall_s``) are the same whatever runs them: in this process
(``workers=1``), on joblib's process pool (``workers=N``), or on a Ray or Dask cluster
(``backend="ray"``/``"dask"``, local or at ``address``; see
:func:`~delayed_rl.experiments.runner.iter_tasks`). SB3 runs use one torch thread, so their
floating-point sums do not depend on the machine's thread count either.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from delayed_rl.experiments.runner import RunProgress, iter_tasks
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
            :func:`~delayed_rl.experiments.runner.iter_tasks`.
        progress: show the progress on stderr (:class:`~delayed_rl.experiments.runner.RunProgress`:
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

"""A sweep's result files: ``results.csv`` (read, appended to, resumed), the summary, the figures.

``results.csv`` holds one row per run, keyed by :func:`run_key`; :func:`summarize` turns the
rows into ``summary.csv``, :func:`render_summary` into ``summary.md`` and :func:`draw_figures`
into one figure per env.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import textwrap
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from delayed_rl.agents.common.hyperparameters import MAX_ABS_VALUE
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.parallel.intervals import mean_ci95
from delayed_rl.sweep.schema import MAX_SWEEP_SEED_VALUE, Sweep

#: The columns of ``results.csv`` that every sweep writes, in this order.
RESULT_COLUMNS = ("agent", "env", "delay", "seed", "steps", "train_reward", "eval_reward", "wall_s")
#: The columns after them: which ``eval_reward`` it is, and the run's configuration hash.
EXTRA_COLUMNS = ("eval_unit", "run_id")
SUMMARY_COLUMNS = (
    "agent",
    "env",
    "delay",
    "seeds",
    "train_reward_mean",
    "train_reward_ci95",
    "eval_reward_mean",
    "eval_reward_ci95",
    "eval_unit",
)


# ---------------------------------------------------------------------------------- results
RESULTS_FILE = "results.csv"
_COLUMNS = (*RESULT_COLUMNS, *EXTRA_COLUMNS)


def run_key(row: Mapping[str, Any]) -> tuple[str, ...]:
    """What identifies a run in ``results.csv``: its labels, seed and ``run_id``, as text."""
    return tuple(str(row[column]) for column in ("agent", "env", "delay", "seed", "run_id"))


def read_results(path: Path) -> list[dict[str, str]]:
    """The rows of ``path``, each checked (none when there is no such file).

    A file that does not end with a line break ends with a row whose write was cut short (the
    sweep was stopped while appending it): that row is left out, with a warning, so its run
    runs again. Every other row must be whole and valid (:func:`check_result_row`): a row of
    the wrong length, a value that does not parse (``abc`` for a number, ``nan``, a seed
    out of range, a cut ``run_id``) is refused with its line number, not resumed from. A run
    given twice (two sweeps on one folder may both run it) is kept once when both rows agree on
    everything but ``wall_s``, and refused, naming both lines, when they do not.

    Raises:
        ValueError: the file's columns are not a sweep's (:data:`RESULT_COLUMNS` and the
            extras), or a row is not valid; the message names the file, the line and the
            column.
    """
    if not path.exists():
        return []
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        line = path.read_bytes()[: error.start].count(b"\n") + 1
        raise ValueError(f"{path}, line {line}: not UTF-8 text ({error.reason})") from None
    cut = ""
    if text and not text.endswith("\n"):
        text, cut = text[: text.rfind("\n") + 1], text[text.rfind("\n") + 1 :]
    reader = csv.DictReader(io.StringIO(text, newline=""), restkey=_REST)
    try:
        fieldnames = reader.fieldnames
        if fieldnames is None:
            return []
        if tuple(fieldnames) != _COLUMNS:
            raise ValueError(
                f"{path}, line 1: the columns are {fieldnames}, not a sweep's "
                f"{list(_COLUMNS)}: give the sweep another output folder"
            )
        rows = []
        first: dict[tuple[str, ...], tuple[int, dict[str, str]]] = {}
        for row in reader:
            try:
                row = check_result_row(row)
            except ValueError as error:
                raise ValueError(
                    f"{path}, line {reader.line_num}: {error}; correct or delete the line (its "
                    "run then runs again)"
                ) from None
            line, seen = first.setdefault(run_key(row), (reader.line_num, row))
            if seen is not row:  # the same run twice: kept once if the results agree
                if _results(seen) != _results(row):
                    raise ValueError(
                        f"{path}, line {reader.line_num}: the run of line {line} again, with "
                        "other results; delete the line that is wrong (or both: the run then "
                        "runs again)"
                    )
                continue
            rows.append(row)
    except csv.Error as error:
        raise ValueError(f"{path}, line {reader.line_num}: not a CSV row: {error}") from None
    if cut.strip():
        lines = text.count("\n") + 1
        warnings.warn(
            f"{path}, line {lines}: a row cut short (the file ends inside it), left out: its "
            "run runs again",
            stacklevel=2,
        )
    return rows


_REST = "\0rest"  # the key csv.DictReader gives the values beyond the header's columns
_RUN_ID = re.compile(r"[0-9a-f]{16}")


def check_result_row(row: Mapping[str, Any]) -> dict[str, str]:
    """Return a row of ``results.csv`` (as ``csv.DictReader`` reads it) after checking it.

    Every column of :data:`RESULT_COLUMNS` and :data:`EXTRA_COLUMNS` holds a value and no more:
    non-empty labels (``agent``, ``env``, ``delay``); ``seed`` an integer in
    ``[0, MAX_SWEEP_SEED_VALUE]``; ``steps`` an integer in ``[1, MAX_TIMESTEPS]``; ``train_reward``,
    ``eval_reward`` and ``wall_s`` decimal numbers of magnitude at most ``MAX_ABS_VALUE``
    (2**200, so that their means and intervals stay finite), ``wall_s >= 0``; ``eval_unit``
    ``episode`` or ``step``; ``run_id`` 16 hexadecimal digits, as :meth:`Sweep.runs` makes it.

    Raises:
        ValueError: the row has more or fewer values than the header, or a value is not
            valid (the message names the column, the value and what is allowed).
    """
    if _REST in row or any(row.get(column) is None for column in _COLUMNS):
        given = sum(row.get(column) is not None for column in _COLUMNS) + len(row.get(_REST, ()))
        raise ValueError(f"the row has {given} values, the header {len(_COLUMNS)}")
    for column in ("agent", "env", "delay"):
        if not row[column]:
            raise ValueError(f"{column} must be a non-empty label, got ''")
    _integer(row, "seed", 0, MAX_SWEEP_SEED_VALUE)
    _integer(row, "steps", 1, MAX_TIMESTEPS)
    for column in ("train_reward", "eval_reward", "wall_s"):
        value = _number(row, column)
        if column == "wall_s" and value < 0:
            raise ValueError(f"wall_s must be a number >= 0 (seconds), got {row[column]!r}")
    if row["eval_unit"] not in ("episode", "step"):
        raise ValueError(f"eval_unit must be 'episode' or 'step', got {row['eval_unit']!r}")
    if not _RUN_ID.fullmatch(row["run_id"]):
        raise ValueError(f"run_id must be 16 hexadecimal digits, got {row['run_id']!r}")
    return {column: row[column] for column in _COLUMNS}


def _integer(row: Mapping[str, str], column: str, low: int, high: int) -> int:
    text = row[column]
    if not re.fullmatch(r"[0-9]{1,20}", text) or not low <= int(text) <= high:
        raise ValueError(f"{column} must be an integer in [{low}, {high}], got {text!r}")
    return int(text)


_NUMBER = re.compile(r"-?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]{1,3})?")


def _number(row: Mapping[str, str], column: str) -> float:
    """A number column: decimal text, of magnitude at most ``MAX_ABS_VALUE`` (2**200)."""
    text = row[column]
    value = float(text) if len(text) <= 40 and _NUMBER.fullmatch(text) else math.nan
    if not abs(value) <= MAX_ABS_VALUE:
        raise ValueError(
            f"{column} must be a decimal number of magnitude at most {MAX_ABS_VALUE.text}, "
            f"got {text[:40]!r}"
        )
    return value


def _results(row: Mapping[str, str]) -> tuple[str, ...]:
    """What a run's row says of its results (all but its time, which differs run to run)."""
    return tuple(row[column] for column in _COLUMNS if column != "wall_s")


def write_results(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Write ``rows`` to ``path`` whole (through a temporary file, so it is never half written)."""
    partial = path.with_name(path.name + ".partial")
    with open(partial, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(partial, path)


def append_result(path: Path, row: Mapping[str, Any]) -> None:
    """Append one finished run's row to ``path`` (which has its header) and flush it."""
    with open(path, "a", newline="", encoding="utf-8") as handle:
        csv.DictWriter(handle, fieldnames=_COLUMNS).writerow(row)


def _in_sweep_order(
    rows: Sequence[Mapping[str, Any]], tasks: Sequence[Mapping[str, Any]]
) -> tuple[list[Mapping[str, Any]], list[Mapping[str, Any]]]:
    """The rows of ``tasks`` in their order, and the others (older runs) in theirs."""
    by_key: dict[tuple[str, ...], Mapping[str, Any]] = {}
    for row in rows:
        by_key.setdefault(run_key(row), row)
    keys = [run_key(task) for task in tasks]
    wanted = set(keys)
    ours = [by_key[key] for key in keys if key in by_key]
    others = [row for key, row in by_key.items() if key not in wanted]
    return ours, others


# ---------------------------------------------------------------------------------- summary
def summarize(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per (agent, env, delay), in the rows' order: the seeds and both rewards' mean and 95 % CI.

    One seed gives no interval: its half-widths are NaN (not 0, which would claim no spread).
    """
    groups: dict[tuple[str, str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["agent"], row["env"], row["delay"]), []).append(row)
    summary = []
    for (agent, env, delay), runs in groups.items():
        train_mean, train_ci = mean_ci95([float(run["train_reward"]) for run in runs])
        eval_mean, eval_ci = mean_ci95([float(run["eval_reward"]) for run in runs])
        summary.append(
            {
                "agent": agent,
                "env": env,
                "delay": delay,
                "seeds": len(runs),
                "train_reward_mean": train_mean,
                "train_reward_ci95": train_ci,
                "eval_reward_mean": eval_mean,
                "eval_reward_ci95": eval_ci,
                "eval_unit": runs[0]["eval_unit"],
            }
        )
    return summary


def write_summary_csv(path: Path, summary: Sequence[Mapping[str, Any]]) -> None:
    """``summary.csv``: the rows of :func:`summarize`."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=SUMMARY_COLUMNS)
        writer.writeheader()
        writer.writerows(summary)


def figure_name(env_label: str, taken: Sequence[str] = ()) -> str:
    """The file name of an env's figure: ``eval_reward_<slug>.png``, unlike those ``taken``.

    >>> figure_name("delayed_rl/GridWorld-5x5-v0")
    'eval_reward_delayed-rl-gridworld-5x5-v0.png'
    """
    slug = re.sub(r"[^a-z0-9]+", "-", env_label.lower()).strip("-") or "env"
    name, n = f"eval_reward_{slug}.png", 1
    while name in taken:
        n += 1
        name = f"eval_reward_{slug}-{n}.png"
    return name


def _by_env(summary: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for row in summary:
        groups.setdefault(row["env"], []).append(row)
    return groups


def _cell(mean: float, ci: float) -> str:
    """``mean ± ci``, or ``mean (one seed)`` where there is no interval."""
    return f"{mean:.3f} (one seed)" if math.isnan(ci) else f"{mean:.3f} ± {ci:.3f}"


def _markdown(text: str) -> str:
    return str(text).replace("|", "\\|")


def _best(rows: Sequence[Mapping[str, Any]], delay: str, column: str) -> float:
    """The largest ``column`` among the rows of ``delay`` (NaN when none is a number)."""
    values = [row[column] for row in rows if row["delay"] == delay]
    return max((value for value in values if not math.isnan(value)), default=math.nan)


def agent_delay_table(rows: Sequence[Mapping[str, Any]], reward: str) -> list[str]:
    """One env's Markdown table: an agent per row, a delay per column, ``reward`` ± its CI.

    Args:
        rows: the env's rows of :func:`summarize`.
        reward: ``"eval_reward"`` or ``"train_reward"``; each delay's best mean is in bold.
    """
    agents = list(dict.fromkeys(row["agent"] for row in rows))
    delays = list(dict.fromkeys(row["delay"] for row in rows))
    cells = {(row["agent"], row["delay"]): row for row in rows}
    best = {delay: _best(rows, delay, f"{reward}_mean") for delay in delays}
    lines = [
        "| agent | " + " | ".join(_markdown(delay) for delay in delays) + " |",
        "|---" * (len(delays) + 1) + "|",
    ]
    for agent in agents:
        texts = []
        for delay in delays:
            row = cells.get((agent, delay))
            if row is None:
                texts.append("—")
                continue
            text = _cell(row[f"{reward}_mean"], row[f"{reward}_ci95"])
            texts.append(f"**{text}**" if row[f"{reward}_mean"] == best[delay] else text)
        lines.append(f"| {_markdown(agent)} | " + " | ".join(texts) + " |")
    return lines


def render_summary(
    sweep: Sweep, summary: Sequence[Mapping[str, Any]], figures: Mapping[str, str]
) -> str:
    """``summary.md``: per env, the evaluation and training rewards by agent and delay.

    Args:
        sweep: the sweep (its name, source, and size).
        summary: the rows of :func:`summarize`.
        figures: per env label, its figure's file name or a note that it was not drawn.
    """
    seeds = len(sweep.seeds)
    lines = [
        f"# {sweep.name}",
        "",
        f"From `{sweep.source}`: {len(sweep.agents)} agent(s) × {len(sweep.envs)} env(s) × "
        f"{len(sweep.delays)} delay(s) × {seeds} seed(s). Each cell is the mean ± the half-width "
        "of its 95 % confidence interval over the seeds (Student t; one seed gives none); "
        "`results.csv` has every "
        "run, `summary.csv` these numbers.",
    ]
    for env, rows in _by_env(summary).items():
        unit = rows[0]["eval_unit"]
        lines += [
            "",
            f"## {env}",
            "",
            f"Greedy evaluation: undelayed reward per {unit} (the best agent per delay in bold):",
            "",
            *agent_delay_table(rows, "eval_reward"),
            "",
            "Training: mean undelayed reward per step:",
            "",
            *agent_delay_table(rows, "train_reward"),
        ]
        figure = figures.get(env)
        if figure is not None:
            drawn = figure.endswith(".png")
            lines += ["", f"![{env}: evaluation reward by delay]({figure})" if drawn else figure]
    return "\n".join(lines) + "\n"


def plot_env(path: Path, env: str, rows: Sequence[Mapping[str, Any]]) -> None:
    """One env's figure: per agent, the evaluation reward's mean and 95 % CI bar at each delay.

    Args:
        path: where to save the PNG.
        env: the env's label (the title).
        rows: the env's rows of :func:`summarize`.
    """
    from delayed_rl import figures

    plt = figures.pyplot()
    delays = list(dict.fromkeys(row["delay"] for row in rows))
    agents = list(dict.fromkeys(row["agent"] for row in rows))
    width = min(0.8 / len(agents), 0.2)
    fig, ax = plt.subplots(figsize=(max(8.5, 1.8 * len(delays) + 5.5), 4.4))
    for i, agent in enumerate(agents):
        mine = [row for row in rows if row["agent"] == agent]
        x = [delays.index(row["delay"]) + (i - (len(agents) - 1) / 2) * width for row in mine]
        means = [row["eval_reward_mean"] for row in mine]
        cis = [
            0.0 if math.isnan(row["eval_reward_ci95"]) else row["eval_reward_ci95"] for row in mine
        ]
        label = figures.band_label(agent, min(row["seeds"] for row in mine))
        ax.errorbar(x, means, yerr=cis, marker="o", linestyle="none", capsize=4, label=label)
    ax.set_xticks(range(len(delays)), [textwrap.fill(delay, 18) for delay in delays])
    ax.set_xlim(-0.6, len(delays) - 0.4)
    ax.margins(y=0.15)
    figures.outside_legend(ax)
    unit = rows[0]["eval_unit"]
    title = f"{env}: greedy evaluation reward by delay"
    figures.finish(fig, ax, path, title, "delay", f"undelayed reward per {unit}")


def draw_figures(out: Path, summary: Sequence[Mapping[str, Any]]) -> dict[str, str]:
    """Draw :func:`plot_env` for every env into ``out``.

    Returns:
        Per env label, the figure's file name, or a note when matplotlib (the ``plot`` extra)
        is not installed.
    """
    figures: dict[str, str] = {}
    for env, rows in _by_env(summary).items():
        name = figure_name(env, list(figures.values()))
        try:
            plot_env(out / name, env, rows)
        except ImportError:
            name = f"{name} not drawn: install the plot extra, matplotlib"
        figures[env] = name
    return figures

"""An experiment's files (``curves.csv``, ``summary.json``, the figures, ``report.md``) and a reproduction's index."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from delayed_rl._validation import check_real
from delayed_rl.experiments.framework.experiment import VERDICTS, Config, Experiment, Summary
from delayed_rl.experiments.framework.task import Task


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
    (out / "summary.json").write_text(json.dumps(payload, indent=2, default=json_default))
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

    ``delayed-rl bench all`` writes it after the last experiment: one table of every
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


def json_default(value: Any) -> Any:
    """What JSON writes for ``value``: a task's :meth:`~.task.Task.to_json`, an array's list."""
    if isinstance(value, Task):
        return value.to_json()
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

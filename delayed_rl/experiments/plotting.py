"""Figures of the experiments (matplotlib, from the ``plot`` extra, imported when drawing)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def figure(draw: Callable[..., None], *args: Any, **kwargs: Any) -> Callable[[Path], None]:
    """A figure of a :class:`~delayed_rl.experiments.runner.Summary`: ``draw`` once given a path.

    Args:
        draw: one of this module's functions, e.g. :func:`learning_curves`.
        *args: ``draw``'s arguments after the path.
        **kwargs: ``draw``'s keyword arguments.

    Returns:
        ``path -> draw(path, *args, **kwargs)``.
    """
    return lambda path: draw(path, *args, **kwargs)


def _pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (figures go to files only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(fig: Any, ax: Any, path: Path, title: str, xlabel: str, ylabel: str) -> None:
    """Label and grid ``ax``, then save ``fig`` to ``path`` and close it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)


def learning_curves(path: Path, groups: dict, title: str, ylabel: str) -> None:
    """Mean curve with a 95 % band per group; ``groups[label] = [(steps, values), ...]``."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for label, runs in groups.items():
        steps = runs[0][0]
        values = np.vstack([v for _, v in runs])
        with warnings.catch_warnings():  # a normalised curve is NaN before any reference reward
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(values, axis=0)
            std = np.nanstd(values, axis=0, ddof=1) if len(runs) > 1 else None
        if len(runs) > 1:
            half = 1.96 * std / np.sqrt(len(runs))
            ax.fill_between(steps, mean - half, mean + half, alpha=0.25)
        ax.plot(steps, mean, label=label)
    ax.legend(fontsize=8)
    _finish(fig, ax, path, title, "time step", ylabel)


def errorbar_curve(path: Path, x, mean, ci, title: str, xlabel: str, ylabel: str) -> None:
    """A line of means with 95 % error bars (Fig. 5.6's estimate-error curve)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.errorbar(x, mean, yerr=ci, marker="o", capsize=3)
    _finish(fig, ax, path, title, xlabel, ylabel)


def grid_heatmap(path: Path, grids: dict, title: str, arrows: dict | None = None) -> None:
    """One heatmap per entry of ``grids`` (size × size arrays), with optional policy arrows."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(grids), figsize=(4.2 * len(grids), 4))
    axes = np.atleast_1d(axes)
    marks = {0: (0, -0.35), 1: (0.35, 0), 2: (0, 0.35), 3: (-0.35, 0)}  # up, right, down, left
    for ax, (label, grid) in zip(axes, grids.items(), strict=True):
        ax.imshow(grid, cmap="viridis")
        ax.set_title(label, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        if arrows and label in arrows:
            for (r, c), action in np.ndenumerate(arrows[label]):
                dx, dy = marks[int(action)]
                ax.arrow(c - dx / 2, r - dy / 2, dx, dy, head_width=0.15, color="white")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

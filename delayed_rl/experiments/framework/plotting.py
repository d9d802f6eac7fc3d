"""Figures of the experiments (matplotlib, from the ``plot`` extra, imported when drawing).

Conventions every figure follows:

- a confidence band or error bar is named in the legend, ``"95 % CI over n seeds"``;
- a value the thesis gives is drawn dashed (a line) or as a black-edged marker, its legend
  label starting with ``"thesis"``; a thesis statement without a number goes in the title;
- a heatmap has a colourbar saying what its colour is; panels that show one quantity share
  one colour scale and one colourbar;
- legends sit outside the axes, so they never cover data.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from delayed_rl.figures import BAND, band_label, finish, outside_legend, pyplot

#: How a thesis value is drawn: ``(value, label)``, or ``(value, label, group)`` to take the
#: colour of that group's curve (e.g. ``(0.55, "thesis MMQ ≈ 0.55", "MMQ")``).
ThesisLine = tuple


def figure(draw: Callable[..., None], *args: Any, **kwargs: Any) -> Callable[[Path], None]:
    """A figure of a :class:`~delayed_rl.experiments.framework.experiment.Summary`: ``draw`` once given a path.

    Args:
        draw: one of this module's functions, e.g. :func:`learning_curves`.
        *args: ``draw``'s arguments after the path.
        **kwargs: ``draw``'s keyword arguments.

    Returns:
        ``path -> draw(path, *args, **kwargs)``.
    """
    return lambda path: draw(path, *args, **kwargs)


def robust_ylim(
    curves: Sequence[tuple[np.ndarray, np.ndarray]],
    include: Sequence[float] = (),
    skip: float = 0.05,
    reach: float = 0.5,
    margin: float = 0.06,
) -> tuple[float, float] | None:
    """y-limits that an early transient far off the curves' later range does not stretch.

    The rule: the *settled range* is the extent of every curve's finite values after the first
    ``skip`` of the step axis (the span from the smallest to the largest step over all
    curves). Earlier values stay in view while they lie within ``reach`` of that range's
    width beyond it (a learning curve rising from its start); further out they run off the
    axes (a normalised reward divided by a reference that has barely earned anything yet), so
    they do not squash every other curve flat. The limits then take in ``include`` (e.g. the
    thesis's values) and ``margin`` of the range each side.

    Args:
        curves: ``(steps, values)`` pairs, e.g. the mean curves and their band edges.
        include: values that must be inside the limits.
        skip: the leading fraction of the step axis that does not set the settled range, in
            [0, 1).
        reach: how far beyond the settled range an early value may lie and stay in view, as a
            fraction of that range's width.
        margin: the padding, as a fraction of the range, on each side.

    Returns:
        ``(low, high)``, or ``None`` when there is no finite value (matplotlib's limits).

    >>> steps = np.arange(1, 101)
    >>> spike = np.where(steps <= 3, -100.0, np.linspace(0.0, 0.5, 100))
    >>> low, high = robust_ylim([(steps, spike)], include=[0.6])
    >>> -0.3 < low < 0.0 < 0.6 < high < 0.7
    True
    """
    finite = [
        (np.asarray(x, float), np.asarray(y, float))
        for x, y in curves
        if np.isfinite(np.asarray(y, float)).any()
    ]
    extra = [float(v) for v in include if np.isfinite(v)]
    if not finite:
        return None
    start = min(float(x.min()) for x, _ in finite)
    stop = max(float(x.max()) for x, _ in finite)
    cut = start + skip * (stop - start)
    late = np.concatenate([y[(x >= cut) & np.isfinite(y)] for x, y in finite])
    every = np.concatenate([y[np.isfinite(y)] for _, y in finite])
    low, high = float(every.min()), float(every.max())
    if late.size:
        settled_low, settled_high = float(late.min()), float(late.max())
        width = max(settled_high - settled_low, 1e-9 * max(1.0, abs(settled_high)))
        low = max(low, settled_low - reach * width)
        high = min(high, settled_high + reach * width)
    low, high = min([low, *extra]), max([high, *extra])
    pad = margin * (high - low) if high > low else max(0.05, 0.05 * abs(high))
    return low - pad, high + pad


def _thesis_lines(ax: Any, thesis: Sequence[ThesisLine], colours: dict[str, str]) -> None:
    """Horizontal dashed lines of the thesis's values, in the colour of their group if given."""
    for line in thesis:
        value, label, *group = line
        colour = colours.get(group[0], "black") if group else "black"
        ax.axhline(value, color=colour, linestyle="--", linewidth=1.3, label=label)


def learning_curves(
    path: Path,
    groups: dict,
    title: str,
    ylabel: str,
    thesis: Sequence[ThesisLine] = (),
    ylim: tuple[float, float] | str | None = "robust",
    xlabel: str = "time step",
    thesis_ratios: Sequence[tuple[str, float, str, str]] = (),
    settle: float = 0.05,
    levels: Sequence[tuple[float, str]] = (),
    colours: Mapping[str, str] | None = None,
) -> None:
    """Mean curve with a 95 % band per group, the thesis's values dashed.

    Args:
        path: where to save the PNG.
        groups: ``{label: [(steps, values), ...]}``, one pair per seed.
        title: the title (a thesis statement without a number belongs here).
        ylabel: the y-axis label.
        thesis: the thesis's values, each ``(value, label)`` or ``(value, label, group)``.
        ylim: ``"robust"``: :func:`robust_ylim` of the means, bands and thesis values (an
            early spike runs off the axes); a pair: those limits; ``None``: matplotlib's.
        xlabel: the x-axis label.
        thesis_ratios: thesis values given as ratios, each ``(base, factor, label, group)``: a
            dashed curve ``factor`` × ``base``'s mean curve, in ``group``'s colour (e.g. MMQ's
            accumulated error as 0.4 × Q's).
        settle: with ``ylim="robust"``, the leading fraction of the steps that does not set
            the curves' settled range (:func:`robust_ylim`'s ``skip``).
        levels: other levels, each ``(value, label)`` (a fixed controller's score), drawn as
            dotted lines in colours of their own.
        colours: the colour of a group or a level, by its label, so that one method has one
            colour in every figure of an experiment (``None``, or a label not in it: the next
            of matplotlib's colours; a level's, the next of purple, brown and grey that no group
            has).
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 4.4))
    means = {}
    from matplotlib.colors import to_hex

    fixed = dict(colours or {})
    colours, drawn = {}, []
    for label, runs in groups.items():
        steps = runs[0][0]
        values = np.vstack([v for _, v in runs]).astype(float)
        with warnings.catch_warnings():  # a normalised curve is NaN before any reference reward
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(values, axis=0)
            std = np.nanstd(values, axis=0, ddof=1) if len(runs) > 1 else None
        (line,) = ax.plot(steps, mean, label=band_label(label, len(runs)), color=fixed.get(label))
        colours[label] = line.get_color()
        means[label] = (steps, mean)
        drawn.append((steps, mean))
        if std is not None:
            half = 1.96 * std / np.sqrt(len(runs))
            ax.fill_between(steps, mean - half, mean + half, alpha=0.18, color=line.get_color())
            drawn += [(steps, mean - half), (steps, mean + half)]
    _thesis_lines(ax, thesis, colours)
    used = {to_hex(colour) for colour in colours.values()}
    spare = iter(c for c in ("tab:purple", "tab:brown", "tab:gray") if to_hex(c) not in used)
    for value, label in levels:
        colour = fixed.get(label) or next(spare, "black")
        ax.axhline(value, color=colour, linestyle=":", linewidth=1.6, label=label)
    for base, factor, label, group in thesis_ratios:
        steps, mean = means[base]
        colour = colours.get(group, "black")
        ax.plot(steps, factor * mean, color=colour, linestyle="--", linewidth=1.3, label=label)
        drawn.append((steps, factor * mean))
    if ylim == "robust":
        include = [line[0] for line in thesis] + [value for value, _ in levels]
        ylim = robust_ylim(drawn, include=include, skip=settle)
    _finish_curves(fig, ax, ylim, path, title, xlabel, ylabel)


def _finish_curves(
    fig: Any, ax: Any, ylim: Any, path: Path, title: str, xlabel: str, ylabel: str
) -> None:
    """Set the y-limits (``None``: matplotlib's), put the legend outside and save the figure."""
    if ylim is not None:
        ax.set_ylim(*ylim)
    outside_legend(ax)
    finish(fig, ax, path, title, xlabel, ylabel)


def band_plot(
    path: Path,
    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]],
    title: str,
    xlabel: str,
    ylabel: str,
    ylim: tuple[float, float] | None = None,
    reference: tuple[float, str] | None = None,
) -> None:
    """Mean curve with a 95 % band per group; optional y-limits and a dashed reference line.

    Args:
        path: where to save the PNG.
        groups: ``{label: [(x, y), ...]}``, one pair per seed, the same ``x`` within a label.
        title: the title.
        xlabel: the x-axis label.
        ylabel: the y-axis label.
        ylim: the y-axis limits (``None``: the curves after their first 5 % and the reference
            line when there is one, else matplotlib's).
        reference: ``(y, label)`` of a horizontal dashed line, e.g. the optimum.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 4.5))
    for label, runs in groups.items():
        x = runs[0][0]
        values = np.vstack([y for _, y in runs]).astype(float)
        mean = values.mean(axis=0)
        (line,) = ax.plot(x, mean, label=band_label(label, len(runs)))
        if len(runs) > 1:
            half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(runs))
            ax.fill_between(x, mean - half, mean + half, alpha=0.18, color=line.get_color())
    if reference is not None:
        ax.axhline(reference[0], color="black", linestyle="--", linewidth=1, label=reference[1])
    if ylim is None and reference is not None:  # the optimum in view, the first 5 % cut off
        settled = [y[x >= 0.05 * x[-1]] for runs in groups.values() for x, y in runs]
        low = min(float(np.min(y)) for y in settled if y.size)
        high = max(reference[0], max(float(np.max(y)) for y in settled if y.size))
        ylim = (low - 0.05 * (high - low), high + 0.08 * (high - low))
    _finish_curves(fig, ax, ylim, path, title, xlabel, ylabel)


def estimate_plot(
    path: Path,
    estimates: dict[str, list[tuple[np.ndarray, np.ndarray]]],
    true_pmf: np.ndarray,
    title: str,
) -> None:
    """Delay estimates (mean over seeds with a 95 % band) over the true pmf's bars.

    Estimates over a coarser grid than every integer (MMQ with ``delay_step`` > 1) are drawn per
    unit of delay (divided by their spacing), so every curve is on the pmf's scale. The x axis
    spans the true pmf's support.

    Args:
        path: where to save the PNG.
        estimates: ``{label: [(support, distribution), ...]}``, one pair per seed.
        true_pmf: the true delay pmf on ``0, 1, ..., len − 1``.
        title: the title.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9.5, 4.5))
    ax.bar(np.arange(true_pmf.size), true_pmf, color="0.8", width=1.0, label="true pmf")
    top = float(true_pmf.max())
    for label, runs in estimates.items():
        support = np.asarray(runs[0][0], dtype=float)
        spacing = float(np.diff(support).min()) if support.size > 1 else 1.0
        values = np.vstack([y for _, y in runs]) / spacing
        mean = values.mean(axis=0)
        (line,) = ax.plot(
            support, mean, marker=".", markersize=3, label=band_label(label, len(runs))
        )
        if len(runs) > 1:
            half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(runs))
            lower = np.maximum(mean - half, 0)
            ax.fill_between(support, lower, mean + half, alpha=0.25, color=line.get_color())
            top = max(top, float((mean + half).max()))
        top = max(top, float(mean.max()))
    ax.set_xlim(-1, true_pmf.size)
    ax.set_ylim(0, 1.1 * top)
    outside_legend(ax)
    finish(fig, ax, path, title, "delay (steps)", "probability (pmf) or share of steps")


def errorbar_curve(
    path: Path,
    x,
    mean,
    ci,
    title: str,
    xlabel: str,
    ylabel: str,
    n: int | None = None,
    thesis: Sequence[tuple] = (),
    label: str = "measured",
    xticklabels: Sequence[str] | None = None,
) -> None:
    """A line of means with 95 % error bars (e.g. Fig. 5.6's estimate-error curve).

    Args:
        path: where to save the PNG.
        x: the x values.
        mean: the mean at each x.
        ci: the half-width of each mean's 95 % CI (or another spread, named by ``label``).
        title: the title.
        xlabel: the x-axis label.
        ylabel: the y-axis label.
        n: the seeds behind each mean, named in the legend (``None``: ``label`` alone).
        thesis: the thesis's values: ``(x, y, label)`` a marker, ``(None, y, label)`` a line
            (dashed when ``label`` starts with "thesis", dotted for other references).
        label: the legend label of the measured curve.
        xticklabels: labels of the ticks at ``x`` (``None``: matplotlib's numbers).
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.4))
    text = f"{label}: mean, {BAND.format(n=n)}" if n else label
    ax.errorbar(x, mean, yerr=ci, marker="o", capsize=3, label=text)
    for at, value, name in thesis:
        if at is None:
            style = "--" if name.startswith("thesis") else ":"
            colour = "C3" if name.startswith("thesis") else "0.3"
            ax.axhline(value, color=colour, linestyle=style, linewidth=1.4, label=name)
        else:
            ax.plot(
                [at],
                [value],
                marker="*",
                markersize=16,
                color="C3",
                markeredgecolor="black",
                linestyle="none",
                label=name,
                zorder=5,
            )
    ax.margins(y=0.1)
    if xticklabels is not None:
        ax.set_xticks(list(x), list(xticklabels))
    outside_legend(ax)
    finish(fig, ax, path, title, xlabel, ylabel)


def value_bars(
    path: Path,
    stats: dict[str, tuple[float, float, int]],
    title: str,
    ylabel: str,
    thesis: dict[str, tuple[float, str]] | None = None,
) -> None:
    """One bar per group (its mean, 95 % error bar), the thesis's value as a dashed tick.

    Args:
        path: where to save the PNG.
        stats: ``{label: (mean, ci, n)}``.
        title: the title.
        ylabel: the y-axis label.
        thesis: ``{label: (value, legend label)}`` for the groups the thesis gives a value.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.5, 4.4))
    names = list(stats)
    positions = np.arange(len(names))
    means = [stats[name][0] for name in names]
    cis = [stats[name][1] for name in names]
    ns = sorted({stats[name][2] for name in names})
    seeds = ns[0] if len(ns) == 1 else "/".join(map(str, ns))
    ax.bar(
        positions,
        means,
        yerr=cis,
        capsize=5,
        color="C0",
        alpha=0.75,
        label=f"measured: mean, {BAND.format(n=seeds)}",
    )
    for name, (value, label) in (thesis or {}).items():
        i = names.index(name)
        ax.hlines(value, i - 0.42, i + 0.42, colors="C3", linestyles="--", linewidth=2, label=label)
    ax.set_xticks(positions, names)
    ax.axhline(0, color="0.4", linewidth=0.8)
    marks = [0.0, *[v for v, _ in (thesis or {}).values()]]
    low = min([*marks, *(m - c for m, c in zip(means, cis, strict=True))])
    high = max([*marks, *(m + c for m, c in zip(means, cis, strict=True))])
    pad = 0.08 * (high - low) if high > low else 0.1
    ax.set_ylim(low - pad, high + pad)  # a thesis value at 0 stays visible above the axis
    outside_legend(ax)
    finish(fig, ax, path, title, "", ylabel)


def _colourbar(fig: Any, image: Any, axes: Any, label: str) -> Any:
    """One colourbar for ``axes`` (all on ``image``'s scale), labelled ``label``."""
    bar = fig.colorbar(image, ax=list(np.atleast_1d(axes)), shrink=0.85, pad=0.02)
    bar.set_label(label)
    return bar


def grid_heatmap(
    path: Path,
    grids: dict,
    title: str,
    colorbar_label: str,
    arrows: dict | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
    columns: int | None = None,
) -> None:
    """One heatmap per entry of ``grids`` (size × size arrays), on one shared colour scale.

    Args:
        path: where to save the PNG.
        grids: ``{panel title: array}``.
        title: the figure's title.
        colorbar_label: what the colour is (the one colourbar's label).
        arrows: ``{panel title: array of actions}`` (0 up, 1 right, 2 down, 3 left) drawn as
            arrows over that panel.
        vmin: the bottom of the colour scale (``None``: the smallest value of every panel).
        vmax: the top of the colour scale (``None``: the largest value of every panel).
        columns: panels per row (``None``: all in one row).
    """
    plt = pyplot()
    columns = columns or len(grids)
    rows = -(-len(grids) // columns)
    fig, axes = plt.subplots(
        rows,
        columns,
        figsize=(3.9 * columns + 1.2, 3.9 * rows + 0.5),
        layout="constrained",
        squeeze=False,
    )
    for ax in axes.flat[len(grids) :]:
        ax.set_visible(False)
    axes = axes.flat[: len(grids)]
    values = np.concatenate([np.ravel(np.asarray(g, float)) for g in grids.values()])
    low = float(np.nanmin(values)) if vmin is None else vmin
    high = float(np.nanmax(values)) if vmax is None else vmax
    marks = {0: (0, -0.6), 1: (0.6, 0), 2: (0, 0.6), 3: (-0.6, 0)}  # up, right, down, left
    image = None
    for ax, (label, grid) in zip(axes, grids.items(), strict=True):
        image = ax.imshow(grid, cmap="viridis", vmin=low, vmax=high)
        ax.set_title(label, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
        if arrows and label in arrows:
            for (r, c), action in np.ndenumerate(arrows[label]):
                dx, dy = marks[int(action)]
                ax.arrow(
                    c - dx / 2,
                    r - dy / 2,
                    dx,
                    dy,
                    width=0.05,
                    head_width=0.28,
                    head_length=0.22,
                    length_includes_head=True,
                    facecolor="white",
                    edgecolor="black",
                    linewidth=0.4,
                )
    _colourbar(fig, image, axes, colorbar_label)
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def value_tables(
    path: Path,
    tables: dict,
    title: str,
    colorbar_label: str,
    row_labels: Sequence[str],
    column_labels: Sequence[str],
    thesis: dict | None = None,
    decimals: int = 2,
) -> None:
    """Tables drawn as coloured cells with their numbers, on one shared colour scale.

    Args:
        path: where to save the PNG.
        tables: ``{panel title: 2-D array}``, all of one shape.
        title: the figure's title.
        colorbar_label: what the colour is (the one colourbar's label).
        row_labels: the rows' tick labels.
        column_labels: the columns' tick labels.
        thesis: ``{panel title: 2-D array}`` of the thesis's values, printed small under each
            measured value as ``"thesis 49.50"``.
        decimals: the decimals printed.
    """
    plt = pyplot()
    n = len(tables)
    fig, axes = plt.subplots(1, n, figsize=(3.3 * n + 1.3, 4.3), layout="constrained")
    axes = np.atleast_1d(axes)
    values = np.concatenate([np.ravel(np.asarray(t, float)) for t in tables.values()])
    low, high = float(values.min()), float(values.max())
    if high == low:
        low, high = low - 1, high + 1
    image = None
    for ax, (label, table) in zip(axes, tables.items(), strict=True):
        table = np.asarray(table, float)
        image = ax.imshow(table, cmap="viridis", vmin=low, vmax=high, aspect="auto")
        ax.set_title(label, fontsize=10)
        ax.set_xticks(range(table.shape[1]), column_labels)
        ax.set_yticks(range(table.shape[0]), row_labels)
        for (r, c), value in np.ndenumerate(table):
            dark = (value - low) / (high - low) < 0.6  # viridis: light text on its dark half
            colour = "white" if dark else "black"
            ax.text(
                c,
                r - 0.08,
                f"{value:.{decimals}f}",
                ha="center",
                va="center",
                fontsize=12,
                fontweight="bold",
                color=colour,
            )
            if thesis and label in thesis:
                ax.text(
                    c,
                    r + 0.25,
                    f"thesis {thesis[label][r][c]:.{decimals}f}",
                    ha="center",
                    va="center",
                    fontsize=8,
                    color=colour,
                )
    _colourbar(fig, image, axes, colorbar_label)
    fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)

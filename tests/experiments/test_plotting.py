"""The experiments' figures: thesis values drawn, colourbars, readable tables, robust limits."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.experiments import get_experiment
from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.experiment import Config


@pytest.fixture
def kept(monkeypatch):
    """The figures the drawing functions close, kept open and returned in order."""
    pytest.importorskip("matplotlib")  # (the plot extra; imported here, not at collection)
    import matplotlib.pyplot as plt

    figures = []
    monkeypatch.setattr(plt, "close", figures.append)
    yield figures
    for fig in figures:
        fig.clf()


def _summary(name: str, **config):
    """The summary of a small run of experiment ``name`` (tasks in this process)."""
    experiment = get_experiment(name)
    config = Config(quick=True, **config)
    config.seeds = config.seeds or experiment.quick_seeds
    tasks = experiment.tasks(config)
    return experiment.summarize(tasks, [experiment.run_alone(t) for t in tasks], config)


def _draw(summary, name, tmp_path, kept):
    """Draw figure ``name`` of ``summary``; return the matplotlib figure."""
    summary.figures[name](tmp_path / f"{name}.png")
    assert (tmp_path / f"{name}.png").stat().st_size > 0
    return kept[-1]


def _labels(fig) -> list[str]:
    """Every legend label of ``fig``'s axes."""
    return [label for ax in fig.axes for label in ax.get_legend_handles_labels()[1]]


def _colourbars(fig) -> list:
    """The colourbar axes of ``fig``."""
    return [ax for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]


def test_robust_ylim_ignores_an_injected_early_spike():
    steps = np.linspace(100, 25_000, 200)
    settled = 0.5 + 0.1 * np.sin(steps / 2000)
    spiky = -0.8 + 0.05 * np.cos(steps / 3000)
    spiky[:4] = [-90.0, -130.0, -50.0, -20.0]  # a reference that had barely earned anything
    low, high = plotting.robust_ylim([(steps, settled), (steps, spiky)], include=[0.0])
    assert -10 < low < -0.85 and 0.6 < high < 1.5  # the spike reaches −130
    # without the spike every value is in view, and a thesis value outside the data too
    low, high = plotting.robust_ylim([(steps, settled)], include=[1.5])
    assert low < settled.min() and high > 1.5


def test_learning_curves_limits_leave_the_spike_out_and_the_thesis_in(tmp_path, kept):
    steps = np.arange(1, 201)
    curve = np.full(200, 0.4)
    curve[:3] = -500.0
    groups = {"9×9": [(steps, curve), (steps, curve + 0.01)]}
    thesis = [(0.0, "thesis 9×9 ≈ 0 %", "9×9")]
    plotting.learning_curves(tmp_path / "c.png", groups, "title", "y", thesis)
    ax = kept[-1].axes[0]
    low, high = ax.get_ylim()
    assert -5 < low < 0.0 < 0.41 < high
    assert "9×9: mean, 95 % CI over 2 seeds" in _labels(kept[-1])


def test_a_method_keeps_its_colour_in_every_figure_and_a_level_takes_a_colour_no_curve_has(
    tmp_path, kept
):
    from matplotlib.colors import to_hex

    from delayed_rl.experiments.framework.gain_settings import method_colours

    steps = np.arange(1, 11)
    labels = {"a": "first", "b": "second", "c": "third", "d": "fourth", "e": "fifth"}
    colours = method_colours(labels)
    run = [(steps, np.ones(10)), (steps, np.zeros(10))]
    seen = {}
    for drawn in (("first", "third", "fifth"), ("third", "fifth"), ("fifth",)):
        groups = {label: run for label in drawn}
        level = (0.5, "a controller")
        plotting.learning_curves(
            tmp_path / "c.png", groups, "t", "y", levels=[level], colours=colours
        )
        lines = {line.get_label(): to_hex(line.get_color()) for line in kept[-1].axes[0].lines}
        for label in drawn:
            key = f"{label}: mean, 95 % CI over 2 seeds"
            assert seen.setdefault(label, lines[key]) == lines[key] == to_hex(colours[label])
        curve_colours = {lines[f"{label}: mean, 95 % CI over 2 seeds"] for label in drawn}
        assert lines["a controller"] not in curve_colours
    assert len(set(seen.values())) == 3


@pytest.mark.experiment
def test_heatmaps_have_one_labelled_colourbar(tmp_path, kept):
    summary = _summary("mmq-gridworld", seeds=1, steps=3000)
    names = [n for n in summary.figures if n.startswith(("fig5_10", "fig5_11", "fig5_12"))]
    assert len(names) == 5  # visits, greedy policies, three probabilistic policies
    for name in names:
        fig = _draw(summary, name, tmp_path, kept)
        bars = _colourbars(fig)
        assert len(bars) == 1, name
        assert bars[0].get_ylabel(), name
    probabilistic = _colourbars(_draw(summary, names[-1], tmp_path, kept))[0]
    assert probabilistic.get_ylim() == (0.0, 1.0)


def test_roulette_cells_print_the_tables_on_one_scale(tmp_path, kept):
    from delayed_rl.experiments.thesis.roulette import THESIS_TABLES

    summary = _summary("roulette")
    fig = _draw(summary, "tables_3_3_to_3_5", tmp_path, kept)
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == 3 and len(_colourbars(fig)) == 1
    assert len({ax.images[0].get_clim() for ax in panels}) == 1  # one shared colour scale
    for ax, table, thesis in zip(panels, summary.extra["tables"], THESIS_TABLES, strict=True):
        texts = [t.get_text() for t in ax.texts]
        measured = [float(t) for t in texts if not t.startswith("thesis")]
        printed = [float(t.split()[1]) for t in texts if t.startswith("thesis")]
        assert measured == [round(float(v), 2) for v in np.ravel(table)]
        assert printed == list(np.ravel(thesis))


@pytest.mark.parametrize(
    ("name", "config", "figure", "expected"),
    [
        ("estimate-error", {}, "fig5_6_estimate_error", ["thesis: peak ≈ 0.6"]),
        ("world-size", {}, "fig5_3to5_world_size_lambda5", ["thesis 9×9 ≈ 0 %"]),
        (
            "mmq-gridworld",
            {"seeds": 1, "steps": 3000},
            "greedy_average_reward",
            ["thesis MMQ 0.59"],
        ),
        ("mmq-gridworld", {"seeds": 1, "steps": 3000}, "table5_1_route_q", ["thesis ≈ 21.4"]),
        (
            "controllers",
            {"seeds": 1},
            "fig5_19_controllers",
            ["thesis P undelayed ≈ +0.9", "thesis MMQ ≈ +0.6", "thesis Q ≈ +0.3"],
        ),
        ("linefollow", {"seeds": 1}, "fig5_22_average_reward", ["thesis MMQ ≈ 0.55"]),
        ("linefollow", {"seeds": 1}, "fig5_23_accumulated_error", ["thesis MMQ = 0.4 × Q"]),
    ],
)
def test_figures_compared_with_the_thesis_draw_its_values(
    name, config, figure, expected, tmp_path, kept
):
    labels = _labels(_draw(_summary(name, **config), figure, tmp_path, kept))
    for start in expected:
        assert any(label.startswith(start) for label in labels), (start, labels)


def test_thesis_lines_sit_at_the_claims_values(tmp_path, kept):
    from delayed_rl.experiments.thesis.controllers import THESIS

    summary = _summary("controllers", seeds=1)
    ax = _draw(summary, "fig5_19_controllers", tmp_path, kept).axes[0]
    drawn = {
        line.get_label(): line.get_ydata()[0]
        for line in ax.get_lines()
        if line.get_label().startswith("thesis")
    }
    assert sorted(drawn.values()) == sorted(THESIS.values())
    for claim in summary.claims[: len(THESIS)]:  # the band rows: "≈ +0.9 (Fig. 5.19)"
        name = claim.quantity.split(":")[0]
        assert f"thesis {name} {claim.thesis}" in drawn


def test_a_qualitative_thesis_statement_is_in_the_title(tmp_path, kept):
    fig = _draw(_summary("delay-sweep"), "fig5_2_delay_sweep", tmp_path, kept)
    assert "thesis: the normalised reward falls as λ grows" in fig._suptitle.get_text()
    assert all(label.startswith("λ = ") for label in _labels(fig))

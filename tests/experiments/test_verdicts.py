"""Every verdict is computed: the rules of the claim helpers, and each experiment's rows flipping.

For each kind of row (band, direction, count, trend) a synthetic measurement must come out
``agrees``, one ``differs`` and one ``inconclusive``. For each experiment's ``summarize``,
synthetic results shaped like its ``run_task``'s make at least one of its rows flip from
``agrees`` to ``differs``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from support import fake_grid_run, fake_line_run

from delayed_rl.experiments.beyond import anonymous_delay, future_work, linefollow_deconv
from delayed_rl.experiments.framework.claims import (
    band_claim,
    count_claim,
    direction_claim,
    paired,
    per_seed_slopes,
    range_claim,
    reference_row,
    trend_claim,
)
from delayed_rl.experiments.framework.experiment import VERDICTS, Claim, Config, Experiment, Summary
from delayed_rl.experiments.framework.line_following import LineTask
from delayed_rl.experiments.framework.report import write_outputs
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.thesis import (
    controllers,
    delay_sweep,
    estimate_error,
    linefollow,
    mmq_gridworld,
    roulette,
    world_size,
)
from delayed_rl.experiments.thesis.controllers import ControllerTask
from delayed_rl.experiments.thesis.mmq_gridworld import MMQGridTask
from delayed_rl.parallel.intervals import wilson_interval


# ---------------------------------------------------------------------- the rules
@pytest.mark.parametrize(
    ("stats", "verdict"),
    [
        ((0.50, 0.10, 5), "agrees"),  # [0.40, 0.60] inside [0.35, 0.75]
        ((0.112, 0.05, 5), "differs"),  # [0.062, 0.162] wholly below
        ((0.30, 0.10, 5), "inconclusive"),  # [0.20, 0.40] straddles 0.35
        ((math.nan, math.nan, 0), "inconclusive"),
    ],
)
def test_band_rule(stats, verdict):
    claim = band_claim("q", "≈ 0.55", stats, 0.55, 0.2)
    assert claim.verdict == verdict
    assert "0.55 ± 0.2 = [0.35, 0.75]" in claim.criterion and claim.criterion.startswith("differs")


def test_range_rule_allows_open_ends():
    assert range_claim("q", "t", (5.0, 1.0, 3), 0.0, math.inf).verdict == "agrees"
    assert range_claim("q", "t", (-5.0, 1.0, 3), 0.0, math.inf).verdict == "differs"
    assert range_claim("q", "t", (0.5, 1.0, 3), 0.0, 1.0).verdict == "inconclusive"


@pytest.mark.parametrize(
    ("stats", "side", "verdict"),
    [
        ((0.3, 0.1, 5), "above", "agrees"),
        ((-0.3, 0.1, 5), "above", "differs"),
        ((0.05, 0.1, 5), "above", "inconclusive"),
        ((0.0, 0.0, 5), "above", "differs"),  # exactly 0 is not above 0
        ((0.8, 0.1, 5), "below", "agrees"),  # against 1 below
        ((1.2, 0.1, 5), "below", "differs"),
        ((0.95, 0.1, 5), "below", "inconclusive"),
    ],
)
def test_direction_rule(stats, side, verdict):
    reference = 0.0 if stats[0] < 0.5 else 1.0
    claim = direction_claim("q", "t", stats, side, reference)
    assert claim.verdict == verdict and claim.criterion.startswith("differs if the 95 % CI")
    assert (claim.low, claim.high) == pytest.approx((stats[0] - stats[1], stats[0] + stats[1]))


def test_direction_rule_refuses_an_unknown_side():
    with pytest.raises(ValueError, match="side must be 'above' or 'below'"):
        direction_claim("q", "t", (0.0, 0.0, 1), "sideways")


@pytest.mark.parametrize(
    ("k", "n", "verdict"),
    [
        (18, 20, "agrees"),  # Wilson [0.70, 0.97] inside [0.5, 1]
        (2, 20, "differs"),  # [0.03, 0.30] wholly below 0.5
        (11, 20, "inconclusive"),  # [0.34, 0.74]
        (0, 0, "inconclusive"),
    ],
)
def test_count_rule_reads_the_wilson_interval(k, n, verdict):
    claim = count_claim("optimal seeds", "most", k, n, 0.5)
    assert claim.verdict == verdict and claim.n == n
    if n:
        assert claim.mean == k / n and (claim.low, claim.high) == wilson_interval(k, n)
        assert claim.note.startswith(f"{k} of {n} seeds") and "Wilson" in claim.criterion


def _trend(slopes, noise):
    rng = np.random.default_rng(0)
    x = np.log10([1, 2, 5, 10, 20, 50])
    ys = [slope * x + noise * rng.standard_normal(x.size) for slope in slopes]
    return trend_claim("slope", "falls", x, ys, "below", "log10 λ")


def test_trend_rule_fits_a_slope_per_seed():
    assert per_seed_slopes([1, 2, 3], [[2, 4, 6], [3, 2, 1]]) == pytest.approx([2.0, -1.0])
    assert _trend([-0.2] * 10, 0.01).verdict == "agrees"
    assert _trend([0.2] * 10, 0.01).verdict == "differs"
    inconclusive = _trend([-0.3, 0.3, -0.2, 0.25, 0.0], 0.05)
    assert inconclusive.verdict == "inconclusive" and inconclusive.n == 5
    assert inconclusive.criterion.startswith("least-squares slope against log10 λ per seed")


def test_paired_differences_and_ratios_are_per_seed():
    assert paired({0: 3.0, 1: 5.0, 2: 1.0}, {1: 1.0, 0: 1.0}) == [2.0, 4.0]
    assert paired({0: 3.0}, {0: 2.0}, "ratio") == [1.5]
    assert math.isnan(paired({0: 3.0}, {0: 0.0}, "ratio")[0])
    with pytest.raises(ValueError, match="how must be"):
        paired({}, {}, "sum")


def test_reference_rows_and_bad_verdicts():
    row = reference_row("undelayed", (0.3, 0.01, 4))
    assert row.verdict == "reference" and row.criterion.startswith("none")
    assert set(VERDICTS) == {"agrees", "differs", "inconclusive", "reference"}
    with pytest.raises(ValueError, match="verdict must be one of"):
        Claim("q", "t", 0.0, 0.0, 1, "ok")


def test_criterion_lands_in_summary_json_and_report_md(tmp_path):
    experiment = Experiment(
        name="fake",
        thesis="Fig. 0",
        description="a fake",
        tasks=lambda c: [],
        run_task=lambda t: {},
        summarize=lambda tasks, results, config: Summary([], []),
        default_seeds=1,
    )
    claims = [
        band_claim("value", "≈ 1", (1.0, 0.1, 3), 1.0, 0.5),
        count_claim("seeds", "most", 3, 4, 0.5),
    ]
    write_outputs(experiment, Config(seeds=3), Summary(claims, []), tmp_path)
    payload = json.loads((tmp_path / "summary.json").read_text())
    assert [c["criterion"] for c in payload["claims"]] == [c.criterion for c in claims]
    assert payload["claims"][1]["low"] == pytest.approx(wilson_interval(3, 4)[0])
    report = (tmp_path / "report.md").read_text()
    assert "| seeds | verdict | criterion |" in report
    assert claims[0].criterion in report and "0.750 [0.301, 0.954]" in report
    assert "Verdicts: agrees 1, differs 0, inconclusive 1, reference 0." in report


# ---------------------------------------------------------------------- every experiment flips
def _verdicts(summary: Summary) -> dict[str, str]:
    assert all(c.verdict in VERDICTS and c.criterion for c in summary.claims)
    return {c.quantity: c.verdict for c in summary.claims}


def _grid_summary(module, value, seeds: int = 4):
    """``module.summarize`` of fake grid runs: reference average 1, delayed ``value(task)``."""
    tasks = module.tasks(Config(quick=True, seeds=seeds))
    results = []
    for task in tasks:
        average = 1.0 if task.reference else value(task)
        results.append(
            {"steps": np.array([1, 2]), "curve": np.full(2, average), "average": average}
        )
    return _verdicts(module.summarize(tasks, results, Config(seeds=seeds)))


def test_delay_sweep_trend_flips():
    def falling(task):
        return 0.8 - 0.1 * np.log10(task.lam) + 0.01 * task.seed

    def rising(task):
        return 0.5 + 0.1 * np.log10(task.lam) + 0.01 * task.seed

    good, bad = _grid_summary(delay_sweep, falling), _grid_summary(delay_sweep, rising)
    tested = [q for q in good if "slope" in q or "minus" in q]
    assert len(tested) == 2
    assert all(good[q] == "agrees" for q in tested) and all(bad[q] == "differs" for q in tested)
    assert {good[q] for q in good if q not in tested} == {"reference"}  # the per-λ points


def test_world_size_rows_flip():
    def thesis_like(task):
        return {3: 0.6, 5: 0.3, 9: 0.0}[task.size] + 0.001 * task.seed

    def unlike(task):  # the 9×9 world earns as much as the 3×3 one
        return {3: 0.6, 5: 0.3, 9: 0.6}[task.size] + 0.001 * task.seed

    good, bad = _grid_summary(world_size, thesis_like), _grid_summary(world_size, unlike)
    assert set(good.values()) == {"agrees"}
    assert bad["normalised reward 9×9, λ = 5"] == "differs"
    assert bad["9×9 minus 3×3 normalised reward at λ = 50 (paired by seed)"] == "differs"
    assert bad["normalised reward 3×3, λ = 5"] == "agrees"


def test_estimate_error_rows_flip():
    def peak_at(centre):
        return lambda task: 0.6 - 0.03 * abs(task.error - centre) + 0.001 * task.seed

    good, bad = (
        _grid_summary(estimate_error, peak_at(0)),
        _grid_summary(estimate_error, peak_at(15)),
    )
    assert set(good.values()) == {"agrees"}
    assert bad["error i of each seed's best estimate (argmax over i)"] == "differs"
    assert bad["normalised reward at i = +15 minus half the seed's peak"] == "differs"
    nothing = _grid_summary(estimate_error, lambda task: -0.1)  # no positive peak: no half of it
    assert nothing["normalised reward at i = -15 minus half the seed's peak"] == "inconclusive"


def test_roulette_rows_flip():
    tables = np.array(roulette.THESIS_TABLES, dtype=float)
    good = _verdicts(roulette.summarize([Task(seed=0)], [{"tables": tables}], Config(seeds=1)))
    assert set(good.values()) == {"agrees"} and len(good) == 18
    off = tables.copy()
    off[2, 0, 0] += 0.01  # Table 3.5's 49.22 read as 49.23
    bad = _verdicts(roulette.summarize([Task(seed=0)], [{"tables": off}], Config(seeds=1)))
    assert bad["round 3: Q(bet even, λ̂ = 0)"] == "differs"
    assert sum(v == "differs" for v in bad.values()) == 1


def _mmq_result(greedy: float, average: float, late: float, seed: int) -> dict:
    route = [(s, 1, 18.0 + 0.1 * seed, 0.5) for s in range(17)]
    return {
        "steps": np.array([1, 2]),
        "curve": np.full(2, average),
        "average": average,
        "greedy": greedy,
        "optimal": greedy > 0.55,
        "snapshot_steps": np.array([50, 100]),
        "snapshot_optimal": np.array([False, greedy > 0.55]),
        "second_half_optimal": late,
        "route_table": route,
        "model_share": np.full(51, 1 / 51),
        "visits": np.ones((9, 9)),
        "policy": np.zeros((9, 9), dtype=np.int64),
        "behaviour": np.full((4, 9, 9), 0.25),
    }


def _mmq_summary(mmq_greedy: float, mmq_average: float, mmq_late: float, seeds: int = 20):
    tasks, results = [], []
    values = {
        "MMQ": (mmq_greedy, mmq_average, mmq_late),
        "Q": (0.0, 0.0, 0.0),
        "Q undelayed": (0.58, 0.4, 1.0),
    }
    for seed in range(seeds):
        for agent, (greedy, average, late) in values.items():
            tasks.append(MMQGridTask(agent=agent, delay_estimates=(0,), lam=0, steps=1, seed=seed))
            results.append(_mmq_result(greedy, average + 0.001 * seed, late, seed))
    return _verdicts(mmq_gridworld.summarize(tasks, results, Config(seeds=seeds)))


def test_mmq_gridworld_rows_flip():
    good = _mmq_summary(0.58, 0.3, 1.0)
    tested = {q: v for q, v in good.items() if v != "reference"}
    assert set(tested.values()) == {"agrees"} and len(tested) == 10
    assert good["MMQ seeds whose final greedy policy is optimal"] == "agrees"  # 20 of 20 > ½
    bad = _mmq_summary(0.0, -0.1, 0.0)
    for quantity in (
        "MMQ greedy average reward (1000 steps)",
        "MMQ seeds whose final greedy policy is optimal",
        "MMQ share of second-half greedy snapshots optimal",
        "MMQ minus Q average reward during learning (paired by seed)",
    ):
        assert bad[quantity] == "differs"
    assert {q for q, v in good.items() if v == "reference"} == {
        "MMQ average reward during learning",
        "undelayed Q average reward during learning",
        "undelayed Q greedy average reward (1000 steps)",
        "undelayed Q share of second-half greedy snapshots optimal",
    }


def _controllers_summary(values: dict[str, float], seeds: int = 4):
    tasks, results = [], []
    for seed in range(seeds):
        for name, value in values.items():
            tasks.append(ControllerTask(controller=name, train_steps=1, run_steps=10, seed=seed))
            average = value + 0.005 * seed
            results.append(
                {
                    "steps": np.array([5, 10]),
                    "curve": np.full(2, average),
                    "average": average,
                    "total_error": 100.0,
                    "visible": 1.0,
                }
            )
    return _verdicts(controllers.summarize(tasks, results, Config(seeds=seeds)))


def test_controllers_rows_flip():
    good = _controllers_summary(dict(controllers.THESIS))
    assert set(good.values()) == {"agrees"} and len(good) == 7
    bad = _controllers_summary({**controllers.THESIS, "MMQ": -0.6})
    assert bad["MMQ: average reward after 10 steps"] == "differs"
    assert bad["MMQ minus Q average reward (paired by seed)"] == "differs"
    assert bad["P undelayed: average reward after 10 steps"] == "agrees"


def _linefollow_summary(mmq: float, q: float, seeds: int = 5):
    tasks, results = [], []
    for seed in range(seeds):
        for agent, average in (("MMQ", mmq + 0.002 * seed), ("Q", q)):
            tasks.append(LineTask(agent=agent, steps=10, seed=seed))
            results.append(
                {
                    "steps": np.array([5, 10]),
                    "curve": np.full(2, average),
                    "error": np.array([100.0, 400.0 if agent == "MMQ" else 1000.0]),
                    "average": average,
                    "total_error": 400.0 if agent == "MMQ" else 1000.0,
                    "visible": 1.0,
                }
            )
    return _verdicts(linefollow.summarize(tasks, results, Config(seeds=seeds)))


def test_linefollow_gap_is_tested_against_plus_0_43_not_only_its_sign():
    good = _linefollow_summary(0.55, 0.12)
    assert set(good.values()) == {"agrees"}
    small = _linefollow_summary(0.232, 0.12)  # MMQ − Q ≈ 0.112: above 0, far from +0.43
    assert small["MMQ minus Q average reward (paired by seed)"] == "differs"
    assert small["MMQ above Q: MMQ minus Q average reward (paired by seed)"] == "agrees"


def _anonymous_summary(deconv_optimal: int, deconv_delay: float, seeds: int = 20):
    tasks, results = [], []
    for seed in range(seeds):
        jitter = 0.001 * seed
        runs = {
            "Q": (False, 0.1 + jitter, 0.0, 0.0),
            "MMQ": (seed < 18, 0.6 + jitter, 8.0 + jitter, 1.0),
            "DeconvQ learned": (seed < deconv_optimal, 0.7 + jitter, deconv_delay + jitter, 1.0),
            "oracle": (True, 0.71 + jitter, 0.0, 1.0),
        }
        for agent, values in runs.items():
            task, result = fake_grid_run(agent, seed, *values)
            tasks.append(task)
            results.append(result)
    summary = anonymous_delay.summarize(tasks, results, Config(seeds=seeds))
    return {q.split(": ", 1)[1]: v for q, v in _verdicts(summary).items()}


def test_anonymous_delay_rows_flip():
    good = _anonymous_summary(20, 8.0)
    # 20 of 20 cannot show a share ≥ 0.95: the count rows are at best inconclusive
    assert good["DeconvQ learned seeds whose greedy policy is optimal"] == "inconclusive"
    assert good["MMQ seeds whose greedy policy is optimal"] == "inconclusive"
    assert good["DeconvQ learned mean delay"] == "agrees"
    assert good["MMQ minus delayed Q training reward"] == "agrees"
    bad = _anonymous_summary(10, 14.0)
    assert bad["DeconvQ learned seeds whose greedy policy is optimal"] == "differs"
    assert bad["DeconvQ learned mean delay"] == "differs"


def test_future_work_rows_flip():
    tasks, results = [], []
    for seed in range(6):
        for variant in future_work.VARIANTS:
            worse = variant == "MMQ trace β=0.9"
            values = (not worse, (0.3 if worse else 0.6) + 0.001 * seed, 8.0, 0.0 if worse else 1.0)
            task, result = fake_grid_run(variant, seed, *values)
            tasks.append(task)
            results.append(result)
    summary = future_work.summarize(tasks, results, Config(seeds=6))
    verdicts = {q.split(": ", 1)[1]: v for q, v in _verdicts(summary).items()}
    trace = "MMQ trace β=0.9"
    assert verdicts[f"{trace} seeds whose greedy policy is optimal"] == "differs"
    assert verdicts[f"{trace} share of second-half greedy snapshots optimal"] == "differs"
    assert verdicts[f"{trace} minus MMQ (thesis) training reward"] == "differs"
    assert verdicts["MMQ (thesis) share of second-half greedy snapshots optimal"] == "agrees"


def _deconv_summary(deconv_average: float, deconv_delay: float, seeds: int = 4):
    tasks, results = [], []
    values = {
        "MMQ": (0.55, 400.0, 60.0),
        "DeconvQ learned": (deconv_average, 300.0, deconv_delay),
        "Q": (0.12, 1000.0, None),
    }
    for seed in range(seeds):
        for agent, (average, error, delay) in values.items():
            tasks.append(LineTask(agent=agent, steps=10, seed=seed))
            estimate_mean = None if delay is None else delay + 0.1 * seed
            results.append(fake_line_run(average + 0.01 * seed, error, estimate_mean))
    return _verdicts(linefollow_deconv.summarize(tasks, results, Config(seeds=seeds)))


def test_linefollow_deconv_rows_flip():
    good = _deconv_summary(0.8, 90.0)
    assert {v for v in good.values() if v != "reference"} == {"agrees"}
    assert good["DeconvQ learned average reward during learning"] == "reference"
    bad = _deconv_summary(0.05, 40.0)
    assert bad["DeconvQ learned minus Q average reward"] == "differs"
    assert bad["DeconvQ learned minus MMQ average reward"] == "differs"
    assert bad["DeconvQ learned mean delay"] == "differs"
    assert bad["MMQ average reward during learning"] == "agrees"

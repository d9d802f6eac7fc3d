"""The experiments beyond the thesis: ``anonymous-delay``, ``future-work``, ``linefollow-deconv``."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from support import fake_grid_run, fake_line_run

from delayed_rl.cli import main
from delayed_rl.experiments import NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.beyond import anonymous_delay as ad
from delayed_rl.experiments.beyond import future_work as fw
from delayed_rl.experiments.beyond import linefollow_deconv as lfd
from delayed_rl.experiments.framework import delay_settings as settings
from delayed_rl.experiments.framework import setting_summaries as summaries
from delayed_rl.experiments.framework import snapshot_runs as snapshots
from delayed_rl.experiments.framework.experiment import VERDICTS
from delayed_rl.experiments.framework.line_following import LineTask
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.training import greedy_average_reward

UP, RIGHT, DOWN, LEFT = 0, 1, 2, 3


# ---------------------------------------------------------------------- delays and policies
@pytest.mark.parametrize("lam", [8, 13])
@pytest.mark.parametrize("kind", settings.DELAYS)
def test_every_delay_has_mean_lambda(kind, lam):
    delay = settings.make_delay(kind, lam)
    assert delay.mean == pytest.approx(lam)
    pmf = delay.pmf(np.arange(60 * lam))
    assert pmf.sum() == pytest.approx(1.0, abs=1e-9)
    assert pmf @ np.arange(pmf.size) == pytest.approx(lam, rel=1e-9)
    draws = delay.sample(np.random.default_rng(0), 200_000)
    assert draws.mean() == pytest.approx(lam, rel=0.02)


def test_geometric_and_bimodal_delays_are_what_the_docstring_says():
    geometric = settings.make_delay("geometric", 13)
    assert geometric.p == pytest.approx(1 / 14)
    bimodal = settings.make_delay("bimodal", 8)
    np.testing.assert_allclose(bimodal.pmf([0, 1, 8, 15, 16, 17]), [0.5, 0, 0, 0, 0.5, 0])
    assert settings.setting_label(9, "bimodal", 13) == "9×9 bimodal {0, 26}"
    task = settings.setting_tasks(Config(quick=True, seeds=1), ["Q"])[0]
    assert summaries.slug(task) == f"{settings.QUICK_SIZE}x{settings.QUICK_SIZE}_poisson"
    assert summaries.slug(dataclasses.replace(task, size=7, delay="geometric")) == "7x7_geometric"


def _loop_policy(size: int) -> np.ndarray:
    """An optimal loop: up everywhere, left along the top row (any action pays in cell 0)."""
    policy = np.full(size * size, UP)
    policy[:size] = LEFT  # the top row walks to the reward cell (0), where any action pays
    return policy


class _Greedy:
    """What ``greedy_average_reward`` reads: a Q-table whose greedy actions are ``actions``."""

    def __init__(self, actions):
        self.q_table = np.eye(4)[actions][:, None, :]


@pytest.mark.parametrize("size", [7, 9])
def test_the_optimal_loop_is_optimal_and_a_detour_is_not(size):
    policy = _loop_policy(size)
    loop = 2 * (size - 1) + 1
    assert snapshots.walk_average(policy, size) == pytest.approx(10 * (1000 // loop) / 1000)
    assert snapshots.walk_average(policy, size) == pytest.approx(
        greedy_average_reward(_Greedy(policy), size)
    )
    assert snapshots.is_optimal(policy, size)
    detour = policy.copy()
    start = size * size - 1
    detour[start - size] = DOWN  # back down to the start from the cell above it: a 2-cycle
    assert snapshots.walk_average(detour, size) == 0.0 and not snapshots.is_optimal(detour, size)
    other_route = policy.copy()
    other_route[start] = LEFT  # one step left, then up that column: as short, still optimal
    assert snapshots.is_optimal(other_route, size)
    wall = policy.copy()
    wall[start] = RIGHT  # into the wall forever
    assert snapshots.walk_average(wall, size) == -1.0 and not snapshots.is_optimal(wall, size)


def test_snapshots_read_the_greedy_policy_of_each_agent_kind():
    delay = settings.make_delay("Poisson", 3)
    for name in ("Q", "MMQ", "DeconvQ learned", "oracle"):
        agent = settings.make_agent(name, 5, delay, 0)
        agent.learn(500, log_interval=None)
        expected = snapshots.greedy_actions(agent.q_table)
        np.testing.assert_array_equal(snapshots.greedy_policy(agent), expected)
    deconv = settings.make_agent("DeconvQ known", 5, delay, 0).learn(500, log_interval=None)
    np.testing.assert_array_equal(
        snapshots.greedy_policy(deconv), deconv.q_table[:, 0, :].argmax(1)
    )


@pytest.mark.parametrize("name", ["MMQ", "DeconvQ learned", "expected credit", "oracle"])
def test_learning_in_snapshot_pieces_equals_one_learn_call(name):
    delay, steps = settings.make_delay("Poisson", 4), 2_600
    whole = settings.make_agent(name, 5, delay, 3).learn(steps, log_interval=None, record=True)
    pieces = settings.make_agent(name, 5, delay, 3)
    run = snapshots.train_with_snapshots(pieces, steps, 5)
    np.testing.assert_array_equal(run["rewards"], whole.training_log["undelayed_reward"])
    np.testing.assert_array_equal(pieces.q_table, whole.q_table)
    interval = steps // snapshots.SNAPSHOTS
    assert run["snapshot_steps"][0] == interval and run["snapshot_steps"][-1] == steps
    assert np.all(np.diff(run["snapshot_steps"]) == interval)
    assert run["snapshot_optimal"][-1] == snapshots.is_optimal(snapshots.greedy_policy(whole), 5)
    assert run["snapshot_greedy"][-1] == pytest.approx(
        snapshots.walk_average(snapshots.greedy_policy(whole), 5)
    )


def test_oracle_env_reports_arrivals():
    env = settings.grid(5, settings.make_delay("Poisson", 2), record_arrivals=True)
    env.reset(seed=0)
    assert "reward_arrivals" in env.step(0)[4]


# ---------------------------------------------------------------------- tasks
def test_task_counts_at_full_size_and_quick():
    full = Config(seeds=20)
    assert len(ad.tasks(full)) == 2 * 3 * 7 * 20 == 840
    assert len(fw.tasks(full)) == 2 * 3 * 6 * 20 == 720
    assert len(lfd.tasks(Config(seeds=5))) == 15
    steps = {(t.size, t.lam): t.steps for t in ad.tasks(full)}
    assert steps == {(9, 13): 1_000_000, (7, 8): 300_000}
    quick = ad.tasks(Config(quick=True, seeds=2))
    assert len(quick) == 14 and {(t.size, t.delay, t.steps) for t in quick} == {
        (7, "Poisson", 30_000)
    }
    assert {t.steps for t in lfd.tasks(Config(quick=True, seeds=2))} == {5_000}
    assert {t.steps for t in ad.tasks(Config(seeds=1, steps=777))} == {777}
    assert {get_experiment(n).default_seeds for n in ("anonymous-delay", "future-work")} == {20}


def test_future_work_options_scale_the_greedy_window():
    assert fw.options("MMQ greedy window 100k", 1_000_000) == {"greedy_window": 100_000}
    assert fw.options("MMQ greedy window 100k", 30_000) == {"greedy_window": 3_000}
    assert fw.options("MMQ kernel σ=2", 10) == {"reward_kernel": 2.0}
    assert fw.options("MMQ (thesis)", 10) == {}
    with pytest.raises(ValueError, match="variant must be one of"):
        fw.options("MMQ", 10)


def test_bad_arguments():
    with pytest.raises(ValueError, match="kind must be one of"):
        settings.make_delay("uniform", 3)
    with pytest.raises(ValueError, match="agent must be one of"):
        settings.make_agent("SARSA", 5, settings.make_delay("Poisson", 2), 0)
    with pytest.raises(ValueError, match="steps"):
        settings.make_agent("MMQ", 5, settings.make_delay("Poisson", 2), 0, steps=0)
    with pytest.raises(TypeError, match="steps"):
        settings.make_agent("MMQ", 5, settings.make_delay("Poisson", 2), 0, steps="1000")
    agent = settings.make_agent("MMQ", 5, settings.make_delay("Poisson", 2), 0, steps=1000)
    assert agent.greedy_window == 100
    with pytest.raises(TypeError, match="averaged"):
        snapshots.greedy_policy(agent, averaged="yes")
    with pytest.raises(ValueError, match=r"agent must be one of \('MMQ', 'Q', 'DeconvQ learned'\)"):
        lfd.EXPERIMENT.run_alone(LineTask(agent="SARSA", seed=0, steps=10))


def test_the_new_experiments_are_listed(capsys):
    assert {"anonymous-delay", "future-work", "linefollow-deconv"} <= set(NAMES)
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in ("anonymous-delay", "future-work", "linefollow-deconv"))


# ---------------------------------------------------------------------- small end-to-end runs
def test_anonymous_delay_small_run_writes_table_claims_and_figures(tmp_path):
    experiment = get_experiment("anonymous-delay")
    summary = run_experiment(experiment, Config(quick=True, seeds=1, steps=2_500), tmp_path, False)
    payload = json.loads((tmp_path / "summary.json").read_text())
    rows = {row["agent"]: row for row in payload["table"]}
    assert set(rows) == set(settings.LEARNERS)
    for row in rows.values():
        assert row["seeds"] == 1 and 0 <= row["optimal_seeds"] <= 1
        for key in ("greedy", "average", "second_half_optimal", "ns_per_step"):
            assert np.isfinite(row[key]) and f"{key}_ci95" in row
        assert row["true_mean_delay"] == 8
    assert "mean_delay" in rows["DeconvQ learned"] and "mean_delay" in rows["MMQ"]
    assert "mean_delay" not in rows["Q"]
    quantities = [claim.quantity for claim in summary.claims]
    assert len(quantities) == 6 and all(q.startswith("7×7 Poisson(8): ") for q in quantities)
    assert {claim.verdict for claim in summary.claims} <= set(VERDICTS)
    assert all(claim.criterion for claim in summary.claims)
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "delay_estimate_7x7_poisson.png",
        "learning_curves_7x7_poisson.png",
        "optimal_snapshots_7x7_poisson.png",
    ]


def test_future_work_small_run_has_a_row_and_claims_per_variant():
    experiment = get_experiment("future-work")
    summary = run_experiment(experiment, Config(quick=True, seeds=1, steps=2_000), None, False)
    assert [row["agent"] for row in summary.extra["table"]] == list(fw.VARIANTS)
    # two claims per variant, plus the training-reward one of each variant that acts otherwise
    assert len(summary.claims) == 2 * len(fw.VARIANTS) + len(fw.VARIANTS) - 1 - len(fw.GREEDY_ONLY)
    assert summary.extra["variants"]["MMQ greedy window 100k"] == {"greedy_window": 200}
    assert not any("greedy window" in c.quantity and "minus" in c.quantity for c in summary.claims)


def test_linefollow_deconv_run_measures_reward_error_and_the_delay_estimate():
    result = lfd.EXPERIMENT.run_alone(LineTask(agent="DeconvQ learned", steps=1_200, seed=0))
    assert result["steps"][-1] == 1_200 and result["error"][-1] == result["total_error"]
    assert result["curve"][-1] == pytest.approx(result["average"])
    assert result["estimate"].shape == (151,) and 0 <= result["mean_delay"] <= 150
    assert result["ns_per_step"] > 0


@pytest.mark.experiment
def test_anonymous_delay_quick_run(tmp_path):
    summary = run_experiment(get_experiment("anonymous-delay"), Config(quick=True), tmp_path, False)
    assert len(summary.claims) == 6 and summary.extra["table"][0]["seeds"] == 2
    by_agent = {row["agent"]: row for row in summary.extra["table"]}
    assert by_agent["Q undelayed"]["average"] > by_agent["Q"]["average"]


# ---------------------------------------------------------------------- computed verdicts
def _fake(agent: str, seed: int, optimal: bool, average: float, mean_delay: float, late: float):
    """:func:`support.fake_grid_run`, a delay estimate only for the agents that hold one."""
    holds = agent in ("MMQ", "DeconvQ learned")
    return fake_grid_run(agent, seed, optimal, average, mean_delay if holds else None, late)


def _verdicts(good: bool, seeds: int = 4) -> dict[str, str]:
    tasks, results = [], []
    for seed in range(seeds):
        jitter = 0.001 * seed
        runs = {
            "Q": (False, 0.0 + jitter, 0, 0.0),
            "MMQ": (good, (0.7 if good else -0.1) + jitter, 8, 1.0 if good else 0.3),
            "DeconvQ learned": (good, (0.7 if good else 0.4) + jitter, 8 if good else 14, 0.0),
            "oracle": (True, 0.71 + jitter, 0, 1.0),
        }
        for agent, (optimal, average, delay, late) in runs.items():
            task, result = _fake(agent, seed, optimal, average, delay, late)
            tasks.append(task)
            results.append(result)
    summary = ad.summarize(tasks, results, Config(seeds=seeds))
    return {claim.quantity.split(": ", 1)[1]: claim.verdict for claim in summary.claims}


def test_anonymous_delay_verdicts_are_computed_from_the_runs():
    good, bad = _verdicts(True), _verdicts(False)
    assert set(good) == set(bad) and len(good) == 6
    counts = {q for q in good if q.endswith("seeds whose greedy policy is optimal")}
    assert len(counts) == 2 and {good[q] for q in counts} == {"inconclusive"}  # 4 of 4 < 95 %
    assert {v for q, v in good.items() if q not in counts} == {"agrees"}
    assert set(bad.values()) == {"differs"}


def test_the_share_of_optimal_seeds_reads_its_wilson_interval():
    tasks, results = [], []
    for seed in range(20):
        task, result = _fake("DeconvQ learned", seed, seed != 0, 0.7, 8, 1.0)
        tasks.append(task)
        results.append(result)
    runs = pivot(tasks, results, by=("agent",))["DeconvQ learned"]
    claim = summaries.optimal_seeds_claim(tasks[0].setting, "DeconvQ learned", runs, "")
    # 19 of 20: Wilson [0.76, 0.99], neither inside nor wholly outside [0.95, 1]
    assert claim.verdict == "inconclusive" and claim.note.startswith("19 of 20 seeds")
    for result in results[1:9]:
        result["optimal"] = False
    claim = summaries.optimal_seeds_claim(tasks[0].setting, "DeconvQ learned", runs, "")
    assert claim.verdict == "differs" and claim.mean == pytest.approx(0.55)


def test_relative_gap_is_nan_and_inconclusive_when_the_oracle_earns_nothing():
    ours = {s: _fake("DeconvQ learned", s, True, 0.1, 8, 1.0)[1]["average"] for s in range(3)}
    oracle = {s: _fake("oracle", s, True, -0.1, 0, 1.0)[1]["average"] for s in range(3)}
    claim = ad.relative_gap_claim("q", "t", ours, oracle, 0.05)
    assert np.isnan(claim.mean) and claim.verdict == "inconclusive"


def _lfd_verdicts(deconv_average: float, deconv_error: float, deconv_delay: float):
    tasks, results = [], []
    values = {
        "MMQ": (0.55, 400.0, 60.0),
        "DeconvQ learned": (deconv_average, deconv_error, deconv_delay),
        "Q": (0.12, 1000.0, None),
    }
    for seed in range(3):
        for agent, (average, error, delay) in values.items():
            tasks.append(LineTask(agent=agent, steps=10, seed=seed))
            jitter = 0.01 * seed
            estimate_mean = None if delay is None else delay + jitter
            results.append(fake_line_run(average + jitter, error * (1 + jitter), estimate_mean))
    summary = lfd.summarize(tasks, results, Config(seeds=3))
    return {claim.quantity: claim.verdict for claim in summary.claims}, summary


def test_linefollow_deconv_verdicts_flip_with_the_data(tmp_path):
    better, summary = _lfd_verdicts(0.8, 200.0, 90.0)
    reference = "DeconvQ learned average reward during learning"
    assert better.pop(reference) == "reference" and set(better.values()) == {"agrees"}
    worse, _ = _lfd_verdicts(0.1, 900.0, 40.0)
    assert worse.pop(reference) == "reference"
    deconv = [q for q in worse if q.startswith("DeconvQ")]
    assert len(deconv) == 4 and all(worse[q] == "differs" for q in deconv)
    assert worse["MMQ average reward during learning"] == "agrees"  # MMQ's rows unchanged
    assert set(summary.extra["accumulated_error"]) == set(lfd.LEARNERS)
    for name, draw in summary.figures.items():
        draw(tmp_path / f"{name}.png")
    assert len(list(tmp_path.glob("*.png"))) == 3


@pytest.mark.experiment
def test_linefollow_deconv_quick_run(tmp_path):
    summary = run_experiment(
        get_experiment("linefollow-deconv"), Config(quick=True), tmp_path, False
    )
    assert len(summary.claims) == 8 and all(np.isfinite(c.mean) for c in summary.claims)
    assert (tmp_path / "delay_estimate.png").exists()

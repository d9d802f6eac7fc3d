"""The experiments and ``delayed-rl bench``: every experiment end to end in --quick mode."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from delayed_rl.cli import main
from delayed_rl.experiments import DEFAULT_NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.framework.experiment import VERDICTS, running_average
from delayed_rl.experiments.framework.line_following import LineTask
from delayed_rl.experiments.framework.training import greedy_average_reward, grid_env, train
from delayed_rl.experiments.thesis.controllers import ControllerTask


@pytest.mark.experiment
@pytest.mark.parametrize("name", DEFAULT_NAMES)  # deep-rl's own test: tests/test_experiment_deep_rl
def test_quick_run_writes_every_file(name, tmp_path):
    experiment, config = get_experiment(name), Config(quick=True, seeds=2)
    summary = run_experiment(experiment, config, tmp_path, False)
    with open(tmp_path / "curves.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert rows and set(rows[0]) == {"experiment", "condition", "seed", "metric", "step", "value"}
    assert {row["seed"] for row in rows} == {str(task.seed) for task in experiment.tasks(config)}
    values = np.array([float(row["value"]) for row in rows])
    assert np.isfinite(values).mean() > 0.5  # normalised curves are NaN only before any reward
    payload = json.loads((tmp_path / "summary.json").read_text())
    assert payload["experiment"] == name and payload["claims"]
    for claim in payload["claims"]:
        assert claim["verdict"] in VERDICTS and claim["criterion"]
        assert np.isfinite(claim["mean"]) or claim["verdict"] == "inconclusive"
    report = (tmp_path / "report.md").read_text()
    header = "| quantity | thesis value | measured mean ± 95 % CI | seeds | verdict | criterion |"
    assert header in report
    assert len(list(tmp_path.glob("*.png"))) == len(summary.figures) > 0


def test_roulette_walk_through_matches_the_thesis_tables():
    summary = run_experiment(get_experiment("roulette"), Config(), None, False)
    assert len(summary.claims) == 18
    assert all(claim.verdict == "agrees" for claim in summary.claims)


def test_mmq_gridworld_quick_separates_the_agents(tmp_path):
    summary = run_experiment(
        get_experiment("mmq-gridworld"), Config(quick=True, seeds=2), None, False
    )
    by_quantity = {claim.quantity: claim for claim in summary.claims}
    mmq = by_quantity["MMQ average reward during learning"].mean
    q = by_quantity["Q average reward during learning"].mean
    assert mmq > q + 0.1  # Fig. 5.9: MMQ learns the route, delayed Q-learning does not
    assert by_quantity["MMQ seeds whose final greedy policy is optimal"].note.endswith(
        "of the 17-step loop"
    )
    assert summary.extra["optimal_seeds"]["MMQ"][1] == 2
    assert "greedy_optimal_snapshots" in summary.figures


def test_mmq_gridworld_learns_in_pieces_as_in_one_run():
    from delayed_rl.experiments.thesis.mmq_gridworld import SIZE, MMQGridTask, run_task

    task = MMQGridTask(agent="MMQ", delay_estimates=tuple(range(51)), lam=13, steps=20_000, seed=3)
    pieces = run_task(task)
    whole = train(grid_env(SIZE, 13), list(task.delay_estimates), task.steps, task.seed)
    log = whole.training_log
    assert pieces["average"] == float(log["undelayed_reward"].mean())
    assert pieces["greedy"] == greedy_average_reward(whole, SIZE)
    np.testing.assert_array_equal(pieces["visits"].ravel(), np.bincount(log["obs"], minlength=81))
    np.testing.assert_array_equal(pieces["model_share"], whole.acting_delay_share)
    assert pieces["snapshot_steps"].size == 50 and pieces["snapshot_steps"][-1] == 20_000
    assert pieces["optimal"] == bool(pieces["snapshot_optimal"][-1])


def test_running_average_is_the_cumulative_mean():
    steps, values = running_average(np.array([1.0, 0.0, 2.0, 1.0]), points=4)
    np.testing.assert_array_equal(steps, [1, 2, 3, 4])
    np.testing.assert_allclose(values, [1.0, 0.5, 1.0, 1.0])


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: get_experiment("nope"), ValueError, "experiment must be one of ('delay-sweep'"),
        (lambda: get_experiment(None), TypeError, "experiment must be one of"),
        (lambda: running_average(np.ones(3), 0), ValueError, "points must be an integer >= 1"),
        (lambda: Config(seeds=0), ValueError, "seeds must be None or an integer >= 1, got 0"),
        (lambda: Config(seeds="3"), TypeError, "seeds must be None or an integer >= 1, got '3'"),
        (lambda: Config(steps=-5), ValueError, "steps must be None or an integer >= 1, got -5"),
        (lambda: Config(quick=1), TypeError, "quick must be a bool, got 1 (int)"),
        (lambda: Config(workers=0), ValueError, "workers must be an integer >= 1, got 0"),
        (lambda: Config(backend="spark"), ValueError, "backend must be one of"),
        (lambda: Config(base_seed=-1), ValueError, "base_seed must be an integer >= 0, got -1"),
        (lambda: Config(seeds=10**12), ValueError, "seeds must be at most MAX_SEED_COUNT = 10,000"),
        (lambda: Config(steps=2**40 + 1), ValueError, "steps must be at most MAX_TIMESTEPS"),
        (lambda: Config(workers=10**6), ValueError, "workers must be at most MAX_WORKERS = 1024"),
        (lambda: Config(base_seed=2**63), ValueError, "base_seed must be at most MAX_SEED_VALUE"),
    ],
)
def test_bad_runner_arguments(call, error, message):
    with pytest.raises(error) as raised:
        call()
    assert str(raised.value).startswith(message)


def test_bad_experiment_arguments():
    from delayed_rl.experiments.framework.line_following import make_agent
    from delayed_rl.experiments.thesis.mmq_gridworld import behaviour_policy

    with pytest.raises(
        ValueError, match=r"kind must be one of \('MMQ', 'Q', 'DeconvQ learned'\), got 'SARSA'"
    ):
        make_agent("SARSA", None, 0)
    with pytest.raises(ValueError, match=r"epsilon must be a number in \[0, 1\], got 1.5"):
        behaviour_policy(np.zeros((2, 1, 4)), epsilon=1.5)
    with pytest.raises(TypeError, match="steps must be an integer >= 1"):
        greedy_average_reward(None, 3, steps=10.0)


def test_grid_tasks_pair_every_delayed_run_with_a_reference_of_its_world_and_seed():
    from delayed_rl.experiments.thesis import world_size

    tasks = world_size.tasks(Config(quick=True, seeds=2, base_seed=5))
    references = [(t.size, t.seed) for t in tasks if t.reference]
    assert references == [(size, seed) for seed in (5, 6) for size in (3, 5, 9)]
    delayed = [t for t in tasks if not t.reference]
    assert sorted((t.size, t.lam, t.seed) for t in delayed) == sorted(
        (size, lam, seed) for size in (3, 5, 9) for lam in (5, 50) for seed in (5, 6)
    )
    assert {t.steps for t in tasks} == {25_000}
    assert all(
        t.delay_estimates == (0,) and t.condition.endswith(f"lambda={t.lam}") for t in delayed
    )


def test_cli_bench_quick_writes_report(tmp_path, capsys):
    argv = ["bench", "delay-sweep", "--quick", "--steps", "2000", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert (tmp_path / "delay-sweep" / "report.md").exists()
    assert "verdict" in capsys.readouterr().out


def test_line_error_counts_an_unseen_line_as_the_worst_offset():
    from delayed_rl.experiments.framework.line_following import line_error

    np.testing.assert_array_equal(line_error([0, 1, 19, 20, 21, 40]), [20, 19, 1, 0, 1, 20])


def test_line_following_tasks_follow_the_thesis_scale_and_seeds():
    from delayed_rl.experiments.thesis import controllers, linefollow

    full = linefollow.tasks(Config(seeds=5, base_seed=7))
    assert sorted((t.agent, t.seed) for t in full) == sorted(
        (agent, seed) for agent in ("MMQ", "Q") for seed in range(7, 12)
    )
    assert {t.steps for t in full} == {150_000}
    runs = controllers.tasks(Config(seeds=2, base_seed=3))
    assert {t.controller for t in runs} == {"P undelayed", "P delayed observations", "Q", "MMQ"}
    assert {t.seed for t in runs} == {3, 4}
    assert {(t.train_steps, t.run_steps) for t in runs} == {(300_000, 1700)}
    assert {t.steps for t in linefollow.tasks(Config(quick=True, seeds=1, steps=123))} == {123}


def test_delayed_observations_break_the_proportional_controller():
    from delayed_rl.experiments.thesis.controllers import run_task

    task = ControllerTask(controller="P undelayed", train_steps=0, run_steps=1700, seed=0)
    undelayed = run_task(task)
    delayed = run_task(dataclasses.replace(task, controller="P delayed observations"))
    # Fig. 5.19: ≈ 0.9 undelayed; the Poisson(90)-late camera loses the line most of the time.
    assert undelayed["average"] > 0.75 and undelayed["visible"] > 0.95
    assert delayed["average"] < 0.3 and delayed["visible"] < 0.8
    assert undelayed["curve"][-1] == pytest.approx(undelayed["average"])
    assert delayed["total_error"] > 3 * undelayed["total_error"]


def test_learners_keep_learning_through_the_controllers_run():
    from delayed_rl.experiments.thesis.controllers import run_task

    result = run_task(ControllerTask(controller="Q", train_steps=500, run_steps=200, seed=1))
    assert result["steps"][-1] == 200 and result["curve"][-1] == pytest.approx(result["average"])
    assert -1.0 <= result["average"] <= 1.0


def test_linefollow_run_records_reward_and_accumulated_error():
    from delayed_rl.experiments.thesis.linefollow import EXPERIMENT

    result = EXPERIMENT.run_alone(LineTask(agent="MMQ", steps=1000, seed=0))
    assert result["steps"][-1] == 1000 and result["error"][-1] == result["total_error"]
    assert np.all(np.diff(result["error"]) >= 0)  # an accumulated sum of |Δ| ≥ 0
    assert np.all(np.diff(result["error"]) <= 20 * np.diff(result["steps"]))  # |Δ| ≤ 20 a step
    assert result["curve"][-1] == pytest.approx(result["average"])


def _fake_linefollow(mmq: tuple[float, float], q: tuple[float, float], seeds: int = 3):
    from delayed_rl.experiments.thesis.linefollow import summarize

    tasks, results = [], []
    for seed in range(seeds):
        for agent, (average, error) in (("MMQ", mmq), ("Q", q)):
            tasks.append(LineTask(agent=agent, steps=10, seed=seed))
            steps = np.array([5, 10])
            jitter = 0.01 * seed
            result = {
                "steps": steps,
                "curve": np.full(2, average + jitter),
                "error": np.array([error / 2, error]),
                "average": average + jitter,
                "total_error": error * (1 + jitter),
                "visible": 1.0,
            }
            results.append(result)
    summary = summarize(tasks, results, Config(seeds=seeds))
    return {claim.quantity: claim for claim in summary.claims}


def test_linefollow_verdicts_follow_the_documented_rules():
    thesis_like = _fake_linefollow(mmq=(0.55, 400.0), q=(0.12, 1000.0))
    assert all(claim.verdict == "agrees" for claim in thesis_like.values())
    ratio = thesis_like["MMQ accumulated error / Q accumulated error"]
    assert ratio.mean == pytest.approx(0.4, abs=0.01) and ratio.n == 3
    unlike = _fake_linefollow(mmq=(0.3, 900.0), q=(0.6, 1000.0))
    assert all(claim.verdict == "differs" for claim in unlike.values())
    assert unlike["MMQ minus Q average reward (paired by seed)"].mean == pytest.approx(-0.3)


def test_behaviour_policy_is_the_two_level_epsilon_greedy_rule():
    from delayed_rl.experiments.thesis.mmq_gridworld import behaviour_policy

    q = np.zeros((2, 3, 4))
    q[0, 1, 2] = 5.0  # state 0: one model holds the max at action 2
    q[1, :, 0] = q[1, :, 1] = 1.0  # state 1: every model ties actions 0 and 1
    policy = behaviour_policy(q, epsilon=0.1)
    np.testing.assert_allclose(policy.sum(axis=1), 1.0)
    # state 0: greedy model (0.9 + 0.1/3) acts greedily (0.9 + 0.1/4) on action 2; the 2 other
    # models (0.1/3 each) tie all four actions
    greedy_model = 0.9 + 0.1 / 3
    expected = greedy_model * (0.9 * np.eye(4)[2] + 0.025) + (2 * 0.1 / 3) * np.full(4, 0.25)
    np.testing.assert_allclose(policy[0], expected)
    np.testing.assert_allclose(policy[1], [0.475, 0.475, 0.025, 0.025])


def _value_iteration_policy(env, gamma: float = 0.9, sweeps: int = 200) -> np.ndarray:
    """A greedy policy of the optimal values, from the env's tables (``env.P``)."""
    n_states, n_actions = env.observation_space.n, env.action_space.n
    v = np.zeros(n_states)
    for _ in range(sweeps):
        q = np.array(
            [
                [
                    sum(p * (r + gamma * v[s2]) for p, s2, r, _ in env.P[s][a])
                    for a in range(n_actions)
                ]
                for s in range(n_states)
            ]
        )
        v = q.max(axis=1)
    return q.argmax(axis=1)


def test_mmq_gridworld_counts_the_optimal_loop_over_a_finite_walk():
    """The optimal policy's 1000-step greedy walk counts as the optimal loop, a detour does not."""
    from delayed_rl.experiments.thesis.mmq_gridworld import LOOP_FRACTION, SIZE

    env = grid_env(SIZE, 0).unwrapped
    policy = _value_iteration_policy(env)
    optimal = 10 / (2 * (SIZE - 1) + 1)

    class Greedy:  # greedy_average_reward reads only the Q-table
        def __init__(self, actions):
            self.q_table = np.eye(env.action_space.n)[actions][:, None, :]

    assert greedy_average_reward(Greedy(policy), SIZE) >= LOOP_FRACTION * optimal
    # a detour: from the cell above the start, left, down (away from the reward cell), left,
    # then back on the optimal route: two moves more, the 19-step loop
    size, start = SIZE, env.start_state
    detour = policy.copy()
    moves = [
        (start - size, start - size - 1),
        (start - size - 1, start - 1),
        (start - 1, start - 2),
    ]
    for here, there in moves:
        detour[here] = _action(env, here, there)
    assert greedy_average_reward(Greedy(detour), SIZE) < LOOP_FRACTION * optimal


def _action(env, state: int, target: int) -> int:
    """The action leading from ``state`` to the neighbouring ``target``."""
    return next(a for a in env.P[state] if env.P[state][a][0][1] == target)


def test_bench_all_writes_an_index_of_every_experiment(tmp_path):
    from delayed_rl.experiments.framework.experiment import Claim, Summary
    from delayed_rl.experiments.framework.report import write_index

    def claims(*verdicts):
        return [Claim("q", "t", 0.0, 0.1, 5, verdict) for verdict in verdicts]

    def costs(runs, shared, seconds):
        return {"runs": runs, "shared_runs": shared, "run_seconds": seconds}

    ran = [
        (get_experiment("roulette"), Summary(claims("agrees", "agrees"), [], extra=costs(1, 0, 1.5))),
        (get_experiment("delay-sweep"), Summary(claims("differs", "inconclusive", "reference"), [], extra=costs(70, 3, 60.0))),
    ]  # fmt: skip
    text = write_index(tmp_path, ran, 61.5).read_text()
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert rows[0].startswith("| `roulette` |") and "| 1 | 0 | 1.5 | 2 | 0 | 0 | 0 |" in rows[0]
    assert (
        "| 70 | 3 | 60.0 | 0 | 1 | 1 | 1 | [delay-sweep/report.md](delay-sweep/report.md) |"
        in rows[1]
    )
    assert "Wall time: 61.5 s (1.0 min)." in text
    assert "Wall time" not in write_index(tmp_path, ran).read_text()
    with pytest.raises(ValueError, match="wall_seconds"):
        write_index(tmp_path, ran, -1.0)
    with pytest.raises(TypeError, match="wall_seconds"):
        write_index(tmp_path, ran, "61.5")

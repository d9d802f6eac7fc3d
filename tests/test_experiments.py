"""The experiment runner and the CLI: every experiment end to end in --quick mode."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from delayed_rl.cli import main
from delayed_rl.experiments import NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.runner import mean_ci95, run_tasks, running_average


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_quick_run_writes_every_file(name, tmp_path):
    experiment, config = get_experiment(name), Config(quick=True, seeds=2)
    summary = run_experiment(experiment, config, tmp_path, False)
    with open(tmp_path / "curves.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert rows and set(rows[0]) == {"experiment", "condition", "seed", "metric", "step", "value"}
    assert {row["seed"] for row in rows} == {str(task["seed"]) for task in experiment.tasks(config)}
    values = np.array([float(row["value"]) for row in rows])
    assert np.isfinite(values).mean() > 0.5  # normalised curves are NaN only before any reward
    payload = json.loads((tmp_path / "summary.json").read_text())
    assert payload["experiment"] == name and payload["claims"]
    for claim in payload["claims"]:
        assert claim["verdict"] in {"agrees", "differs"} and np.isfinite(claim["mean"])
    report = (tmp_path / "report.md").read_text()
    assert "| quantity | thesis value | measured mean ± 95 % CI | seeds | verdict |" in report
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


def test_results_do_not_depend_on_the_number_of_workers():
    experiment = get_experiment("delay-sweep")
    tasks = experiment.tasks(Config(quick=True, seeds=2, steps=3000))
    one = run_tasks(experiment.run_task, tasks, 1, "loky")
    two = run_tasks(experiment.run_task, tasks, 2, "loky")
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a["curve"], b["curve"])


def test_mean_ci95_matches_the_t_interval():
    mean, half = mean_ci95([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5
    assert half == pytest.approx(3.182 * np.std([1, 2, 3, 4], ddof=1) / 2, rel=0.02)
    assert mean_ci95([5.0]) == (5.0, 0.0)


def test_running_average_is_the_cumulative_mean():
    steps, values = running_average(np.array([1.0, 0.0, 2.0, 1.0]), points=4)
    np.testing.assert_array_equal(steps, [1, 2, 3, 4])
    np.testing.assert_allclose(values, [1.0, 0.5, 1.0, 1.0])


def test_bad_runner_arguments():
    with pytest.raises(ValueError, match="backend"):
        run_tasks(len, [], 1, "spark")
    with pytest.raises(ValueError, match="workers"):
        run_tasks(len, [], 0, "loky")
    with pytest.raises(ValueError, match="unknown experiment 'nope'"):
        get_experiment("nope")


def test_cli_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "delayed_rl/GridWorld-9x9-v0" in out and "mmq-gridworld" in out


@pytest.mark.parametrize(
    "argv", [["bench", "nope"], ["bench", "delay-sweep", "--seeds", "0"],
             ["bench", "delay-sweep", "--backend", "spark"], ["frobnicate"]],
)  # fmt: skip
def test_cli_rejects_bad_input_with_exit_code_2(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "error" in capsys.readouterr().err


def test_cli_bench_quick_writes_report(tmp_path, capsys):
    argv = ["bench", "delay-sweep", "--quick", "--steps", "2000", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert (tmp_path / "delay-sweep" / "report.md").exists()
    assert "verdict" in capsys.readouterr().out

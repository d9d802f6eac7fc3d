"""The line follower's training runs: pooled readouts give what runs of their own give."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.experiments import Config, run_experiment, run_experiments
from delayed_rl.experiments.beyond import linefollow_deconv
from delayed_rl.experiments.framework.line_following import training_run, training_task
from delayed_rl.experiments.thesis import controllers, linefollow, real_robot

TIMINGS = {"ns_per_step", "pretrain_seconds"}


def assert_same(ours, theirs):
    """Equal to the bit, wall times apart."""
    if isinstance(ours, dict):
        assert set(ours) - TIMINGS == set(theirs) - TIMINGS
        for key in set(ours) - TIMINGS:
            assert_same(ours[key], theirs[key])
    elif isinstance(ours, np.ndarray):
        assert ours.dtype == theirs.dtype and ours.tobytes() == theirs.tobytes()
    else:
        assert ours == theirs


@pytest.mark.parametrize("agent", ["MMQ", "Q", "DeconvQ learned"])
def test_each_readout_of_one_run_is_what_a_run_of_its_own_gives(agent):
    readouts = [
        ["continue", 600, "real", 40],
        ["log", 400],  # spans the pieces ending at 250 and 400
        ["continue", 250, "clean", 60],
        ["log", 250],
        ["continue", 600, "clean", 30],
    ]
    pooled = training_run(training_task(agent, 3, *readouts))["readouts"]
    assert len(pooled) == len(readouts)
    for readout, result in zip(readouts, pooled, strict=True):
        (alone,) = training_run(training_task(agent, 3, readout))["readouts"]
        assert_same(result, alone)
    assert pooled[1]["steps"][-1] == 400 and pooled[3]["steps"][-1] == 250
    twice = training_run(training_task(agent, 3, ["log", 250], ["log", 250]))["readouts"]
    assert_same(twice[0], twice[1])
    assert_same(twice[0], pooled[3])
    assert pooled[0]["pretrain_seconds"] >= pooled[2]["pretrain_seconds"] > 0
    other_seed = training_run(training_task(agent, 4, ["log", 400]))["readouts"][0]
    assert other_seed["curve"].tobytes() != pooled[1]["curve"].tobytes()  # the check can fail


@pytest.mark.parametrize(
    "readout",
    [["log"], ["log", 0], ["log", 10, 5], ["continue", 10, "moon", 5], ["continue", 10, "real"],
     ["fit", 10], ("log", 10), ["log", 2.5], ["continue", 10, "clean", True],
     ["continue", 10, ["clean"], 5]],
)  # fmt: skip
def test_a_bad_readout_is_refused_by_name(readout):
    with pytest.raises(ValueError, match=r"a readout must be \['log', n\] or") as error:
        training_run(training_task("Q", 0, readout))
    assert repr(readout) in str(error.value)


@pytest.mark.experiment
def test_the_line_experiments_run_together_train_each_learner_and_seed_once():
    config = Config(quick=True, seeds=1, workers=1)
    experiments = [
        linefollow.EXPERIMENT,
        linefollow_deconv.EXPERIMENT,
        controllers.EXPERIMENT,
        real_robot.EXPERIMENT,
    ]
    together = run_experiments(experiments, config, progress=False)
    # one training run per learner (MMQ, Q, DeconvQ learned), and the two P controllers' runs
    assert [s.extra["runs"] for s in together] == [2, 3, 4, 3]
    assert [s.extra["shared_runs"] for s in together] == [2, 3, 2, 3]
    for experiment, summary in zip(experiments, together, strict=True):
        alone = run_experiment(experiment, Config(quick=True, seeds=1, workers=1), progress=False)
        assert [(c.quantity, c.mean, c.ci95, c.verdict) for c in summary.claims] == [
            (c.quantity, c.mean, c.ci95, c.verdict) for c in alone.claims
        ]
        assert [c.values.tobytes() for c in summary.curves] == [
            c.values.tobytes() for c in alone.curves
        ]

"""Tests of :mod:`delayed_rl.parallel.pools`."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.experiments import Config, get_experiment
from delayed_rl.parallel.pools import run_tasks


@pytest.mark.cold_cache
def test_results_do_not_depend_on_the_number_of_workers():
    experiment = get_experiment("delay-sweep")
    tasks = experiment.tasks(Config(quick=True, seeds=2, steps=3000))
    one = run_tasks(experiment.run_task, tasks, 1, "loky")
    two = run_tasks(experiment.run_task, tasks, 2, "loky")
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a["curve"], b["curve"])


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: run_tasks(len, [], 1, "spark"), ValueError, "backend must be one of ('loky'"),
        (lambda: run_tasks(len, [], 1, 3), TypeError, "backend must be one of"),
        (lambda: run_tasks(len, [], 0, "loky"), ValueError, "workers must be an integer >= 1"),
        (lambda: run_tasks(len, [], 2.0, "loky"), TypeError, "workers must be an integer >= 1"),
        (lambda: run_tasks(len, [], 2000, "loky"), ValueError, "workers must be at most"),
    ],
)
def test_bad_runner_arguments(call, error, message):
    with pytest.raises(error) as raised:
        call()
    assert str(raised.value).startswith(message)

"""Tests of :mod:`delayed_rl.parallel.pools`."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.experiments import Config, get_experiment
from delayed_rl.parallel.pools import MAX_WORKERS, check_workers, process_pool, run_tasks


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


def test_check_workers_takes_1_to_max_workers_and_names_the_argument():
    assert check_workers("workers", 1) == 1 and check_workers("workers", MAX_WORKERS) == 1024
    with pytest.raises(ValueError, match="workers must be an integer >= 1, got 0"):
        check_workers("workers", 0)
    with pytest.raises(ValueError, match="workers must be at most MAX_WORKERS = 1024"):
        check_workers("workers", 1025)
    with pytest.raises(TypeError, match="workers"):
        check_workers("workers", 2.0)


@pytest.mark.cold_cache
def test_a_process_pool_runs_closures_in_other_processes():
    import os

    offset = 5
    pool = process_pool(2)
    try:
        done = [pool.submit(lambda x: (x + offset, os.getpid()), x) for x in range(4)]
        results = [future.result(timeout=120) for future in done]
    finally:
        pool.shutdown(wait=True)
    assert [value for value, _ in results] == [5, 6, 7, 8]
    assert os.getpid() not in {pid for _, pid in results}
    with pytest.raises(ValueError, match="processes must be an integer >= 1"):
        process_pool(0)

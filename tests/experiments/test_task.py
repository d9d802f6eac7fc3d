"""A task's cost: what orders the runs, longest first."""

from __future__ import annotations

import dataclasses
import math

import pytest

from delayed_rl.experiments import NAMES, Config, get_experiment
from delayed_rl.experiments.framework.task import Task


@dataclasses.dataclass(frozen=True, kw_only=True)
class Stepped(Task):
    steps: int


def test_a_task_costs_a_microsecond_a_step_by_default_and_one_without_steps():
    assert Stepped(steps=2_000_000, seed=0).cost() == pytest.approx(2.0)
    assert Task(seed=0).cost() == pytest.approx(1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_every_experiments_tasks_have_a_positive_finite_cost(name):
    experiment = get_experiment(name)
    tasks = experiment.tasks(Config(quick=True, seeds=1))
    costs = [experiment.task_cost(task) for task in tasks]
    assert costs and all(math.isfinite(cost) and cost > 0 for cost in costs)


def test_future_work_costs_its_variants_by_their_own_step_times():
    experiment = get_experiment("future-work")
    tasks = {task.agent: task for task in experiment.tasks(Config(quick=True, seeds=1))}
    kernel, coarse = tasks["MMQ kernel σ=2"], tasks["MMQ Λ step 3"]
    assert kernel.steps == coarse.steps
    assert kernel.cost() > tasks["MMQ (thesis)"].cost() > coarse.cost()


def test_a_dict_task_costs_a_microsecond():
    assert get_experiment("roulette").task_cost({"x": 1}) == pytest.approx(1e-6)


def test_setting_tasks_take_a_setting_task_type_and_learners_by_name():
    from delayed_rl.experiments.framework import delay_settings

    with pytest.raises(TypeError, match="task_type must be SettingTask"):
        delay_settings.setting_tasks(Config(quick=True, seeds=1), ["Q"], Stepped)
    with pytest.raises(ValueError, match="agent must be one of"):
        delay_settings.learner_arguments("SARSA", None)
    agent, options = delay_settings.learner_arguments("DeconvQ known", "the delay")
    assert agent == "deconv" and options["delay"] == "the delay"

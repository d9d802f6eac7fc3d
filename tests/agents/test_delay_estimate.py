"""One name, one default and one limit for the longest delay an agent models."""

from __future__ import annotations

import inspect

import pytest

from delayed_rl.agents import (
    DeconvolutionQLearning,
    ExpectedCreditQLearning,
    MultipleModelQLearning,
)
from delayed_rl.agents.common.delay_estimate import (
    DEFAULT_MAX_DELAY_ESTIMATE,
    MAX_DELAY_ESTIMATE,
    check_max_delay_estimate,
)
from delayed_rl.agents.expected_credit import credit_weights
from delayed_rl.delays import Poisson, Uniform
from delayed_rl.envs.gridworld import GridWorldEnv

MODELLERS = {
    "DeconvolutionQLearning": lambda k: DeconvolutionQLearning(
        GridWorldEnv(size=3), max_delay_estimate=k
    ),
    "ExpectedCreditQLearning": lambda k: ExpectedCreditQLearning(
        GridWorldEnv(size=3), Poisson(2.0), max_delay_estimate=k
    ),
}


def test_every_agent_that_models_a_delay_takes_max_delay_estimate_and_no_max_delay():
    from delayed_rl.agents.registry import REGISTRY, agent_class

    modellers = [DeconvolutionQLearning, ExpectedCreditQLearning, MultipleModelQLearning]
    for name in REGISTRY:  # no registered agent takes the wrappers' clip
        assert "max_delay" not in inspect.signature(agent_class(name)).parameters, name
    for cls in modellers:
        assert "max_delay_estimate" in inspect.signature(cls).parameters, cls


@pytest.mark.parametrize("name", sorted(MODELLERS))
def test_the_limit_is_the_same_constant_for_every_agent(name):
    make = MODELLERS[name]
    assert make(MAX_DELAY_ESTIMATE).max_delay_estimate == MAX_DELAY_ESTIMATE
    with pytest.raises(ValueError, match="max_delay_estimate must be at most MAX_DELAY_ESTIMATE"):
        make(MAX_DELAY_ESTIMATE + 1)


def test_a_known_delay_beyond_the_limit_needs_a_max_delay_estimate():
    far = Uniform(0, MAX_DELAY_ESTIMATE + 5)
    with pytest.raises(ValueError, match="reaches 1029: give a max_delay_estimate"):
        DeconvolutionQLearning(GridWorldEnv(size=3), delay=far)
    clipped = credit_weights(far, max_delay_estimate=MAX_DELAY_ESTIMATE)
    assert clipped.size == MAX_DELAY_ESTIMATE + 1
    assert clipped[-1] == pytest.approx(6 / (MAX_DELAY_ESTIMATE + 6))  # the clipped mass


def test_the_default_is_the_thesis_cut_off_for_both_learners():
    assert DEFAULT_MAX_DELAY_ESTIMATE == 50
    assert MultipleModelQLearning(GridWorldEnv(size=3)).delay_estimates[-1] == 50
    assert DeconvolutionQLearning(GridWorldEnv(size=3)).delay_pmf.size == 51


@pytest.mark.parametrize(
    ("value", "error", "message"),
    [
        (-1, ValueError, "max_delay_estimate must be None or an integer >= 0, got -1"),
        (2.5, TypeError, "max_delay_estimate must be None or an integer"),
        ("8", TypeError, "max_delay_estimate must be None or an integer"),
        (True, TypeError, "max_delay_estimate must be None or an integer"),
    ],
)
def test_bad_values_are_refused_by_name(value, error, message):
    with pytest.raises(error, match=message):
        check_max_delay_estimate(value)
    assert check_max_delay_estimate(None) is None and check_max_delay_estimate(7) == 7

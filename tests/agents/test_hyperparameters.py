"""Tests of :mod:`delayed_rl.agents.common.hyperparameters`: one check per shared name."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.agents.common.hyperparameters import (
    DEFAULTS,
    HYPERPARAMETER_CHECKS,
    HYPERPARAMETER_NAMES,
    check_hyperparameters,
    with_defaults,
)
from delayed_rl.agents.common.schedules import ConstantSchedule


def test_every_shared_name_has_one_check_in_the_same_order():
    assert tuple(HYPERPARAMETER_CHECKS) == HYPERPARAMETER_NAMES


def test_a_missing_or_unknown_name_is_named():
    given = with_defaults("QLearning", {})
    del given["seed"]
    with pytest.raises(TypeError, match=r"missing \['seed'\], unknown \[\]"):
        check_hyperparameters(**given)
    with pytest.raises(TypeError, match=r"missing \[\], unknown \['gammma'\]"):
        check_hyperparameters(**with_defaults("QLearning", {}), gammma=0.5)
    with pytest.raises(TypeError, match=r"QLearning\(\) got an unexpected keyword argument 'x'"):
        with_defaults("QLearning", {"x": 1})


def test_the_learning_rate_is_kept_as_given_beside_its_schedule():
    rate = np.float32(0.25)
    checked = check_hyperparameters(**with_defaults("QLearning", {"learning_rate": rate}))
    assert type(checked["learning_rate"]) is np.float32
    assert isinstance(checked["lr_schedule"], ConstantSchedule)
    assert checked["lr_schedule"](1.0) == 0.25
    assert checked["gamma"] == DEFAULTS.gamma
    with pytest.raises(ValueError, match=r"learning_rate must be a number in \(0, 1\]"):
        check_hyperparameters(**with_defaults("QLearning", {"learning_rate": 1.5}))

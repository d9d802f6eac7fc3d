"""The longest delay an agent models, ``max_delay_estimate``: its default and its limit.

The name is MMQ's λ̂max (the thesis's "maximum delay estimate"), and every agent that models a
delay takes it under that name: :class:`~delayed_rl.agents.MultipleModelQLearning` keeps a
table per estimate up to it, :class:`~delayed_rl.agents.DeconvolutionQLearning` and
:class:`~delayed_rl.deep.DeconvolutionRewardModel` learn a pmf on ``0..max_delay_estimate`` (or
cap a known delay's support there), and :class:`~delayed_rl.agents.ExpectedCreditQLearning`
credits that many lags. The wrappers' ``max_delay`` is something else: the clip on the delays
they draw.
"""

from __future__ import annotations

from typing import Any

from delayed_rl._validation import Limit, check_int, check_limit

__all__ = ["DEFAULT_MAX_DELAY_ESTIMATE", "MAX_DELAY_ESTIMATE", "check_max_delay_estimate"]

DEFAULT_MAX_DELAY_ESTIMATE = 50
"""The thesis's λ̂max in the 9×9 grid world (section 5.1.1), the default where one is needed."""

MAX_DELAY_ESTIMATE = Limit(1024, "MAX_DELAY_ESTIMATE", __name__, "1024")
"""The longest delay modelled by a pmf or by credited lags (``K``): 1024 steps.

The tabular deconvolution binds it: a solve builds ``(K + 1)²`` matrices (24 MiB at the limit)
and costs ``O(K³)``, and its statistics take ``(K + 1)·|S|·|A|`` sums; the deep deconvolution
evaluates ``R̂`` on ``window + K`` steps per window, and expected credit costs ``O(K)`` a step.
The experiments model at most 150 steps. MMQ's ``max_delay_estimate`` (λ̂max) has the same
limit; a Λ given as its ``delay_estimates`` list is bounded by its tables' memory instead
(:data:`~delayed_rl.agents.common.q_table.MAX_TABLE_BYTES`: a table per estimate, no solve).
"""


def check_max_delay_estimate(value: Any) -> int | None:
    """``value`` checked as a ``max_delay_estimate``: ``None``, or an integer in ``0..1024``.

    Raises:
        TypeError: ``value`` is not an integer (nor ``None``).
        ValueError: it is negative or above :data:`MAX_DELAY_ESTIMATE`.
    """
    return check_limit(
        "max_delay_estimate",
        check_int("max_delay_estimate", value, 0, optional=True),
        MAX_DELAY_ESTIMATE,
    )

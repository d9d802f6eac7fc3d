"""Tabular agents with a stable-baselines3-like API.

The algorithms, side by side over the shell of :mod:`delayed_rl.agents.common`:

- :class:`QLearning`: Q-learning (rewards credited to the step that just happened);
- :class:`FixedDelayQLearning`: Q-learning that assumes a constant delay ``k``;
- :class:`MultipleModelQLearning`: Multiple Model Q-learning, which learns over parallel delay
  hypotheses (thesis section 3.2);
- :class:`ExpectedCreditQLearning`: Q-learning that spreads each received reward over the past
  steps by a known delay distribution's pmf (the cheap anonymous baseline);
- :class:`OracleQLearning`: Q-learning that credits each reward to the transition that emitted
  it, read from ``RewardDelay(..., record_arrivals=True)`` (the non-anonymous upper bound);
- :class:`DeconvolutionQLearning`: Q-learning on mean rewards estimated by deconvolving the
  delayed reward stream, with the delay known or learned;
- :func:`load_agent`: load any of them from a file, whatever its class;
- ``ProportionalController`` (thesis Eqs. 5.8–5.9), imported from
  :mod:`delayed_rl.agents.proportional` on first access.

Each learning rule is also written plainly, without caches or compiled code, in
:mod:`delayed_rl.agents.reference`; both training paths are tested against it bit for bit.
All share :class:`~delayed_rl.agents.common.base.TabularAgent`: ``learn``, ``predict``,
``update``, ``save``/``load``, ``get_env``/``set_env``, ``logger``, and SB3 callbacks.
"""

from delayed_rl.agents.common.base import RECORD_KEYS, TabularAgent, load_agent
from delayed_rl.agents.common.hyperparameters import DEFAULTS, AgentDefaults
from delayed_rl.agents.common.schedules import ConstantSchedule, LinearSchedule
from delayed_rl.agents.registry import REGISTRY, agent_class

#: The registered algorithms by class name, exported here (the registry is their one list).
_ALGORITHMS = {entry.class_name: agent_class(name) for name, entry in REGISTRY.items()}
globals().update(_ALGORITHMS)

__all__ = [
    "DEFAULTS",
    "ProportionalController",
    "RECORD_KEYS",
    "AgentDefaults",
    "ConstantSchedule",
    "LinearSchedule",
    "TabularAgent",
    "load_agent",
    *_ALGORITHMS,
]


def __getattr__(name: str):
    # lazy: the controller module is only imported when it is asked for
    if name == "ProportionalController":
        from delayed_rl.agents.proportional import ProportionalController

        return ProportionalController
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""Tabular agents with a stable-baselines3-like API.

- :class:`QLearning`: Q-learning (rewards credited to the step that just happened);
- :class:`FixedDelayQLearning`: Q-learning that assumes a constant delay ``k``;
- :class:`MultipleModelQLearning` (alias :class:`MMQ`): Multiple Model Q-learning, which learns
  over parallel delay hypotheses (thesis section 3.2);
- :class:`ExpectedCreditQLearning`: Q-learning that spreads each received reward over the past
  steps by a known delay distribution's pmf (the cheap anonymous baseline);
- :class:`OracleQLearning`: Q-learning that credits each reward to the transition that emitted
  it, read from ``RewardDelay(..., record_arrivals=True)`` (the non-anonymous upper bound);
- :class:`DeconvolutionQLearning` (alias :class:`DeconvQ`): Q-learning on mean rewards estimated
  by deconvolving the delayed reward stream, with the delay known or learned;
- :func:`load_agent`: load any of them from a file, whatever its class;
- ``ProportionalController`` (thesis Eqs. 5.8–5.9), imported from
  :mod:`delayed_rl.agents.proportional` on first access.

All share :class:`~delayed_rl.agents.base.TabularAgent`: ``learn``, ``predict``, ``update``,
``save``/``load``, ``get_env``/``set_env``, ``logger``, and SB3 callbacks.
"""

from delayed_rl.agents.base import RECORD_KEYS, TabularAgent, load_agent
from delayed_rl.agents.deconvolution import DeconvolutionQLearning, DeconvQ
from delayed_rl.agents.expected_credit import ExpectedCreditQLearning
from delayed_rl.agents.hyperparameters import DEFAULTS, AgentDefaults
from delayed_rl.agents.mmq import MMQ, MultipleModelQLearning
from delayed_rl.agents.oracle import OracleQLearning
from delayed_rl.agents.qlearning import FixedDelayQLearning, QLearning
from delayed_rl.agents.schedules import ConstantSchedule, LinearSchedule

__all__ = [
    "DEFAULTS",
    "MMQ",
    "ProportionalController",
    "RECORD_KEYS",
    "AgentDefaults",
    "ConstantSchedule",
    "DeconvQ",
    "DeconvolutionQLearning",
    "ExpectedCreditQLearning",
    "FixedDelayQLearning",
    "LinearSchedule",
    "MultipleModelQLearning",
    "OracleQLearning",
    "QLearning",
    "TabularAgent",
    "load_agent",
]


def __getattr__(name: str):
    # lazy: the controller module is only imported when it is asked for
    if name == "ProportionalController":
        from delayed_rl.agents.proportional import ProportionalController

        return ProportionalController
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

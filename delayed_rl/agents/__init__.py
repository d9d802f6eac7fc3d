"""Tabular agents with a stable-baselines3-like API (``learn``, ``predict``, ``save``/``load``).

Every agent of :data:`~delayed_rl.agents.registry.REGISTRY` is exported here by its class name
(``delayed-rl list`` prints them; the docs' agents page says which to use when), e.g.
:class:`MultipleModelQLearning`, the thesis's agent, over parallel delay hypotheses, and
:class:`DeconvolutionQLearning`, Q-learning on deconvolved mean rewards. Also
:func:`load_agent`, and ``ProportionalController`` (thesis Eqs. 5.8–5.9, imported on first use).

All share :class:`~delayed_rl.agents.common.base.TabularAgent`; the rules are written plainly in
:mod:`delayed_rl.agents.reference` and stated on the docs' agents page (``docs/agents.md``).
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

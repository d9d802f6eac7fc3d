"""delayed-rl: stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning.

Importing the package registers its env ids (``gym.make("delayed_rl/GridWorld-9x9-v0")``) and
nothing else; the agents named here are imported on first use
(``delayed_rl.MultipleModelQLearning``), so that ``import delayed_rl.wrappers`` stays as light
as the wrappers.
"""

from typing import Any

from delayed_rl import envs as _envs  # noqa: F401  (registers the env ids)
from delayed_rl._version import __version__

__all__ = ["FixedDelayQLearning", "MultipleModelQLearning", "QLearning", "__version__"]
#: The thesis's agents, as shortcuts (every agent is in :mod:`delayed_rl.agents`, from its registry).
_SHORTCUTS = ("FixedDelayQLearning", "MultipleModelQLearning", "QLearning")


def __getattr__(name: str) -> Any:
    """The agents of :data:`__all__`, imported from :mod:`delayed_rl.agents` on first use."""
    if name in _SHORTCUTS:
        from delayed_rl import agents

        return getattr(agents, name)
    raise AttributeError(f"module 'delayed_rl' has no attribute {name!r}")

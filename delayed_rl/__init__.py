"""delayed-rl: stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning."""

from delayed_rl import envs as _envs  # noqa: F401  (registers the env ids)
from delayed_rl._version import __version__
from delayed_rl.agents import (
    MMQ,
    FixedDelayQLearning,
    MultipleModelQLearning,
    QLearning,
)

__all__ = ["MMQ", "FixedDelayQLearning", "MultipleModelQLearning", "QLearning", "__version__"]

"""delayed-rl: stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning."""

from delayed_rl import envs as _envs  # noqa: F401  (registers the env ids)

__version__ = "0.1.0"
from delayed_rl.agents import (  # noqa: E402  (after the env registration above)
    MMQ,
    FixedDelayQLearning,
    MultipleModelQLearning,
    QLearning,
)

__all__ = ["MMQ", "FixedDelayQLearning", "MultipleModelQLearning", "QLearning", "__version__"]

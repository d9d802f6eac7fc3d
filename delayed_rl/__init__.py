"""delayed-rl: stochastically delayed rewards for Gymnasium, and Multiple Model Q-learning."""

from delayed_rl import envs as _envs  # noqa: F401  (registers the env ids)

__version__ = "0.1.0"

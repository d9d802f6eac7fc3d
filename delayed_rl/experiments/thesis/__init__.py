"""The thesis's own experiments, one module each (their names: :data:`delayed_rl.experiments.NAMES`)."""

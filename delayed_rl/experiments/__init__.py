"""The thesis experiments, one module each, on the shared runner (:mod:`.runner`)."""

from __future__ import annotations

import importlib

from delayed_rl._validation import check_choice
from delayed_rl.experiments.pool import run_experiment, run_experiments
from delayed_rl.experiments.runner import Config, Experiment, Summary

_MODULES = {
    "delay-sweep": "delay_sweep",
    "world-size": "world_size",
    "estimate-error": "estimate_error",
    "mmq-gridworld": "mmq_gridworld",
    "roulette": "roulette",
    "controllers": "controllers",
    "linefollow": "linefollow",
    "anonymous-delay": "anonymous_delay",
    "future-work": "future_work",
    "linefollow-deconv": "linefollow_deconv",
    "real-robot": "real_robot",
}
#: The experiments' names, as ``delayed-rl bench NAME`` takes them.
NAMES = tuple(_MODULES)


def get_experiment(name: str) -> Experiment:
    """The experiment called ``name`` (one of :data:`NAMES`), its module imported on demand.

    Raises:
        TypeError: ``name`` is not a string.
        ValueError: ``name`` is not one of :data:`NAMES`.
    """
    check_choice("experiment", name, NAMES)
    return importlib.import_module(f"delayed_rl.experiments.{_MODULES[name]}").EXPERIMENT


__all__ = [
    "NAMES",
    "Config",
    "Experiment",
    "Summary",
    "get_experiment",
    "run_experiment",
    "run_experiments",
]

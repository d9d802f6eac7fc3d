"""The experiments, one module each: the thesis's (:mod:`.thesis`) and beyond it (:mod:`.beyond`).

Each module defines its ``EXPERIMENT`` on the framework (:mod:`.framework`: the experiment type, the pool,
the claims' rules, the figures and the pieces several experiments share); no experiment module
imports another. :func:`get_experiment` imports the one asked for.
"""

from __future__ import annotations

import importlib

from delayed_rl._validation import check_choice
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary
from delayed_rl.experiments.framework.pool import run_experiment, run_experiments

#: Each experiment's module, below this package, by the name ``delayed-rl bench NAME`` takes.
_MODULES = {
    "delay-sweep": "thesis.delay_sweep",
    "world-size": "thesis.world_size",
    "estimate-error": "thesis.estimate_error",
    "mmq-gridworld": "thesis.mmq_gridworld",
    "roulette": "thesis.roulette",
    "controllers": "thesis.controllers",
    "linefollow": "thesis.linefollow",
    "anonymous-delay": "beyond.anonymous_delay",
    "future-work": "beyond.future_work",
    "linefollow-deconv": "beyond.linefollow_deconv",
    "real-robot": "thesis.real_robot",
    "deep-rl": "beyond.deep_rl",
    "late-observations": "beyond.late_observations",
    "multiagent-gridworld": "beyond.multiagent_gridworld",
    "multiagent-pursuit": "beyond.multiagent_pursuit",
}
#: The experiments' names, as ``delayed-rl bench NAME`` takes them.
NAMES = tuple(_MODULES)
#: Experiments too long for the default ``delayed-rl bench all`` (``bench all --long`` runs them).
LONG_NAMES = ("deep-rl", "late-observations", "multiagent-gridworld", "multiagent-pursuit")
#: What ``delayed-rl bench all`` runs: every experiment but :data:`LONG_NAMES`.
DEFAULT_NAMES = tuple(name for name in NAMES if name not in LONG_NAMES)


def get_experiment(name: str) -> Experiment:
    """The experiment called ``name`` (one of :data:`NAMES`), its module imported on demand.

    Raises:
        TypeError: ``name`` is not a string.
        ValueError: ``name`` is not one of :data:`NAMES`.
    """
    check_choice("experiment", name, NAMES)
    return importlib.import_module(f"delayed_rl.experiments.{_MODULES[name]}").EXPERIMENT


__all__ = [
    "DEFAULT_NAMES",
    "LONG_NAMES",
    "NAMES",
    "Config",
    "Experiment",
    "Summary",
    "get_experiment",
    "run_experiment",
    "run_experiments",
]

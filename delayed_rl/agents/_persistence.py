"""An agent's state to and from a model file's contents; the registry of agent classes.

:mod:`~delayed_rl.agents.save_util` reads and writes the files; this module decides what an
agent puts in them (hyper-parameters, spaces, learned arrays, random streams, training clock) and
rebuilds an agent from them. Every :class:`~delayed_rl.agents.base.TabularAgent` subclass is
registered here under ``"module.QualName"`` when it is defined, so a file names its class and
loading finds it again, a user's subclass included.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from delayed_rl._validation import check_int
from delayed_rl._version import __version__
from delayed_rl.agents import save_util
from delayed_rl.agents._statistics import TrainingStatistics
from delayed_rl.agents.schedules import schedule_from_json

__all__ = ["AGENT_CLASSES", "class_key", "load_as", "save"]

AGENT_CLASSES: dict[str, type] = {}
"""Every agent class defined in this process, by :func:`class_key`."""


def class_key(cls: type) -> str:
    """``"module.QualName"``: how a model file names the class that saved it."""
    return f"{cls.__module__}.{cls.__qualname__}"


def save(agent: Any, path: str | Path) -> Path:
    """Write ``agent`` to ``path`` (see ``TabularAgent.save``); return the path written."""
    rng_state, rng_block = agent._uniform.get_state()
    predict_state, predict_block = agent._predict_uniform.get_state()
    metadata = {
        "class": class_key(type(agent)),
        "library_version": __version__,
        "hyperparameters": agent._get_hyperparameters(),
        "observation_space": save_util.space_to_json(agent.observation_space),
        "action_space": save_util.space_to_json(agent.action_space),
        "num_timesteps": int(agent.num_timesteps),
        "progress_remaining": float(agent._progress_remaining),
        "exploration_rate": float(agent.exploration_rate),
        "rng_state": rng_state,
        "predict_rng_state": predict_state,
    }
    arrays = {
        **agent._get_state_arrays(),
        "rng_block": rng_block,
        "predict_rng_block": predict_block,
        "acting_counts": np.asarray(agent._statistics.acting_counts, dtype=np.int64),
    }
    return save_util.write_model_file(path, metadata, arrays)


def load_as(cls: type, path: str | Path, custom_objects: dict[str, Any] | None) -> tuple[Any, str]:
    """Rebuild the agent saved at ``path``, which must be a ``cls`` (or a subclass).

    Returns:
        The agent (without an env) and the file's name, for messages.

    Raises:
        FileNotFoundError: there is no such file.
        ValueError: the file is unreadable, malformed, or holds another class.
    """
    path = save_util.resolve_model_path(path)
    where = str(path)
    metadata, arrays = save_util.read_model_file(path)
    saved = _saved_class(metadata.get("class"), where)
    if not issubclass(saved, cls):
        raise ValueError(
            f"{where} holds a {saved.__name__} model, not a {cls.__name__}: load it with "
            f"{saved.__name__}.load() or delayed_rl.agents.load_agent()"
        )
    hyperparameters = _hyperparameters(saved, metadata, where, custom_objects or {})
    agent = saved.__new__(saved)
    try:
        agent._set_hyperparameters(**hyperparameters)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{where}: invalid hyper-parameters: {error}") from None
    agent._set_spaces(
        save_util.space_from_json(metadata.get("observation_space"), "observation_space", where),
        save_util.space_from_json(metadata.get("action_space"), "action_space", where),
    )
    agent._setup_model()
    agent._set_state_arrays(arrays, where)
    _restore_clock(agent, metadata, arrays, where)
    agent.env = None
    agent._vec_env = None
    agent._episode_ended = True
    return agent, where


def _saved_class(name: Any, where: str) -> type:
    """The agent class a model file names.

    Files written before classes were named with their module hold the bare class name; it is
    looked up among the library's own agents.

    Raises:
        ValueError: no class of that name is defined in this process.
    """
    if name in AGENT_CLASSES:
        return AGENT_CLASSES[name]
    builtin = [
        cls
        for key, cls in AGENT_CLASSES.items()
        if key.startswith("delayed_rl.") and cls.__name__ == name
    ]
    if len(builtin) == 1:
        return builtin[0]
    raise ValueError(
        f"{where} holds an unknown agent class {name!r}: import the module that defines it "
        "before loading"
    )


def _hyperparameters(
    cls: type, metadata: dict[str, Any], where: str, custom_objects: dict[str, Any]
) -> dict[str, Any]:
    """The constructor arguments to rebuild with: the saved ones, then ``custom_objects``.

    Raises:
        ValueError: the saved ones are malformed, or ``custom_objects`` names an unknown one.
    """
    names = cls._hyperparameter_names
    try:
        saved = dict(metadata["hyperparameters"])
        unknown = set(saved) - set(names)
        if unknown:
            raise ValueError(f"unknown hyper-parameters {sorted(unknown)}")
        saved["learning_rate"] = schedule_from_json(saved["learning_rate"])
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: malformed hyper-parameters in the metadata: {error}") from None
    unknown = set(custom_objects) - set(names)
    if unknown:
        raise ValueError(f"custom_objects may override {list(names)}, got {sorted(unknown)}")
    return {**saved, **custom_objects}


def _restore_clock(
    agent: Any, metadata: dict[str, Any], arrays: dict[str, np.ndarray], where: str
) -> None:
    """Restore the step count, the schedules' clock, the random streams and the acting counts."""
    try:
        agent.num_timesteps = check_int("num_timesteps", metadata["num_timesteps"], 0)
        agent._progress_remaining = float(metadata["progress_remaining"])
        agent.exploration_rate = float(metadata["exploration_rate"])
        agent._alpha = agent._current_learning_rate()
        for stream, state, block in (
            (agent._uniform, "rng_state", "rng_block"),
            (agent._predict_uniform, "predict_rng_state", "predict_rng_block"),
        ):
            values = arrays[block]
            if values.dtype != np.float64 or values.ndim != 1:
                raise ValueError(f"{block} must be a 1-D float64 array")
            stream.set_state(metadata[state], values)
        counts = arrays["acting_counts"]
        if counts.shape != (agent.n_models,) or counts.dtype.kind != "i":
            raise ValueError("acting_counts does not match the number of delay models")
        agent._statistics = TrainingStatistics(agent.n_models, agent.num_timesteps)
        agent._statistics.acting_counts = counts.tolist()
        agent._statistics.logged_counts = counts.tolist()
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: malformed training state: {error}") from None

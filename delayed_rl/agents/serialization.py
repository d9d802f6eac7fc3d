"""Saving agents to ``.npz`` archives and loading them back, without pickles.

A model file is a NumPy ``.npz`` archive holding the learned arrays (``q_table``,
``delay_estimates``, the random streams' pending numbers, the acting-model counters) and one
string array, ``metadata``: JSON with the class, hyper-parameters, spaces, training clock, random
generator states, the library version and a format marker. It is read with
``allow_pickle=False``, so loading a model file can never run code.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["FORMAT", "FORMAT_VERSION", "load_agent", "save_agent"]

FORMAT = "delayed_rl.agent"
FORMAT_VERSION = 1


def _agent_classes() -> dict[str, type]:
    from delayed_rl.agents.mmq import MultipleModelQLearning
    from delayed_rl.agents.qlearning import FixedDelayQLearning, QLearning

    return {cls.__name__: cls for cls in (QLearning, FixedDelayQLearning, MultipleModelQLearning)}


def save_agent(agent: Any, path: str | Path) -> Path:
    """Write ``agent`` to ``path`` (``.npz`` appended when the path has no suffix)."""
    import delayed_rl

    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(".npz")
    rng_state, rng_block = agent._uniform.get_state()
    predict_state, predict_block = agent._predict_uniform.get_state()
    metadata = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "class": type(agent).__name__,
        "library_version": delayed_rl.__version__,
        "hyperparameters": agent._get_hyperparameters(),
        "observation_space": _space_to_json(agent.observation_space),
        "action_space": _space_to_json(agent.action_space),
        "num_timesteps": int(agent.num_timesteps),
        "progress_remaining": float(agent._progress_remaining),
        "exploration_rate": float(agent.exploration_rate),
        "rng_state": rng_state,
        "predict_rng_state": predict_state,
    }
    arrays = agent._get_state_arrays()
    arrays.update(
        rng_block=rng_block,
        predict_rng_block=predict_block,
        acting_counts=np.asarray(agent._acting_counts, dtype=np.int64),
        metadata=np.array(json.dumps(metadata)),
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as file:
        np.savez_compressed(file, **arrays)
    return path


def _space_to_json(space: spaces.Discrete) -> dict[str, Any]:
    return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}


def _space_from_json(data: Any, name: str, where: str) -> spaces.Discrete:
    if (
        not isinstance(data, dict)
        or data.get("type") != "Discrete"
        or not isinstance(data.get("n"), int)
        or not isinstance(data.get("start"), int)
        or data["n"] < 1
    ):
        raise ValueError(f"{where}: malformed {name} in the metadata: {data!r}")
    return spaces.Discrete(data["n"], start=data["start"])


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise _unreadable(path, error) from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError(
            f"{path} is not a delayed-rl model file: it holds a single .npy array, not an .npz "
            "archive"
        )
    try:
        with data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as error:
        raise _unreadable(path, error) from None


def _unreadable(path: Path, error: Exception) -> ValueError:
    return ValueError(
        f"{path} is not a readable delayed-rl model file (.npz archive read with "
        f"allow_pickle=False): {error}"
    )


def load_agent(
    path: str | Path,
    env: gym.Env | str | None = None,
    custom_objects: dict[str, Any] | None = None,
    expected_cls: type | None = None,
) -> Any:
    """Load the agent that :func:`save_agent` wrote to ``path``.

    Args:
        path: the file; ``path + ".npz"`` is tried when ``path`` does not exist.
        env: the env to train on next (its spaces must match), or ``None``.
        custom_objects: constructor arguments to override (e.g. a ``learning_rate`` schedule).
        expected_cls: the class that must have been saved (``None``: any delayed-rl agent).

    Raises:
        FileNotFoundError: neither ``path`` nor ``path.npz`` exists.
        ValueError: the file is corrupt, not a delayed-rl model, holds another class, or ``env``'s
            spaces differ from the saved ones (the message names the file and the mismatch).
    """
    path = Path(path)
    if not path.exists() and path.with_name(path.name + ".npz").exists():
        path = path.with_name(path.name + ".npz")
    if not path.exists():
        raise FileNotFoundError(f"no model file at {path} (nor {path}.npz)")
    where = str(path)
    arrays = _read_arrays(path)
    metadata = _read_metadata(arrays, where)
    classes = _agent_classes()
    name = metadata.get("class")
    if expected_cls is not None and name == expected_cls.__name__:
        cls = expected_cls
    elif expected_cls is not None and expected_cls.__name__ != "TabularAgent":
        raise ValueError(
            f"{where} holds a {name} model, not a {expected_cls.__name__}: load it with "
            f"{name}.load()"
        )
    elif name in classes:
        cls = classes[name]
    else:
        raise ValueError(f"{where} holds an unknown agent class {name!r}")
    observation_space = _space_from_json(
        metadata.get("observation_space"), "observation_space", where
    )
    action_space = _space_from_json(metadata.get("action_space"), "action_space", where)

    from delayed_rl.agents.schedules import schedule_from_json

    try:
        hyperparameters = dict(metadata["hyperparameters"])
        unknown = set(hyperparameters) - set(cls._hyperparameter_names)
        if unknown:
            raise ValueError(f"unknown hyper-parameters {sorted(unknown)}")
        hyperparameters["learning_rate"] = schedule_from_json(hyperparameters["learning_rate"])
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: malformed hyper-parameters in the metadata: {error}") from None
    if custom_objects:
        unknown = set(custom_objects) - set(cls._hyperparameter_names)
        if unknown:
            raise ValueError(
                f"custom_objects may override {list(cls._hyperparameter_names)}, got "
                f"{sorted(unknown)}"
            )
        hyperparameters.update(custom_objects)

    agent = cls.__new__(cls)
    try:
        agent._set_hyperparameters(**hyperparameters)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{where}: invalid hyper-parameters: {error}") from None
    agent._set_spaces(observation_space, action_space)
    agent._setup_model()
    agent._reset_statistics()
    agent._set_state_arrays(arrays, where)
    _restore_clock(agent, metadata, arrays, where)
    agent.env = None
    agent._vec_env = None
    agent._episode_open = False
    if env is not None:
        try:
            agent.set_env(env)
        except ValueError as error:
            raise ValueError(f"cannot load {where} into this env: {error}") from None
    return agent


def _read_metadata(arrays: dict[str, np.ndarray], where: str) -> dict[str, Any]:
    raw = arrays.get("metadata")
    if raw is None or raw.shape != () or raw.dtype.kind != "U":
        raise ValueError(
            f"{where} is not a delayed-rl model file: it has no metadata string (arrays: "
            f"{sorted(arrays)})"
        )
    try:
        metadata = json.loads(str(raw))
    except json.JSONDecodeError as error:
        raise ValueError(f"{where}: the metadata is not valid JSON: {error}") from None
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT:
        raise ValueError(
            f"{where} is not a delayed-rl model file (its metadata lacks format={FORMAT!r})"
        )
    version = metadata.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise ValueError(
            f"{where} has model format version {version!r}; this delayed-rl reads versions up "
            f"to {FORMAT_VERSION} (upgrade delayed-rl)"
        )
    return metadata


def _restore_clock(
    agent: Any, metadata: dict[str, Any], arrays: dict[str, np.ndarray], where: str
) -> None:
    try:
        num_timesteps = metadata["num_timesteps"]
        if not isinstance(num_timesteps, int) or num_timesteps < 0:
            raise ValueError(f"num_timesteps must be an integer >= 0, got {num_timesteps!r}")
        agent.num_timesteps = num_timesteps
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
        if counts.shape != (len(agent._acting_counts),) or counts.dtype.kind != "i":
            raise ValueError("acting_counts does not match the number of delay models")
        agent._acting_counts = counts.tolist()
        agent._log_counts = list(agent._acting_counts)
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: malformed training state: {error}") from None

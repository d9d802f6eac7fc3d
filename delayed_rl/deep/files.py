"""Reading a reward model file, every part checked before it is used.

The file (:meth:`~delayed_rl.deep.reward_model.RewardModel.save`) is a zip of
``reward_model.json``, ``weights.pt`` and, once the model has seen a step, ``history.npz``. The
JSON names the class (one of the library's) and its settings, which go through the class's own
constructor checks; the tensors are read with ``torch.load(weights_only=True)`` and must match
the model's names and shapes and be finite; the arrays are read without pickle and must have the
history's shapes, dtypes and values (actions and observations inside their spaces).
"""

from __future__ import annotations

import inspect
import io
import json
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from delayed_rl.deep.encoding import SpaceEncoding
from delayed_rl.deep.history import TransitionHistory
from delayed_rl.deep.reward_model import FORMAT, HISTORY_ARRAYS, MAX_MEMBER_BYTES, RewardModel

__all__ = ["load_reward_model", "make_reward_model"]


def _classes() -> dict[str, type[RewardModel]]:
    """The reward model classes, by name (:data:`~delayed_rl.deep.REWARD_MODELS`)."""
    import delayed_rl.deep as deep

    return {name: getattr(deep, name) for name in deep.REWARD_MODELS}


def make_reward_model(spec: Any, observation_space: Any, action_space: Any) -> RewardModel:
    """The reward model ``spec`` describes, for these spaces.

    ``spec`` is a reward model (returned as it is, after its spaces are checked), or a mapping
    ``{"type": <class name>, <setting>: <value>, ...}``: one of the library's reward models
    (``DeconvolutionRewardModel``, ``ReturnDecompositionRewardModel``, ``ReturnRegressionRewardModel``) and
    its keyword arguments, as a hyperparameter file writes it (rl-zoo3's YAML, say). A model
    made from a mapping without a ``seed`` takes one from the algorithm whose buffer makes it
    (:mod:`delayed_rl.deep.binding`).

    Raises:
        TypeError: ``spec`` is neither, or ``type`` is not a string; a setting the class does not
            take; a setting's type (the class's own checks).
        ValueError: an unknown ``type``; a setting's value (the class's own checks); a model
            whose spaces are not these.
    """
    if isinstance(spec, RewardModel):
        for name, space, encoding in (
            ("observation_space", observation_space, spec.observations),
            ("action_space", action_space, spec.actions),
        ):
            if encoding.to_dict() != SpaceEncoding(name, space).to_dict():
                raise ValueError(
                    f"reward_model was made for the {name} {encoding.space}, the buffer's is "
                    f"{space} (SB3 moves an image's channels first: make the model for "
                    "VecTransposeImage.transpose_space(env.observation_space), from "
                    "stable_baselines3.common.vec_env, or give a mapping)"
                )
        return spec
    if not isinstance(spec, dict):
        raise TypeError(
            "reward_model must be a delayed_rl.deep reward model or a mapping {'type': <class "
            f"name>, <setting>: <value>, ...}}, got {spec!r} ({type(spec).__name__})"
        )
    settings = dict(spec)
    kind = settings.pop("type", None)
    classes = _classes()
    if not isinstance(kind, str):
        raise TypeError(f"reward_model's 'type' must be a class name (a string), got {kind!r}")
    if kind not in classes:
        raise ValueError(f"reward_model's 'type' must be one of {sorted(classes)}, got {kind!r}")
    unknown = sorted(set(settings) - set(_setting_names(classes[kind])))
    if unknown:
        raise TypeError(
            f"reward_model's settings {unknown} are not {kind}'s: it takes "
            f"{sorted(_setting_names(classes[kind]))}"
        )
    return classes[kind](observation_space, action_space, **settings)


def _setting_names(kind: type[RewardModel]) -> tuple[str, ...]:
    """The keyword settings ``kind`` takes (its own, then every reward model's)."""
    parameters = inspect.signature(RewardModel.__init__).parameters
    common = tuple(name for name, p in parameters.items() if p.kind is p.KEYWORD_ONLY)
    return (*kind.own_settings, *common)


def _member(archive: zipfile.ZipFile, name: str, path: Path) -> bytes | None:
    try:
        info = archive.getinfo(name)
    except KeyError:
        return None
    if info.file_size > MAX_MEMBER_BYTES:
        raise ValueError(f"{path}: {name} is {info.file_size} bytes, over {MAX_MEMBER_BYTES.text}")
    return archive.read(name)


def load_reward_model(path: str | Path) -> RewardModel:
    """The model in the file at ``path`` (see the module docstring for the checks).

    Raises:
        ValueError: the file, or a part of it, is not what a reward model file holds.
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            header_bytes = _member(archive, "reward_model.json", path)
            weights = _member(archive, "weights.pt", path)
            arrays = _member(archive, "history.npz", path)
    except (zipfile.BadZipFile, OSError, EOFError) as error:
        raise ValueError(f"{path} is not a reward model file: {error}") from None
    if header_bytes is None or weights is None:
        raise ValueError(
            f"{path} is not a reward model file: reward_model.json or weights.pt missing"
        )
    try:
        header = json.loads(header_bytes)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: reward_model.json is not JSON: {error}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        declared = header.get("format") if isinstance(header, dict) else None
        raise ValueError(
            f"{path}: reward_model.json does not declare format {FORMAT!r}, got {declared!r} "
            "(earlier formats were written by earlier versions of delayed-rl; this one reads "
            "its own only)"
        )
    name = header.get("class")
    kind = _classes().get(name) if isinstance(name, str) else None
    if kind is None:
        raise ValueError(f"{path}: unknown reward model class {header.get('class')!r}")
    observations = SpaceEncoding.from_dict("observation_space", header.get("observation_space"))
    actions = SpaceEncoding.from_dict("action_space", header.get("action_space"))
    settings = header.get("settings")
    if not isinstance(settings, dict):
        raise ValueError(f"{path}: settings must be a JSON object")
    try:
        model = kind(observations.space, actions.space, **settings)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path}: bad settings: {error}") from None
    missing = sorted(set(model.settings()) - set(settings))
    if missing:
        raise ValueError(f"{path}: bad settings: {', '.join(missing)} missing")
    _load_tensors(model, weights, path)
    _load_counters(model, header, arrays, path)
    return model


def _load_tensors(model: RewardModel, weights: bytes, path: Path) -> None:
    try:
        tensors = torch.load(io.BytesIO(weights), weights_only=True)
        network, extra = tensors["network"], tensors["extra"]
        for name, value in [*network.items(), *extra.items()]:
            if not torch.is_tensor(value) or not torch.isfinite(value).all():
                raise ValueError(f"tensor {name} is not a finite tensor")
        expected = model._extra_state()
        if set(extra) != set(expected) or any(
            extra[name].shape != expected[name].shape for name in expected
        ):
            raise ValueError("the learned delay's tensors do not match the settings")
        model.network.load_state_dict(network, strict=True)
        model._load_extra_state(extra)
        _load_optimizer(model.optimizer, tensors["optimizer"])
    except (
        RuntimeError,
        KeyError,
        TypeError,
        ValueError,
        EOFError,
        AttributeError,
        pickle.UnpicklingError,
    ) as error:
        raise ValueError(f"{path}: weights.pt does not fit the model: {error}") from None


def _load_optimizer(optimizer: torch.optim.Optimizer, state: Any) -> None:
    """Load Adam's state, checked: the settings' hyperparameters, finite moments of the right shape.

    torch itself checks only how many parameters each group holds.
    """
    settings = [
        {k: v for k, v in group.items() if k != "params"} for group in optimizer.param_groups
    ]
    optimizer.load_state_dict(state)
    loaded = [{k: v for k, v in group.items() if k != "params"} for group in optimizer.param_groups]
    if loaded != settings:
        raise ValueError(f"the optimizer's settings {loaded} are not the model's {settings}")
    for group in optimizer.param_groups:
        for param in group["params"]:
            for name, value in optimizer.state.get(param, {}).items():
                if not torch.is_tensor(value) or not torch.isfinite(value).all():
                    raise ValueError(f"the optimizer's {name} is not a finite tensor")
                if value.dim() > 0 and value.shape != param.shape:
                    raise ValueError(
                        f"the optimizer's {name} has shape {tuple(value.shape)}, not its "
                        f"parameter's {tuple(param.shape)}"
                    )


def _load_counters(model: RewardModel, header: dict[str, Any], arrays: bytes | None, path: Path):
    counters = header.get("counters")
    try:
        n_envs, steps = int(counters["n_envs"]), int(counters["steps_added"])
        model.updates_taken = int(counters["updates_taken"])
        model.rng.bit_generator.state = header["rng"]
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{path}: bad counters or generator state: {error}") from None
    if min(n_envs, steps, model.updates_taken) < 0:
        raise ValueError(f"{path}: negative counters {counters}")
    if (arrays is None) != (n_envs == 0):
        raise ValueError(f"{path}: history.npz must be there exactly when n_envs > 0")
    model.takes_algorithm_seed = False
    if arrays is None:
        return
    try:
        with np.load(io.BytesIO(arrays), allow_pickle=False) as data:
            loaded = {name: data[name] for name in data.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: history.npz is not readable: {error}") from None
    history = TransitionHistory(
        model.observations,
        model.actions,
        n_envs,
        model.capacity,
        keep_next=model.reads_next_observation,
    )
    expected = {
        **model.observations.arrays(history.obs, "obs"),
        **(
            {}
            if history.next_obs is None
            else model.observations.arrays(history.next_obs, "next_obs")
        ),
        **model.actions.arrays(history.action, "action"),
        **{name: getattr(history, name) for name in HISTORY_ARRAYS},
    }
    unknown = sorted(set(loaded) - set(expected))
    if unknown:
        raise ValueError(f"{path}: history.npz holds unknown arrays {unknown}")
    missing = sorted(set(expected) - set(loaded))
    if missing:
        raise ValueError(f"{path}: history.npz misses arrays {missing}")
    for name, empty in expected.items():
        value = loaded[name]
        if value.shape != empty.shape or value.dtype != empty.dtype:
            raise ValueError(
                f"{path}: history array {name} must be {empty.dtype} of shape {empty.shape}, "
                f"got {value.dtype} of shape {value.shape}"
            )
    obs = model.observations.from_arrays(loaded, "obs")
    action = model.actions.from_arrays(loaded, "action")
    next_obs = (
        model.observations.from_arrays(loaded, "next_obs") if history.next_obs is not None else None
    )
    held = history.rows(max(0, steps - model.capacity), steps)
    count = held.size * n_envs
    model.observations.batch(model.observations.flat(model.observations.take(obs, held)), count)
    if next_obs is not None:
        model.observations.batch(
            model.observations.flat(model.observations.take(next_obs, held)), count
        )
    model.actions.batch(model.actions.flat(model.actions.take(action, held)), count)
    if not np.isfinite(loaded["reward"][held]).all():
        raise ValueError(f"{path}: history rewards must be finite")
    _replay(history, model, (obs, action, next_obs), loaded, steps)
    model.history = history


def _replay(
    history: TransitionHistory,
    model: RewardModel,
    stores: tuple[Any, Any, Any],
    loaded: dict[str, np.ndarray],
    steps: int,
) -> None:
    """Fill ``history`` by adding the held steps again, so its episode index is rebuilt.

    ``stores`` are the loaded observations, actions and next observations (or ``None``).
    """
    obs, action, next_obs = stores
    first = max(0, steps - history.capacity)
    history.steps_added = first
    history._episode_first[:] = first - 1 if first > 0 else 0  # an episode cut off: not whole
    for step in range(first, steps):
        row = step % history.capacity
        history.add(
            model.observations.take(obs, row),
            model.actions.take(action, row),
            loaded["reward"][row],
            loaded["episode_end"][row],
            loaded["undelayed"][row],
            None if next_obs is None else model.observations.take(next_obs, row),
        )
        history.cut(np.flatnonzero(loaded["episode_cut"][row]))

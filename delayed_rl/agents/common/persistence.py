"""An agent's state to and from a model file's contents, copies and pickles; the model-file class table.

:mod:`~delayed_rl.agents.common.save_util` reads and writes the files; this module decides what an
agent puts in them (hyper-parameters, spaces, learned arrays, random streams, training clock) and
rebuilds an agent from them, checking every field with the constructor's own checks before
anything is allocated. Every :class:`~delayed_rl.agents.common.base.TabularAgent` subclass is
registered here under ``"module.QualName"`` when it is defined, so a file names its class and
loading finds it again, a user's subclass included.

It also decides what a copy or a pickle of an agent holds (:class:`CopyProtocol`): everything
but the derived attributes (views of the tables, the ``VecEnv`` view), which are rebuilt; the
env, the compiled run and the logger are kept when they can be copied and dropped otherwise.
"""

from __future__ import annotations

import copy
import pickle
import warnings
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from delayed_rl._validation import check_int, check_limit, check_probability, check_real
from delayed_rl._version import __version__
from delayed_rl.agents.common import save_util
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.agents.common.schedules import schedule_from_json
from delayed_rl.agents.common.statistics import TrainingStatistics
from delayed_rl.agents.common.streams import UniformStream

__all__ = ["AGENT_CLASSES", "CopyProtocol", "check_state_array", "class_key", "load_as", "save"]

AGENT_CLASSES: dict[str, type] = {}
"""Every agent class defined in this process, by :func:`class_key`."""

_METADATA_KEYS = frozenset(
    {
        "format",
        "format_version",
        "class",
        "library_version",
        "hyperparameters",
        "observation_space",
        "action_space",
        "num_timesteps",
        "progress_remaining",
        "exploration_rate",
        "rng_state",
        "predict_rng_state",
    }
)
_STREAMS = (("rng_state", "rng_block"), ("predict_rng_state", "predict_rng_block"))
_SCHEDULE_FIELDS = {"linear": ("start", "end", "end_fraction"), "constant": ("value",)}
_SCHEDULE_FIELDS["callable"] = _SCHEDULE_FIELDS["constant"]  # and its "repr", a string
_OPTIONAL = ("env", "_compiled", "_logger")
"""What a copy keeps when it can be copied, and drops (``None``) otherwise."""


def check_state_array(
    name: str,
    array: Any,
    shape: tuple[int, ...],
    dtype: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    note: str = "",
) -> np.ndarray:
    """``array`` (native byte order) after checking its shape, dtype and values.

    What a model file's state array must be, as the constructed agent has it: exactly ``shape``
    and ``dtype`` (any byte order); for floats, no NaN or infinity; every value in
    ``[low, high]`` (``None``: no bound). The first offending value is shown, with its index.

    Args:
        name: the array's name in the file, for the message.
        array: the array read (``None``: missing).
        shape: the shape the agent expects.
        dtype: the dtype it expects.
        low: the smallest value allowed.
        high: the largest value allowed.
        note: appended to the description of what is allowed (e.g. the limit's name).

    Raises:
        ValueError: ``array`` is missing, of another shape or dtype, or holds a value that is
            not allowed (the message names it).
    """
    dtype, shape = np.dtype(dtype), tuple(shape)
    if (
        not isinstance(array, np.ndarray)
        or array.shape != shape
        or (array.dtype.newbyteorder("=") != dtype)
    ):
        got = (
            "missing"
            if array is None
            else f"{array.dtype} array of shape {array.shape}"
            if isinstance(array, np.ndarray)
            else repr(array)
        )
        raise ValueError(f"{name} must be a {dtype} array of shape {shape}, got {got}")
    array = array.astype(dtype, copy=False)
    allowed = f"{'numbers' if dtype.kind == 'f' else 'values'}{_interval_text(low, high)}{note}"
    if dtype.kind == "f":
        finite = np.isfinite(array)
        if not finite.all():
            raise ValueError(
                f"{name} holds non-finite values ({_first(array, ~finite)}): it must hold "
                f"finite {allowed}"
            )
    outside = np.zeros(array.shape, dtype=bool)
    if low is not None:
        outside |= array < low
    if high is not None:
        outside |= array > high
    if outside.any():
        raise ValueError(f"{name} must hold {allowed}, got {_first(array, outside)}")
    return array


def _interval_text(low: float | None, high: float | None) -> str:
    """``" in [0, 1]"``, ``" >= 0"``, ``" <= 5"`` or ``""`` (integers shown exactly)."""

    def shown(bound: float) -> str:
        return str(bound) if isinstance(bound, (int, np.integer)) else f"{bound:g}"

    if low is not None and high is not None:
        return f" in [{shown(low)}, {shown(high)}]"
    if low is not None:
        return f" >= {shown(low)}"
    return "" if high is None else f" <= {shown(high)}"


def _first(array: np.ndarray, mask: np.ndarray) -> str:
    """The first entry of ``array`` where ``mask`` holds, and its index, for a message."""
    at = np.unravel_index(int(np.argmax(mask)), array.shape)
    index = tuple(int(i) for i in at)
    return f"{array[at].item()!r} at index {index[0] if len(index) == 1 else index}"


def class_key(cls: type) -> str:
    """``"module.QualName"``: how a model file names the class that saved it."""
    return f"{cls.__module__}.{cls.__qualname__}"


# ---------------------------------------------------------------------- model files
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


def load_as(cls: type, path: str | Path, custom_objects: dict[str, Any] | None, env: Any) -> Any:
    """Rebuild the agent saved at ``path``, a ``cls`` (or a subclass), with ``env`` (or none).

    Every metadata field is checked as the constructor checks it, and the arrays' headers
    against the sizes the metadata declares, before the tables are allocated or any array read.

    Raises:
        FileNotFoundError: there is no such file.
        ValueError: the file is unreadable, malformed, or holds another class (one error,
            naming the file and the field), or ``env``'s spaces are not the saved ones.
    """
    path = save_util.resolve_model_path(path)
    with save_util.ModelFile(path) as model:
        where, metadata = model.where, model.metadata
        unknown = set(metadata) - _METADATA_KEYS
        if unknown:
            raise ValueError(f"{where}: unexpected fields {sorted(unknown)} in the metadata")
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
        except (TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"{where}: invalid hyper-parameters: {error}") from None
        agent._set_spaces(
            save_util.space_from_json(
                metadata.get("observation_space"), "observation_space", where
            ),
            save_util.space_from_json(metadata.get("action_space"), "action_space", where),
        )
        _check_headers(model, agent._state_array_specs())
        try:
            agent._check_state_headers(model.headers)
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        try:
            agent._setup_model()
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        arrays = model.read({*agent._get_state_arrays(), "acting_counts", *dict(_STREAMS).values()})
    try:
        agent._set_state_arrays(arrays, where)
    except (KeyError, IndexError, TypeError, ValueError, OverflowError) as error:
        message = str(error)
        raise ValueError(message if where in message else f"{where}: {message}") from None
    _restore_clock(agent, metadata, arrays, where)
    agent.env = None
    agent._vec_env = None
    agent._episode_ended = True
    if env is not None:
        try:
            agent.set_env(env)
        except ValueError as error:
            raise ValueError(f"cannot load {where} into this env: {error}") from None
    return agent


def _check_headers(
    model: save_util.ModelFile, specs: dict[str, tuple[tuple[int, ...], Any]]
) -> None:
    """Check the arrays' headers (shape, dtype) against what the agent expects, before reading.

    ``specs`` (from the agent's ``_state_array_specs``) gives the exact shape and dtype of its
    own arrays; the random blocks are 1-D float64 arrays no longer than a stream's block and the
    acting counts a 1-D int64 array.

    Raises:
        ValueError: an array is missing or declares another shape or dtype (naming it).
    """
    block = UniformStream.BLOCK_SIZE
    expected: dict[str, tuple[Any, Any, str]] = {
        name: (shape, np.dtype(dtype), f"a {np.dtype(dtype)} array of shape {shape}")
        for name, (shape, dtype) in specs.items()
    }
    for _, name in _STREAMS:
        expected[name] = (None, np.dtype(np.float64), f"a 1-D float64 array of <= {block} values")
    expected["acting_counts"] = (None, np.dtype(np.int64), "a 1-D int64 array")
    for name, (shape, dtype, wanted) in expected.items():
        header = model.headers.get(name)
        if header is None:  # which arrays a file needs follows from its class and settings
            raise ValueError(
                f"{model.where}: {name} must be {wanted} (as the file's class and "
                "hyper-parameters call for it), got missing"
            )
        fits = shape == header.shape if shape is not None else len(header.shape) == 1
        if name in dict(_STREAMS).values():
            fits = fits and header.shape[0] <= block
        if not fits or header.dtype.newbyteorder("=") != dtype:
            raise ValueError(f"{model.where}: {name} must be {wanted}, got {header.describe()}")


def _saved_class(name: Any, where: str) -> type:
    """The agent class a model file names (``"module.QualName"``, :func:`class_key`).

    The library's own agents are found by their class name wherever their module is: a file
    naming ``delayed_rl.<any module>.<Name>`` (or the bare ``<Name>``) loads as the library's
    agent class ``<Name>``, so a file saved before a module moved still loads.

    Raises:
        ValueError: no class of that name is defined in this process.
    """
    if not isinstance(name, str):
        raise ValueError(f"{where}: class in the metadata must be a class name, got {name!r}")
    if name in AGENT_CLASSES:
        return AGENT_CLASSES[name]
    bare = name.rsplit(".", 1)[-1] if name.startswith("delayed_rl.") else name
    builtin = [
        cls
        for key, cls in AGENT_CLASSES.items()
        if key.startswith("delayed_rl.") and cls.__name__ == bare
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
        if not isinstance(metadata.get("hyperparameters"), dict):
            raise TypeError(f"expected a dict, got {metadata.get('hyperparameters')!r}")
        saved = dict(metadata["hyperparameters"])
        unknown = set(saved) - set(names)
        if unknown:
            raise ValueError(f"unknown hyper-parameters {sorted(unknown)}")
        missing = set(names) - set(saved) - set(custom_objects)
        missing -= set(getattr(cls, "_optional_hyperparameter_names", ()))
        if missing:
            raise ValueError(f"missing hyper-parameters {sorted(missing)}")
        if "learning_rate" in saved:
            saved["learning_rate"] = _schedule(saved["learning_rate"])
    except (KeyError, TypeError, ValueError, OverflowError) as error:
        raise ValueError(
            f"{where}: malformed hyper-parameters (the metadata's hyperparameters field): {error}"
        ) from None
    unknown = set(custom_objects) - set(names)
    if unknown:
        raise ValueError(f"custom_objects may override {list(names)}, got {sorted(unknown)}")
    return {**saved, **custom_objects}


def _schedule(data: Any) -> Any:
    """The learning rate a file describes, its fields checked (numbers, the known kinds)."""
    kind = data.get("type") if isinstance(data, dict) else None
    fields = _SCHEDULE_FIELDS.get(kind) if isinstance(kind, str) else None
    described = {"type", *fields, *(("repr",) if kind == "callable" else ())} if fields else None
    if described is None or set(data) != described or not isinstance(data.get("repr", ""), str):
        raise ValueError(f"learning_rate must be a schedule description, got {data!r}")
    for name in fields:
        check_real(f"learning_rate's {name}", data[name])
    return schedule_from_json(data)


def _restore_clock(
    agent: Any, metadata: dict[str, Any], arrays: dict[str, np.ndarray], where: str
) -> None:
    """Restore the step count, the schedules' clock, the random streams and the acting counts.

    ``num_timesteps`` and every acting count must lie in ``[0, MAX_TIMESTEPS]``
    (:data:`~delayed_rl.agents.common.python_loop.MAX_TIMESTEPS`), ``progress_remaining`` and
    ``exploration_rate`` in [0, 1], the random blocks in [0, 1).

    Raises:
        ValueError: a field is missing or out of range (the message names the file and it).
    """
    try:
        agent.num_timesteps = check_limit(
            "num_timesteps", check_int("num_timesteps", metadata["num_timesteps"], 0), MAX_TIMESTEPS
        )
        agent._progress_remaining = check_probability(
            "progress_remaining", metadata["progress_remaining"]
        )
        agent.exploration_rate = check_probability("exploration_rate", metadata["exploration_rate"])
        if not isinstance(metadata.get("library_version", ""), str):
            raise TypeError(
                f"library_version must be a string, got {metadata['library_version']!r}"
            )
        agent._alpha = agent._current_learning_rate()
        for stream, (state, block) in zip(
            (agent._uniform, agent._predict_uniform), _STREAMS, strict=True
        ):
            values = arrays[block]
            if not np.all((values >= 0.0) & (values < 1.0)):
                raise ValueError(f"{block} must hold numbers in [0, 1), got {values.max()!r}")
            stream.set_state(_generator_state(state, metadata[state]), values)
        counts = arrays["acting_counts"]
        if counts.shape != (agent.n_models,):
            raise ValueError(
                f"acting_counts must be {agent.n_models} counts (one per delay model), got "
                f"{counts.shape[0]}"
            )
        check_state_array(
            "acting_counts",
            counts,
            (agent.n_models,),
            np.int64,
            0,
            MAX_TIMESTEPS,
            note=f" ({MAX_TIMESTEPS.text})",
        )
        agent._statistics = TrainingStatistics(agent.n_models, agent.num_timesteps)
        agent._statistics.acting_counts = counts.tolist()
        agent._statistics.logged_counts = counts.tolist()
    except (KeyError, TypeError, ValueError, OverflowError) as error:
        raise ValueError(f"{where}: malformed training state: {error}") from None


def _generator_state(name: str, state: Any) -> dict[str, Any]:
    """``state`` after checking that it is a PCG64 generator's, as numpy writes it.

    Raises:
        ValueError: it is not (numpy's own setter could crash or accept nonsense).
    """
    inner = state.get("state") if isinstance(state, dict) else None
    if not (
        isinstance(state, dict)
        and set(state) == {"bit_generator", "state", "has_uint32", "uinteger"}
        and state["bit_generator"] == "PCG64"
        and isinstance(inner, dict)
        and set(inner) == {"state", "inc"}
        and all(type(inner[key]) is int and 0 <= inner[key] < 2**128 for key in inner)
        and inner["inc"] % 2 == 1
        and state["has_uint32"] in (0, 1)
        and type(state["has_uint32"]) is int
        and type(state["uinteger"]) is int
        and 0 <= state["uinteger"] < 2**32
    ):
        raise ValueError(
            f"{name} must be a PCG64 state (bit_generator, state {{state, inc (odd)}} below "
            f"2**128, has_uint32 0 or 1, uinteger below 2**32), got {state!r}"
        )
    return state


# ---------------------------------------------------------------------- copies and pickles
def _own_state(agent: Any) -> dict[str, Any]:
    """The agent's attributes but the derived ones (``type(agent)._derived``)."""
    derived = type(agent)._derived
    return {name: value for name, value in vars(agent).items() if name not in derived}


def _dropped(agent: Any, name: str, error: Exception) -> None:
    """What replaces an optional attribute that cannot be copied: ``None`` (the env: said)."""
    if name == "env":
        warnings.warn(
            f"the env of this {type(agent).__name__} cannot be copied ({error}): the copy has "
            "no env; give it one with set_env(env)",
            UserWarning,
            stacklevel=4,
        )
    return None


def _without_env(state: dict[str, Any]) -> dict[str, Any]:
    """A state whose env was dropped: no compiled run either; the next env is reset."""
    if state.get("env") is None:
        state["_compiled"] = None
        state["_episode_ended"] = True
    return state


class CopyProtocol:
    """How agents copy, pickle and declare their arrays (a base of ``TabularAgent``).

    ``copy.deepcopy`` and ``pickle`` copy every attribute but the :attr:`_derived` ones, which
    :meth:`_rebuild_derived` recomputes on the copy (a view of a table would otherwise become a
    separate array: the copy would learn into one and act from the other). The env, the compiled
    run (``_compiled``: its state and random generator, so the copy continues it identically) and
    the logger are copied when they can be, dropped otherwise (an env with a warning).
    ``copy.copy`` shares every attribute with the original.
    """

    _derived: ClassVar[tuple[str, ...]] = ("_vec_env",)
    """Attributes computed from the others, never copied: subclasses extend it."""

    def _rebuild_derived(self) -> None:
        """Recompute the :attr:`_derived` attributes (after a deep copy or unpickling)."""
        self._vec_env = None

    def _state_array_specs(self) -> dict[str, tuple[tuple[int, ...], Any]]:
        """``{name: (shape, dtype)}`` of the state arrays known before ``_setup_model``.

        That is, from the hyper-parameters and spaces alone: loading checks a file's arrays
        against them before ``_setup_model`` allocates anything. Default: none.
        """
        return {}

    def _check_state_headers(self, headers: dict[str, save_util.ArrayHeader]) -> None:
        """Check the headers of the state arrays whose shape ``_state_array_specs`` cannot fix.

        Called when loading, after ``_state_array_specs``' arrays are checked and before
        anything is allocated or read: an agent whose arrays' lengths depend on what it has seen
        (DeconvQ's statistics) checks their sizes here. Default: nothing to check.

        Raises:
            ValueError: a header declares an array the agent cannot hold (naming it).
        """
        return None

    def __getstate__(self) -> dict[str, Any]:
        state = _own_state(self)
        for name in _OPTIONAL:
            if state.get(name) is not None:
                try:
                    pickle.dumps(state[name], pickle.HIGHEST_PROTOCOL)
                except Exception as error:  # any object may refuse, in its own way
                    state[name] = _dropped(self, name, error)
        return _without_env(state)

    def __setstate__(self, state: dict[str, Any]) -> None:
        derived = type(self)._derived
        vars(self).update({name: value for name, value in state.items() if name not in derived})
        self._rebuild_derived()

    def __deepcopy__(self, memo: dict[int, Any]) -> Any:
        cls = type(self)
        twin = cls.__new__(cls)
        memo[id(self)] = twin
        state = {}
        for name, value in _own_state(self).items():
            if name in _OPTIONAL and value is not None:
                try:
                    value = copy.deepcopy(value, memo)
                except Exception as error:  # any object may refuse, in its own way
                    value = _dropped(self, name, error)
            else:
                value = copy.deepcopy(value, memo)
            state[name] = value
        twin.__setstate__(_without_env(state))
        return twin

    def __copy__(self) -> Any:
        cls = type(self)
        twin = cls.__new__(cls)
        vars(twin).update(vars(self))
        return twin

"""What the vector twins share: sub-env seeds, autoreset modes, reset masks, batches."""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import iterate

from delayed_rl._validation import check_int, check_rewards


def sub_env_seeds(seed: Any, num_envs: int) -> list[int | None]:
    """The seed of each sub-env for ``reset(seed=seed)``, as Gymnasium's vector envs read it.

    ``None`` leaves every sub-env unseeded; an int ``s`` seeds sub-env ``i`` with ``s + i`` (as
    ``SyncVectorEnv`` and ``AsyncVectorEnv`` do); a sequence gives each sub-env its entry
    (``None`` entries: unseeded).

    Raises:
        TypeError: ``seed`` is neither ``None``, an integer nor a sequence, or an entry is
            neither ``None`` nor an integer.
        ValueError: ``seed`` or an entry is negative, or the sequence's length is not
            ``num_envs``.
    """
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, numbers.Integral) and not isinstance(seed, (bool, np.bool_)):
        first = check_int("seed", seed, 0)
        return [first + i for i in range(num_envs)]
    if isinstance(seed, (str, bytes)) or not isinstance(seed, (Sequence, np.ndarray)):
        raise TypeError(
            f"seed must be None, an integer >= 0 or a list of {num_envs} of them, "
            f"got {seed!r} ({type(seed).__name__})"
        )
    if len(seed) != num_envs:
        raise ValueError(
            f"seed must be a list of one seed per sub-env ({num_envs}), got {len(seed)}: {seed!r}"
        )
    return [check_int(f"seed[{i}]", entry, 0, optional=True) for i, entry in enumerate(seed)]


def autoreset_mode(env: VectorEnv) -> AutoresetMode:
    """The autoreset mode of ``env`` (its ``metadata["autoreset_mode"]``, else ``NEXT_STEP``).

    Raises:
        ValueError: the metadata names no ``gymnasium.vector.AutoresetMode``.
    """
    mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
    try:
        return AutoresetMode(mode)
    except ValueError:
        raise ValueError(
            f"unsupported autoreset_mode {mode!r}; supported: {list(AutoresetMode)}"
        ) from None


def reset_mask(options: dict[str, Any] | None, num_envs: int) -> np.ndarray:
    """Which sub-envs a ``reset(options=options)`` resets: ``options["reset_mask"]``, else all.

    Read it before calling the vector env's ``reset``: ``SyncVectorEnv.reset`` pops it.
    """
    if options and "reset_mask" in options:
        return np.array(options["reset_mask"], dtype=bool)
    return np.ones(num_envs, dtype=bool)


def checked_rewards(rewards: Any, num_envs: int, wrapper: str) -> np.ndarray:
    """A vector env's ``rewards`` as float64, checked (:func:`~delayed_rl._validation.check_rewards`).

    Infinite and NaN rewards pass (the pending rewards refuse them with their own message).

    Raises:
        TypeError: ``rewards`` is not a batch of real scalars (the message names ``rewards[i]``,
            its value and what is allowed).
        ValueError: it does not hold ``num_envs`` rewards, or an entry is an integer beyond
            float64's range.
    """
    try:
        return check_rewards("rewards", rewards, num_envs)
    except (TypeError, ValueError) as error:
        raise type(error)(
            f"{error}; the inner vector env returned them, and {wrapper} refuses to delay them"
        ) from None


def unbatch_actions(env: VectorEnv, actions: Any) -> list[Any]:
    """The sub-envs' actions in the batch ``actions`` of ``env`` (``gymnasium.vector.utils.iterate``).

    ``actions`` is a batch of ``env.action_space``: an array with one row per sub-env, and for a
    ``Dict`` (``Tuple``) action space a dict (tuple) of such batches. The actions are not checked
    against the single action space (the caller names each ``actions[i]`` when it checks them).

    Raises:
        TypeError: ``actions`` is not a batch of the action space's form.
        ValueError: it does not hold one action per sub-env.
    """
    allowed = (
        f"a batch of {env.num_envs} actions of {env.single_action_space} (one per sub-env; "
        "a dict or tuple of batches for a Dict or Tuple space)"
    )
    try:
        given = list(iterate(env.action_space, actions))
    except (TypeError, KeyError, IndexError, ValueError) as error:
        kind = TypeError if isinstance(error, TypeError) else ValueError
        raise kind(
            f"actions must be {allowed}, got {actions!r} ({type(actions).__name__}): {error}"
        ) from None
    if len(given) != env.num_envs:
        raise ValueError(f"actions must be {allowed}, got {len(given)}: {actions!r}")
    return given


def reset_inner(
    env: VectorEnv, seed: Any, options: dict[str, Any] | None
) -> tuple[list[int | None], np.ndarray, Any, dict[str, Any]]:
    """Check ``seed`` and the reset mask, then reset the inner vector env ``env``.

    Returns:
        Each sub-env's seed (:func:`sub_env_seeds`), the mask of the sub-envs reset
        (:func:`reset_mask`), and the env's observations and ``info``.

    Raises:
        TypeError, ValueError: as :func:`sub_env_seeds` and :func:`reset_mask`, before the env
            is reset.
    """
    seeds = sub_env_seeds(seed, env.num_envs)
    envs = reset_mask(options, env.num_envs)
    obs, info = env.reset(seed=seed, options=options)
    return seeds, envs, obs, info

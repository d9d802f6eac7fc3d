"""A relabelling buffer and the algorithm that builds or loads it: one seed, one live model.

SB3 hands a buffer no reference to its algorithm; a relabelling buffer finds it as the ``self``
of ``_setup_model`` or ``load_replay_buffer`` on the call stack (:func:`calling_algorithm`).
With it, the buffer seeds its reward model from the algorithm's seed
(:func:`reward_model_seed`), keeps one live model in the algorithm's buffer kwargs across SB3's
save and load, and refuses the n-step settings SB3 would ignore. An off-policy buffer also reads
the ``collect_rollouts`` that calls its ``add()``, to see when the algorithm reset its env in
the middle of episodes (:func:`env_was_reset`). The docs' deep RL page
(``docs/deep_rl.md``, "The buffers, in full") says how.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

__all__ = [
    "REWARD_MODEL_STREAM",
    "calling_algorithm",
    "env_was_reset",
    "remember_episode_starts",
    "reward_model_seed",
]

REWARD_MODEL_STREAM = 0x52574D
"""The spawn key that sets a reward model's seed apart from its algorithm's."""

_MAX_FRAMES = 32
"""How far up the call stack :func:`calling_algorithm` looks."""


def reward_model_seed(algorithm_seed: int) -> int:
    """The seed a reward model takes from an algorithm seeded with ``algorithm_seed``.

    ``np.random.SeedSequence(algorithm_seed, spawn_key=(REWARD_MODEL_STREAM,))``'s first 64-bit
    word, cut to ``0..2**63 − 1``: a function of the algorithm's seed alone, unrelated to the
    global generators SB3 seeds with it.

    Example:
        >>> reward_model_seed(0) == reward_model_seed(0) != reward_model_seed(1)
        True
    """
    sequence = np.random.SeedSequence(int(algorithm_seed), spawn_key=(REWARD_MODEL_STREAM,))
    return int(sequence.generate_state(1, np.uint64)[0] >> np.uint64(1))


def calling_algorithm(*methods: str) -> Any:
    """The SB3 algorithm whose method named in ``methods`` is on the call stack, or ``None``."""
    from stable_baselines3.common.base_class import BaseAlgorithm

    frame = sys._getframe(1)
    for _ in range(_MAX_FRAMES):
        if frame is None:
            return None
        if frame.f_code.co_name in methods:
            candidate = frame.f_locals.get("self")
            if isinstance(candidate, BaseAlgorithm):
                return candidate
        frame = frame.f_back
    return None


def remember_episode_starts(buffer: Any, algorithm: Any) -> None:
    """Note ``algorithm``'s episode-start array as the one ``buffer`` has seen (no reset yet).

    Called when an algorithm builds or loads the buffer (:func:`env_was_reset`).
    """
    buffer._episode_starts_seen = algorithm._last_episode_starts


def env_was_reset(buffer: Any) -> bool:
    """Whether the off-policy algorithm adding to ``buffer`` reset its env since the buffer's last call.

    SB3's ``_setup_learn`` resets the env when ``learn()`` starts with
    ``reset_num_timesteps=True`` (the default) or with no last observation (after ``load`` with
    ``force_reset=True``, the default, or ``set_env``), and then, only then, gives the
    algorithm a new ``_last_episode_starts`` array (an off-policy algorithm never replaces it
    otherwise). The buffer keeps the array it last saw (:func:`remember_episode_starts` when
    an algorithm builds or loads it): a different one means a reset. Outside an algorithm's
    ``collect_rollouts`` (a buffer filled by hand) it is ``False``.
    """
    algorithm = calling_algorithm("collect_rollouts")
    if algorithm is None:
        return False
    starts = algorithm._last_episode_starts
    if starts is getattr(buffer, "_episode_starts_seen", None):
        return False
    buffer._episode_starts_seen = starts
    return True


def kwargs_attribute(buffer: Any) -> str:
    """The algorithm's attribute that holds ``buffer``'s keyword arguments."""
    from stable_baselines3.common.buffers import RolloutBuffer

    return "rollout_buffer_kwargs" if isinstance(buffer, RolloutBuffer) else "replay_buffer_kwargs"


def bind(buffer: Any, algorithm: Any) -> None:
    """Seed ``buffer``'s model from ``algorithm`` where it takes that seed; put it in the kwargs."""
    model = buffer.reward_model
    if model.takes_algorithm_seed and algorithm.seed is not None:
        model.reseed(reward_model_seed(algorithm.seed))
    _hold(algorithm, kwargs_attribute(buffer), model)


def adopt(buffer: Any, algorithm: Any) -> None:
    """After ``load_replay_buffer``: the kwargs' model takes the loaded model's state, and trains.

    Raises:
        ValueError: the kwargs' model was made for other spaces than the loaded one.
    """
    attribute = kwargs_attribute(buffer)
    held = (getattr(algorithm, attribute, None) or {}).get("reward_model")
    loaded = buffer.reward_model
    if held is loaded:
        return
    if type(held) is type(loaded):
        for name in ("observations", "actions"):
            if getattr(held, name).to_dict() != getattr(loaded, name).to_dict():
                raise ValueError(
                    f"the loaded buffer's reward model was made for the "
                    f"{getattr(loaded, name).name} {getattr(loaded, name).space}, the "
                    f"algorithm's for {getattr(held, name).space}"
                )
        held.__dict__.clear()
        held.__dict__.update(loaded.__dict__)
        buffer.reward_model = held
    else:
        _hold(algorithm, attribute, loaded)


def _hold(algorithm: Any, attribute: str, model: Any) -> None:
    kwargs = getattr(algorithm, attribute, None) or {}
    if kwargs.get("reward_model") is not model:
        setattr(algorithm, attribute, {**kwargs, "reward_model": model})

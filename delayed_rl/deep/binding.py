"""A relabelling buffer and the algorithm that builds or loads it: one seed, one live model.

SB3 hands a buffer no reference to its algorithm: it builds it in ``_setup_model`` and loads it
in ``load_replay_buffer``. A relabelling buffer finds that algorithm as the ``self`` of those
two methods on the call stack (:func:`calling_algorithm`), and nothing else reads the stack.
With it, the buffer:

- **seeds its reward model from the algorithm's seed.** A model the buffer makes from a mapping,
  or one made with ``seed=None`` that has seen no step, is initialised again from
  :func:`reward_model_seed` of the algorithm's ``seed`` (rl-zoo3's ``--seed`` included). The
  derived seed feeds the model's own generators, never numpy's, torch's or Python's global ones,
  so the algorithm's own draws are those of a run without a reward model. An unseeded algorithm
  leaves such a model on fresh entropy, as SB3 leaves itself; an explicit model seed is kept.
- **keeps one live model.** The buffer puts its model in the algorithm's
  ``replay_buffer_kwargs`` / ``rollout_buffer_kwargs`` (a new dict: the user's is not changed),
  so SB3's ``save`` writes the model that trains, in the object and the mapping forms alike.
  When ``load_replay_buffer`` unpickles a buffer, the model it carries becomes the state of the
  object the algorithm's kwargs hold, and the buffer trains that object: after SB3's resume flow
  (``load``, ``load_replay_buffer``, ``learn``, ``save``) the files hold the live model.
- **refuses n-step settings SB3 would ignore** (see :mod:`delayed_rl.deep.buffers`).

A buffer built by hand, outside an algorithm, has none of this: its model keeps its own seed.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

__all__ = ["REWARD_MODEL_STREAM", "calling_algorithm", "reward_model_seed"]

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

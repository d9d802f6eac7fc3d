"""An experiment's task: a small frozen dataclass, one per (condition, seed).

Each experiment defines its task type, a subclass of :class:`Task` with one typed field per
setting; its run and summary read ``task.field``, and its :meth:`Task.cost` orders the runs. A
task's identity, what finds its kept run, is its canonical JSON (:meth:`Task.to_json`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["Task", "optional"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Task:
    """The base of the experiments' task types.

    A task's JSON is its fields by name, except an :func:`optional` field at its default, which
    is left out: a setting only some of an experiment's tasks have. Sequences are tuples (JSON
    lists); a mapping field (a delay's description, an env's arguments) stays a dict, so such a
    task is not hashable, and its dict is not to be changed.

    Attributes:
        seed: the seed of the run.
    """

    seed: int

    def to_json(self) -> dict[str, Any]:
        """The task as a dict: its fields, less the :func:`optional` ones at their default."""
        return {
            field.name: getattr(self, field.name)
            for field in dataclasses.fields(self)
            if not (field.metadata.get("optional") and getattr(self, field.name) == field.default)
        }

    def cost(self) -> float:
        """The task's run's estimated core-seconds, which only orders the runs.

        The pool starts the longest runs first, so that none starts last. The base estimate is
        a microsecond a step (its ``steps``, 1 without); a task type whose steps cost more, or
        whose cost depends on its settings, overrides it.
        """
        return 1e-6 * float(getattr(self, "steps", 1))


def optional(default: Any = None) -> Any:
    """A task field that only some tasks set: left out of :meth:`Task.to_json` at ``default``."""
    return dataclasses.field(default=default, metadata={"optional": True})

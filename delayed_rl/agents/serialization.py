"""Deprecated: model files are :mod:`delayed_rl.agents.save_util`; loading is ``TabularAgent.load``.

``save_agent(agent, path)`` is ``agent.save(path)`` and ``load_agent(path, ...)`` is
:func:`delayed_rl.agents.load_agent`; both still work here, with a ``DeprecationWarning``.
"""

from __future__ import annotations

import warnings
from typing import Any

__all__ = ["load_agent", "save_agent"]


def _deprecated(name: str, instead: str) -> None:
    warnings.warn(
        f"delayed_rl.agents.serialization.{name} is deprecated: use {instead}",
        DeprecationWarning,
        stacklevel=3,
    )


def save_agent(agent: Any, path: Any) -> Any:
    """Deprecated: ``agent.save(path)``."""
    _deprecated("save_agent", "agent.save(path)")
    return agent.save(path)


def load_agent(path: Any, env: Any = None, custom_objects: Any = None) -> Any:
    """Deprecated: :func:`delayed_rl.agents.load_agent`."""
    from delayed_rl.agents.base import TabularAgent

    _deprecated("load_agent", "delayed_rl.agents.load_agent")
    return TabularAgent.load(path, env=env, custom_objects=custom_objects)

"""The compiled (numba) training path for tabular envs and the e-puck; see :class:`CompiledRun`.

``agent.learn()`` runs on it by itself when it can (``learn(compiled=None)``, the default):
the agent's rule has a compiled twin, the env stack compiles (:func:`inspect_stack`, the
protocol of :mod:`delayed_rl.compiled.tabular`), the learning rate is constant and no callback
is given. ``learn(compiled=False)`` never does and ``learn(compiled=True)`` must (else
:class:`NotCompilable` says why). How it differs from the Python path (random streams, the env
object, compiling and caching, callbacks between chunks): the docs' compiled-path page
(``docs/compiled.md``).
"""

from typing import Any

from delayed_rl._numba import HAVE_NUMBA
from delayed_rl.compiled.tabular import NotCompilable, TabularModel, inspect_stack

__all__ = ["HAVE_NUMBA", "CompiledRun", "NotCompilable", "TabularModel", "inspect_stack"]


def __getattr__(name: str) -> Any:
    """:class:`CompiledRun`, imported on first use.

    The loop it runs can step the e-puck, whose physics (pymunk) an agent that trains on a
    grid need not load.
    """
    if name == "CompiledRun":
        from delayed_rl.compiled.run import CompiledRun

        return CompiledRun
    raise AttributeError(f"module 'delayed_rl.compiled' has no attribute {name!r}")

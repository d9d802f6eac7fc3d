"""The compiled (numba) training path for tabular envs; see :class:`FusedRun`."""

from delayed_rl.fast.kernel import HAVE_NUMBA
from delayed_rl.fast.run import FusedRun
from delayed_rl.fast.tabular import NotCompilable, TabularModel, inspect_stack

__all__ = ["HAVE_NUMBA", "FusedRun", "NotCompilable", "TabularModel", "inspect_stack"]

"""numba, compiled with one set of options for the whole library (``cache=True``, ``nogil=True``).

``jit`` compiles a function; where numba is missing (it is a core dependency, so only in odd
installs) it returns the function as it is, and ``HAVE_NUMBA`` says so. :func:`entry_point` gives
Python a compiled function without numba's per-call dispatch, for calls made at every env step.

For developers: numba's cache checks only the source file of the function it compiled, not
those of the compiled functions it calls. After editing a callee in another module (e.g.
:func:`delayed_rl.compiled.deconvolution_statistics.observe`, which the loop of
:func:`delayed_rl.compiled.kernel.run_chunk` calls), delete the ``*.nbi``/``*.nbc`` files under
``delayed_rl/`` or the caller keeps running the old callee. An installed upgrade rewrites every
file, so users are not affected.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["HAVE_NUMBA", "entry_point", "jit"]

try:
    import numba

    HAVE_NUMBA = True
    jit = numba.njit(cache=True, nogil=True)
except ImportError:  # pragma: no cover - exercised where numba is absent
    HAVE_NUMBA = False

    def jit(function):
        """Return ``function`` uncompiled (numba is not installed)."""
        return function


def entry_point(function: Callable, *example: Any) -> Callable:
    """The compiled ``function`` for arguments of the types of ``example``, without dispatch.

    Calling a compiled function from Python first finds the numba types of its arguments and
    picks the compiled version for them: for the e-puck camera's 14 arguments, more than the
    reading itself (measured: ``benchmarks/SPEED.md``). The callable returned skips that step: it converts each scalar
    argument to the type of its ``example`` as ``float()`` and ``int()`` do (a numeric string
    too) and takes an array's memory as the example's dtype, dimensions and layout *without
    checking them*. So it is for internal calls whose arguments the caller made itself, of
    fixed types (the e-puck's camera, track and physics handles, its pose and speeds), never
    for what a user passes. It is not picklable; make it again in a copy. Without numba,
    ``function`` itself.
    """
    if not HAVE_NUMBA:  # pragma: no cover - exercised where numba is absent
        return function
    signature = tuple(function.typeof_pyval(value) for value in example)
    return function.compile(signature)

"""numba, compiled with one set of options for the whole library (``cache=True``, ``nogil=True``).

``jit`` compiles a function; where numba is missing (it is a core dependency, so only in odd
installs) it returns the function as it is, and ``HAVE_NUMBA`` says so.

For developers: numba's cache checks only the source file of the function it compiled, not
those of the compiled functions it calls. After editing a callee in another module (e.g.
:func:`delayed_rl.fast.statistics.observe`, which :func:`delayed_rl.fast.kernel.run_chunk`
calls), delete the ``*.nbi``/``*.nbc`` files under ``delayed_rl/`` or the caller keeps running
the old callee. An installed upgrade rewrites every file, so users are not affected.
"""

from __future__ import annotations

__all__ = ["HAVE_NUMBA", "jit"]

try:
    import numba

    HAVE_NUMBA = True
    jit = numba.njit(cache=True, nogil=True)
except ImportError:  # pragma: no cover - exercised where numba is absent
    HAVE_NUMBA = False

    def jit(function):
        """Return ``function`` uncompiled (numba is not installed)."""
        return function

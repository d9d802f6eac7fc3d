"""Package attributes imported from their modules on first use, with a hint when an extra is missing."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_attributes"]


def lazy_attributes(
    package: str,
    homes: Mapping[str, str],
    needs: tuple[str, ...],
    what: str,
    extra: str,
    install: str,
) -> Callable[[str], Any]:
    """Return a module ``__getattr__`` that imports ``package``'s names from their modules.

    Args:
        package: the package's ``__name__``.
        homes: each public name's module, relative to ``package``.
        needs: the top-level packages the modules need: an ``ImportError`` for one of them
            becomes the error below; any other ``ImportError`` passes through unchanged.
        what: those packages as the error names them (``"PettingZoo"``).
        extra: the extra that installs them.
        install: the command that installs the extra, as the error should print it.

    Returns:
        ``__getattr__(name)``: the attribute, imported on first use.

    Raises:
        AttributeError: (from ``__getattr__``) ``name`` is not one of ``homes``.
        ImportError: (from ``__getattr__``) the module needs a package of ``needs`` that is not
            installed; the message names the missing module, the extra and ``install``.
    """

    def __getattr__(name: str) -> Any:
        if name not in homes:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        try:
            module = importlib.import_module(f"{package}.{homes[name]}")
        except ImportError as error:
            if error.name and error.name.split(".")[0] in needs:
                raise ImportError(
                    f"{package}.{name} needs {what}, which is not installed "
                    f"({error.name} is missing): install the {extra} extra, {install}"
                ) from error
            raise
        return getattr(module, name)

    return __getattr__

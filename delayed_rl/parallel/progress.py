"""The progress of many runs on the terminal: tqdm's bar, else a line per finished run."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from typing import Any


def tqdm_installed() -> bool:
    """Whether tqdm is installed (an optional dependency), so :class:`RunProgress` draws a bar."""
    return _tqdm() is not None


def _tqdm() -> Any:
    """``tqdm.auto.tqdm`` (a terminal's bar, or a notebook's), or ``None`` without tqdm."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm


class RunProgress:
    """The progress of ``total`` runs on stderr: tqdm's bar, else a line per finished run.

    A context manager: ``with RunProgress(total, label, enabled) as progress:``, then
    :meth:`tick` once per finished run (as :func:`iter_tasks` yields it), and print to the
    terminal inside :meth:`paused`. tqdm's bar (tqdm is optional, in the ``dev`` extra) shows
    the runs done out of ``total``, the time elapsed and the time left, and stays drawn, as it
    ends, on a line of its own; without tqdm each :meth:`tick` prints
    ``[label] done/total runs done``.

    Args:
        total: how many runs there are.
        label: the bar's name (``sweep``, an experiment's name).
        enabled: show anything at all (``False``: every method does nothing).

    Attributes:
        done: how many runs have been counted so far.
    """

    def __init__(self, total: int, label: str, enabled: bool):
        self.total, self.label, self.done = total, label, 0
        tqdm = _tqdm() if enabled else None
        self._bar = None
        if tqdm is not None:
            self._bar = tqdm(total=total, desc=label, unit="run", file=sys.stderr)
        self._lines = enabled and self._bar is None

    def __enter__(self) -> RunProgress:
        return self

    def __exit__(self, *error: object) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def tick(self) -> None:
        """Count one more run done."""
        self.done += 1
        if self._bar is not None:
            self._bar.update()
        elif self._lines:
            print(f"[{self.label}] {self.done}/{self.total} runs done", file=sys.stderr, flush=True)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """A context in which to print to the terminal: the bar is cleared, then drawn again."""
        if self._bar is None:
            yield
            return
        self._bar.clear()
        try:
            yield
        finally:
            sys.stdout.flush()
            self._bar.refresh()

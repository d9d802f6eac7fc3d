"""A minimal logger with the interface of stable-baselines3's ``Logger``.

Agents record their metrics through ``agent.logger``. Without a logger set, it is a
:class:`Logger` that prints a table to stdout when the agent's ``verbose >= 1`` (like SB3's
default) and otherwise only keeps the last values in ``name_to_value``. Any object with SB3's
``record``/``dump`` methods can replace it with ``agent.set_logger(...)``, in particular
``stable_baselines3.common.logger.configure(folder, ["stdout", "csv", "tensorboard"])``.
"""

from __future__ import annotations

import sys
from collections import defaultdict
from typing import Any, TextIO

__all__ = ["Logger"]


class Logger:
    """Collects key/value pairs and writes them, as a table, at each :meth:`dump`.

    Args:
        verbose: 0 keeps the values silently; 1 prints a table at each dump.
        stream: where to print (default ``sys.stdout``).
    """

    def __init__(self, verbose: int = 0, stream: TextIO | None = None):
        self.verbose = verbose
        self.stream = stream
        self.name_to_value: dict[str, Any] = {}
        self._sums: dict[str, float] = defaultdict(float)
        self._counts: dict[str, int] = defaultdict(int)
        self.dumps: list[dict[str, Any]] = []
        """Every dumped table (``{"step": ..., key: value, ...}``), for inspection."""

    def record(self, key: str, value: Any, exclude: str | tuple[str, ...] | None = None) -> None:
        """Set ``key`` to ``value`` for the next dump (``exclude`` is accepted for SB3 parity)."""
        self.name_to_value[key] = value

    def record_mean(
        self, key: str, value: Any, exclude: str | tuple[str, ...] | None = None
    ) -> None:
        """Average ``value`` with the other values recorded for ``key`` since the last dump."""
        if value is None:
            return
        self._sums[key] += float(value)
        self._counts[key] += 1
        self.name_to_value[key] = self._sums[key] / self._counts[key]

    def dump(self, step: int = 0) -> None:
        """Write the recorded values (a table on stdout when ``verbose >= 1``), then clear them."""
        if self.name_to_value:
            row = {"step": step, **self.name_to_value}
            self.dumps.append(row)
            if self.verbose >= 1:
                self._print(row)
        self.name_to_value = {}
        self._sums.clear()
        self._counts.clear()

    def _print(self, row: dict[str, Any]) -> None:
        items = [(key, _format(value)) for key, value in row.items() if key != "step"]
        width_key = max(len(key) for key, _ in items)
        width_value = max(len(value) for _, value in items)
        line = "-" * (width_key + width_value + 7)
        out = self.stream or sys.stdout
        out.write(line + "\n")
        for key, value in items:
            out.write(f"| {key:<{width_key}} | {value:>{width_value}} |\n")
        out.write(line + "\n")
        out.flush()

    def get_log_dir(self) -> str | None:
        """Where the logs are written: ``None`` (this logger writes no files)."""
        return None

    def close(self) -> None:
        """Nothing to close (SB3 parity)."""


def _format(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)

"""What every figure shares: matplotlib on first use, the band's legend, the legend's place, saving.

Used by the experiments' figures (:mod:`delayed_rl.experiments.framework.plotting`) and the
sweeps' (:mod:`delayed_rl.sweep.results`). matplotlib comes from the ``plot`` extra.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["BAND", "band_label", "finish", "outside_legend", "pyplot"]

#: The legend text of a 95 % band or error bar over ``n`` seeds.
BAND = "95 % CI over {n} seeds"


def band_label(label: str, n: int) -> str:
    """A curve's legend label naming its band: ``"MMQ: mean, 95 % CI over 5 seeds"``.

    >>> band_label("MMQ", 5), band_label("Q", 1)
    ('MMQ: mean, 95 % CI over 5 seeds', 'Q (1 seed)')
    """
    return f"{label}: mean, {BAND.format(n=n)}" if n > 1 else f"{label} (1 seed)"


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (figures go to files only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def outside_legend(ax: Any, fontsize: float = 8) -> None:
    """The legend of ``ax`` to the right of its axes (it never covers the data)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=fontsize, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)


def finish(fig: Any, ax: Any, path: Path, title: str, xlabel: str, ylabel: str) -> None:
    """Label and grid ``ax``, title ``fig`` (over the legend too), save it to ``path``, close it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    fig.suptitle(title, fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)

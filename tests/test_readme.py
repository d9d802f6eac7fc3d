"""The README's Python examples run as written (in order, in one namespace)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.DOTALL)


def _run(blocks: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict:
    monkeypatch.chdir(tmp_path)  # the examples write files
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), namespace)
    return namespace


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    tabular = [block for block in _blocks() if "stable_baselines3" not in block]
    assert len(tabular) >= 2
    namespace = _run(tabular, tmp_path, monkeypatch)
    assert namespace["action"] in (0, 3)  # the trained agent heads up or left from the start
    assert (tmp_path / "mmq9.npz").exists()


@pytest.mark.sb3
def test_readme_deep_rl_block_learns_the_delay(tmp_path, monkeypatch):
    import torch

    torch.set_num_threads(1)
    blocks = _blocks()
    assert any("stable_baselines3" in block for block in blocks)
    namespace = _run(blocks, tmp_path, monkeypatch)  # every block, in order, as a reader would
    # Poisson(20): the learned pmf's mean within one standard deviation of the delay's, √20
    assert abs(namespace["model"].mean_delay - 20) < math.sqrt(20)

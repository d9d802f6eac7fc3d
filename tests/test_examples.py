"""The scripts in ``examples/`` run, on a smoke setting, and say what they should."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str, capsys: pytest.CaptureFixture) -> str:
    """Run ``examples/<name>`` as a script with ``args``; return what it printed."""
    argv = sys.argv
    sys.argv = [name, *args]
    try:
        runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    finally:
        sys.argv = argv
    return capsys.readouterr().out


def test_own_tabular_env_trains_on_the_compiled_path(capsys):
    out = run_example("own_tabular_env.py", "--steps", "50000", capsys=capsys)
    lines = out.strip().splitlines()
    assert len(lines) == 2 and all("trained on the fused path" in line for line in lines)
    assert "DeconvolutionQLearning: trained on the fused path, greedy actions [1, 1]" in lines[1]

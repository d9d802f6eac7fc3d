"""The e-puck env reproduces its stored reference trajectories bit for bit.

``tests/data/epuck_trajectories.npz`` was recorded (by ``tests/data/make_epuck_trajectories.py``)
from the env before its per-step code was optimised. Each configuration is replayed with the
stored actions and every observation, reward, episode end, ``info`` entry and body velocity must
be exactly equal (same dtype, same bits), so a speed-up that changes any floating-point result,
even in the last bit, fails here. A few configurations are also replayed on the numpy and Python
reference path (the compiled kernels off, as without numba).

The env's bits do not depend on the CPU (no numpy SIMD loop, BLAS or C-library function that
rounds by CPU decides them: see ``delayed_rl._portable_math`` and the kernels' docstring), so the
file holds on every x86-64 CPU; ``tests/test_cpu_independence.py`` checks that claim in a
subprocess with numpy's SIMD loops and numba's host-CPU code turned off.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from delayed_rl.envs.linefollow import _chipmunk, _kernels

DATA = Path(__file__).parents[1] / "data"


def _load_generator():
    spec = importlib.util.spec_from_file_location(
        "make_epuck_trajectories", DATA / "make_epuck_trajectories.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


generator = _load_generator()
REFERENCE = dict(np.load(generator.PATH))
NAMES = sorted({key.split("/")[0] for key in REFERENCE})


def assert_bit_identical(name: str, field: str, got: np.ndarray, want: np.ndarray) -> None:
    """Same dtype, shape and bytes; on failure, name the first differing row."""
    assert got.dtype == want.dtype, f"{name}/{field}: dtype {got.dtype} != {want.dtype}"
    assert got.shape == want.shape, f"{name}/{field}: shape {got.shape} != {want.shape}"
    same = got.reshape(len(got), -1).view(np.uint8) == want.reshape(len(want), -1).view(np.uint8)
    rows = np.flatnonzero(~same.all(axis=1))
    assert rows.size == 0, (
        f"{name}/{field}: {rows.size} rows differ, first at row {rows[0]}: "
        f"{got[rows[0]]!r} != {want[rows[0]]!r}"
    )
    assert np.array_equal(got, want)


def test_the_reference_file_covers_every_configuration():
    assert sorted(generator.CONFIGURATIONS) == NAMES
    for name in NAMES:
        assert json.loads(str(REFERENCE[f"{name}/config"])) == generator.CONFIGURATIONS[name]


@pytest.mark.parametrize("name", NAMES)
def test_replaying_the_stored_actions_reproduces_every_row_exactly(name):
    config = json.loads(str(REFERENCE[f"{name}/config"]))
    want = {field: REFERENCE[f"{name}/{field}"] for field in generator.ROW_FIELDS}
    actions = iter(want["action"][want["kind"] == 1])
    got = generator.record(config, choose=lambda obs: next(actions))
    for field in generator.ROW_FIELDS:
        assert_bit_identical(name, field, got[field], want[field])


@pytest.mark.parametrize(
    "name", ["default-random-0", "pixels-continuous-random-2", "real-pixels-follow-recover-6"]
)
def test_the_reference_path_reproduces_the_rows_too(name, monkeypatch):
    monkeypatch.setattr(_kernels, "enabled", lambda: False)
    monkeypatch.setattr(_chipmunk, "enabled", lambda: False)
    test_replaying_the_stored_actions_reproduces_every_row_exactly(name)

"""The core install: what runs with only the core dependencies (no SciPy).

SciPy is not a dependency, but numba compiles ``@`` and ``np.dot`` in compiled code to BLAS
calls that need it. A subprocess whose imports of SciPy fail, with numba's cache in a fresh
folder (so every function is compiled there, as on a first run after a core install), trains
the agents whose solves are compiled: deconvolution Q-learning with a learned delay (the
projected gradient on the delay's pmf) and with a known delay on an env of more than
``DENSE_SOLVE_PAIRS`` pairs (conjugate gradients).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

_BLOCK_SCIPY = textwrap.dedent(
    """
    import sys

    class _NoScipy:
        def find_spec(self, name, path=None, target=None):
            if name == "scipy" or name.startswith("scipy."):
                raise ImportError("SciPy is not installed (blocked by the test)")
            return None

    sys.meta_path.insert(0, _NoScipy())
    """
)

_TRAIN = textwrap.dedent(
    """
    import json, sys
    import gymnasium as gym
    import numpy as np
    from delayed_rl.agents import DeconvolutionQLearning
    from delayed_rl.agents.deconvolution.regression import DENSE_SOLVE_PAIRS
    from delayed_rl.delays import Poisson

    learned = DeconvolutionQLearning(
        gym.make("delayed_rl/GridWorld-v0", size=5, reward_delay=3), max_delay_estimate=10, seed=0
    )
    learned.learn(3000)
    big = gym.make("delayed_rl/GridWorld-v0", size=12, reward_delay=3)
    known = DeconvolutionQLearning(big, delay=Poisson(3), max_delay_estimate=10, seed=0)
    assert known.n_states * known.n_actions > DENSE_SOLVE_PAIRS
    known.learn(3000)
    print(json.dumps({
        "scipy_imported": any(name.split(".")[0] == "scipy" for name in sys.modules),
        "pmf_sum": float(learned.delay_pmf.sum()),
        "finite": bool(np.all(np.isfinite(learned.reward_model))
                       and np.all(np.isfinite(known.reward_model))),
        "known_nonzero": bool(np.any(known.reward_model != 0.0)),
    }))
    """
)


@pytest.mark.cold_cache
def test_deconvolution_solves_compile_and_run_without_scipy(tmp_path: Path):
    (tmp_path / "sitecustomize.py").write_text(_BLOCK_SCIPY)
    root = Path(__file__).resolve().parents[1]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tmp_path), str(root)]),
        "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"),
    }
    done = subprocess.run(
        [sys.executable, "-c", _TRAIN], env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["scipy_imported"] is False
    assert abs(result["pmf_sum"] - 1.0) < 1e-9  # the learned delay is a distribution
    assert result["finite"] and result["known_nonzero"]

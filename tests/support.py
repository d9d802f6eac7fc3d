"""Test helpers shared by several test modules."""

from __future__ import annotations

import numpy as np

from delayed_rl.delays import Delay


class ScriptedDelay(Delay):
    """Delays read from a script, in order (``then`` once it runs out); ignores the generator."""

    def __init__(self, script, then: int = 0, mean: float = 1.0):
        self.script, self.then, self._mean, self.used = list(script), then, mean, 0

    def sample(self, rng, size=None):
        n = 1 if size is None else int(np.prod(size))
        out = [
            self.script[i] if i < len(self.script) else self.then
            for i in range(self.used, self.used + n)
        ]
        self.used += n
        return self._finish(np.reshape(out, () if size is None else size), size)

    def pmf(self, k):
        return 0.0

    @property
    def mean(self):
        return self._mean

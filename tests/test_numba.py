"""``delayed_rl._numba.entry_point``: a compiled function called without numba's dispatch."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl._numba import HAVE_NUMBA, entry_point, jit

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")


@jit
def _scaled_sum(values, scale, offset):
    total = 0.0
    for v in values:
        total += v
    return total * scale + offset


def test_it_computes_what_the_dispatcher_computes():
    values = np.random.default_rng(0).normal(size=17)
    call = entry_point(_scaled_sum, values, 1.0, 0)
    assert call is not _scaled_sum
    for scale, offset in ((2.5, 3), (-1.0, -7), (0.0, 0)):
        assert repr(call(values, scale, offset)) == repr(_scaled_sum(values, scale, offset))


def test_numbers_are_converted_to_the_examples_types():
    values = np.arange(4.0)
    call = entry_point(_scaled_sum, values, 1.0, 0)
    compiled = len(_scaled_sum.signatures)
    # an int where the example had a float is taken as a float, a numpy int as an int
    assert call(values, 2, np.int64(1)) == 13.0
    assert len(_scaled_sum.signatures) == compiled  # no new version was compiled for them
    assert entry_point(_scaled_sum, values, 5.0, 1) is call  # the same version again


def test_it_refuses_what_cannot_be_converted():
    call = entry_point(_scaled_sum, np.arange(4.0), 1.0, 0)
    with pytest.raises(TypeError):
        call([0.0, 1.0], 1.0, 0)  # a list is not the example's array

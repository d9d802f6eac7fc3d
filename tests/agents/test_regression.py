"""The regression's dense solve: the four-row Cholesky gives the one-row order's bits."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.agents.deconvolution.regression import (
    _cholesky_factor,
    _cholesky_solve,
    _dot,
    _matrix_vector,
)


def one_row_cholesky_factor(a: np.ndarray) -> np.ndarray:
    """The right-looking factorization one row at a time, in numpy (``U`` in the upper triangle)."""
    n = a.shape[0]
    for j in range(n):
        a[j, j] = np.sqrt(a[j, j])
        a[j, j + 1 :] /= a[j, j]
        for i in range(j + 1, n):
            a[i, i:] -= a[j, i] * a[j, i:]
    return a


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 40, 67])
def test_four_rows_at_once_change_no_bit(n):
    rng = np.random.default_rng(n)
    m = rng.normal(size=(n, n + 3))
    a = m @ m.T + 0.1 * np.eye(n)
    expected = np.triu(one_row_cholesky_factor(a.copy()))
    got = a.copy()
    _cholesky_factor(got)
    assert np.triu(got).tobytes() == expected.tobytes()
    np.testing.assert_allclose(expected.T @ expected, a, rtol=1e-12, atol=1e-12)
    b = rng.normal(size=n)
    np.testing.assert_allclose(a @ _cholesky_solve(a.copy(), b), b, rtol=1e-8, atol=1e-8)


def test_refuses_a_matrix_that_is_not_positive_definite():
    a = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="not positive definite"):
        _cholesky_solve(a, np.ones(2))


@pytest.mark.parametrize("row", [2, 6, 8])  # inside the first block of four, after it, the rest
def test_refuses_a_matrix_whose_pivot_fails_in_any_part_of_the_factorization(row):
    n = 9
    a = np.eye(n) * 4.0
    a[row, row - 1] = a[row - 1, row] = 4.0  # rows row - 1 and row equal: a zero pivot at row
    with pytest.raises(ValueError, match="not positive definite"):
        _cholesky_solve(a.copy(), np.ones(n))
    a[row, row - 1] = a[row - 1, row] = 3.9  # a little less: positive definite
    np.testing.assert_allclose(a @ _cholesky_solve(a.copy(), np.ones(n)), np.ones(n), rtol=1e-9)
    a[row, row] = np.nan
    with pytest.raises(ValueError, match="not positive definite"):
        _cholesky_solve(a, np.ones(n))


@pytest.mark.parametrize("n", [0, 1, 3, 4, 5, 8, 51])
def test_the_written_out_products_match_numpy(n):
    """``_dot`` and ``_matrix_vector`` (numba's ``@`` needs SciPy) against numpy's products."""
    rng = np.random.default_rng(n)
    a, b = rng.normal(size=n), rng.normal(size=n)
    g = rng.normal(size=(7, n))
    scale = np.abs(a) @ np.abs(b) + 1.0  # the rounding error of a sum is relative to this
    assert abs(_dot(a, b) - a @ b) <= 1e-13 * scale
    np.testing.assert_allclose(_matrix_vector(g, b), g @ b, rtol=0, atol=1e-13 * (n + 1) * 10)
    ints = rng.integers(-9, 9, size=n).astype(float)  # exact in any order
    assert _dot(ints, ints) == float(ints @ ints)

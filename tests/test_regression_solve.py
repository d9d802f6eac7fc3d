"""The regression's dense solve: the four-row Cholesky gives the one-row order's bits."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.agents._regression import _cholesky_solve, _prefix_dot


def one_row_cholesky_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The solve as written before the four-row products: one inner product per entry."""
    n = a.shape[0]
    for j in range(n):
        for i in range(j, n):
            total = a[i, j] - _prefix_dot(a, i, j, j)
            a[i, j] = np.sqrt(total) if i == j else total / a[j, j]
    x = b.copy()
    for i in range(n):  # L y = b
        total = x[i]
        for k in range(i):
            total -= a[i, k] * x[k]
        x[i] = total / a[i, i]
    for i in range(n - 1, -1, -1):  # Lᵀ x = y
        total = x[i]
        for k in range(i + 1, n):
            total -= a[k, i] * x[k]
        x[i] = total / a[i, i]
    return x


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 8, 9, 13, 40, 67])
def test_four_rows_at_once_change_no_bit(n):
    rng = np.random.default_rng(n)
    m = rng.normal(size=(n, n + 3))
    a = m @ m.T + 0.1 * np.eye(n)
    b = rng.normal(size=n)
    expected = one_row_cholesky_solve(a.copy(), b)
    got = _cholesky_solve(a.copy(), b)
    assert got.tobytes() == expected.tobytes()
    np.testing.assert_allclose(a @ got, b, rtol=1e-8, atol=1e-8)


def test_refuses_a_matrix_that_is_not_positive_definite():
    a = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="not positive definite"):
        _cholesky_solve(a, np.ones(2))

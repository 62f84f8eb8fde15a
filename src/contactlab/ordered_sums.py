"""Sums taken in index order, so that a kernel computes the same bits compiled and as Python.

NumPy's ``sum`` adds eight or more terms pairwise and ``np.dot`` calls a BLAS whose order differs
between NumPy's and Numba's builds; a loop in index order is the one order both keep
(tests/test_reruns.py steps every built-in scene both ways and compares the bits)."""

from __future__ import annotations

import numpy as np

from .compiling import njit


@njit(cache=True, inline="always")  # inlined: conjugate gradients call it in their loop
def ordered_dot(a: np.ndarray, b: np.ndarray) -> float:
    """a · b of two (N,) arrays, summed from index 0 up."""
    total = 0.0
    for i in range(a.shape[0]):
        total += a[i] * b[i]
    return total

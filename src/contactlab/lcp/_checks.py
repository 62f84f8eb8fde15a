"""Input checks shared by the solvers of :mod:`contactlab.lcp`.

Every mistake raises :class:`contactlab.errors.InputError` with the field name and one sentence.
"""

from __future__ import annotations

import numbers

import numpy as np
import scipy.sparse as sp

from ..errors import InputError


def square_csr(matrix, field: str) -> sp.csr_matrix:
    """``matrix`` (SciPy sparse or array-like, shape (n, n)) as a float64 CSR matrix with sorted,
    summed indices; raises InputError when it is not square, not 2-D or not finite."""
    if sp.issparse(matrix):
        csr = sp.csr_matrix(matrix, dtype=np.float64, copy=True)
    else:
        try:
            dense = np.asarray(matrix, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(
                field, f"expected a square matrix of numbers, got {type(matrix).__name__} ({exc})."
            ) from None
        if dense.ndim != 2:
            raise InputError(field, f"expected a square 2-D matrix, got an array of shape {dense.shape}.")
        csr = sp.csr_matrix(dense)
    if csr.shape[0] != csr.shape[1]:
        raise InputError(field, f"expected a square matrix, got shape {csr.shape}.")
    csr.sum_duplicates()
    csr.sort_indices()
    if not np.all(np.isfinite(csr.data)):
        raise InputError(field, "the matrix holds NaN or infinite entries.")
    return csr


def finite_vector(values, n: int, field: str) -> np.ndarray:
    """``values`` as a finite float64 vector of length ``n`` (a copy); InputError otherwise."""
    try:
        out = np.array(values, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise InputError(field, f"expected a vector of {n} numbers ({exc}).") from None
    if out.ndim != 1 or out.shape[0] != n:
        raise InputError(field, f"expected a vector of length {n}, got shape {out.shape}.")
    if not np.all(np.isfinite(out)):
        raise InputError(field, "the vector holds NaN or infinite entries.")
    return out


def positive_float(value, field: str, zero: bool = False) -> float:
    """``value`` as a finite float > 0 (≥ 0 with ``zero``); InputError naming ``field`` otherwise."""
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not np.isfinite(value)
        or value < 0
        or (value == 0 and not zero)
    ):
        wanted = "a finite number ≥ 0" if zero else "a positive finite number"
        raise InputError(field, f"expected {wanted}, got {value!r}.")
    return float(value)


def positive_int(value, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise InputError(field, f"expected a positive integer, got {value!r}.")
    return int(value)


def choice(value, allowed, field: str) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise InputError(field, f"expected one of {', '.join(repr(a) for a in allowed)}, got {value!r}.")
    return value

"""Reading 3D frictional-contact problems: FCLIB HDF5 (local and global) and Siconos ``.dat`` text.

:func:`read_problem` returns a :class:`FrictionProblem` in local form ``u = W r + q`` (see
:mod:`contactlab.lcp.friction`, whose solvers take it), whatever the file held:

* FCLIB HDF5 ``/fclib_local``: W, q, μ as stored.
* FCLIB HDF5 ``/fclib_global`` (``M v = H r + f``, ``u = Hᵀ v + w``): reduced to local form with
  ``W = Hᵀ M⁻¹ H`` and ``q = Hᵀ M⁻¹ f + w`` (M factorized by sparse LU).
* Siconos text (``frictionContact_printInFile``): dimension, nc, storage (0 dense, 1 sparse
  block), the matrix (column-major values), q, μ, and at most one trailing flag (more values:
  a Siconos global problem's text, which is refused rather than misread).

FCLIB matrices follow the CSparse ``cs`` convention: ``nz ≥ 0`` triplets (``i`` rows, ``p``
columns), ``nz = −1`` compressed columns, ``nz = −2`` compressed rows; indices 0-based.
A file that cannot be read raises :class:`contactlab.errors.InputError` naming the path.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import InputError

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


@dataclass
class FrictionProblem:
    """A 3D Coulomb friction problem in FCLIB local form."""

    W: sp.csr_matrix
    """(3·nc, 3·nc) SciPy CSR Delassus matrix, per contact [N, T1, T2]."""
    q: np.ndarray
    """(3·nc,) free relative velocity."""
    mu: np.ndarray
    """(nc,) friction coefficients."""
    name: str
    """the file name."""
    source_format: str
    """``"fclib_local"``, ``"fclib_global"``, ``"siconos_dense"`` or ``"siconos_sparse_block"``."""

    @property
    def nc(self) -> int:
        """Number of contacts."""
        return int(self.mu.shape[0])


class _Bad(Exception):
    """Internal: what is wrong with the file (turned into an InputError naming the path)."""


def read_problem(path: str | Path) -> FrictionProblem:
    """Read an FCLIB HDF5 file or a Siconos ``.dat`` friction problem (3D) from ``path``.

    The format is recognised from the content (HDF5 signature, else text). Raises
    :class:`contactlab.errors.InputError` (field: the path) when the file is missing, is neither
    format, is truncated or holds inconsistent sizes or non-finite numbers.
    """
    path = Path(path)
    field = str(path)
    if not path.is_file():
        raise InputError(field, "no such file (expected an FCLIB .hdf5 or Siconos .dat friction problem).")
    try:
        with open(path, "rb") as handle:
            head = handle.read(8)
        if head == _HDF5_SIGNATURE:
            W, q, mu, kind = _read_hdf5(path)
        else:
            W, q, mu, kind = _read_siconos_text(path)
        _check_sizes(W, q, mu)
    except _Bad as exc:
        raise InputError(field, f"cannot read this friction problem: {exc}.") from None
    except OSError as exc:
        raise InputError(field, f"cannot read this friction problem: {exc}.") from None
    return FrictionProblem(W.tocsr(), q, mu, path.name, kind)


def _check_sizes(W, q, mu):
    m = q.shape[0]
    nc = mu.shape[0]
    if m != 3 * nc:
        raise _Bad(f"q has {m} entries but there are {nc} contacts (expected 3·nc = {3 * nc})")
    if W.shape != (m, m):
        raise _Bad(f"W has shape {W.shape}, expected ({m}, {m})")
    if not (np.all(np.isfinite(W.data)) and np.all(np.isfinite(q)) and np.all(np.isfinite(mu))):
        raise _Bad("it holds NaN or infinite values")
    if np.any(mu < 0):
        raise _Bad("it holds a negative friction coefficient")


# ----------------------------------------------------------------------------- HDF5


def _read_hdf5(path):
    import h5py

    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise _Bad(f"not a readable HDF5 file ({exc})") from None
    with handle:
        try:
            if "fclib_local" in handle:
                group = handle["fclib_local"]
                _check_dimension(group)
                W = _fclib_matrix(group["W"], "W")
                q = _dataset(group, "vectors/q")
                mu = _dataset(group, "vectors/mu")
                return W.tocsr(), q, mu, "fclib_local"
            if "fclib_global" in handle:
                group = handle["fclib_global"]
                _check_dimension(group)
                if "G" in group or "vectors/b" in group:
                    raise _Bad("the global problem has equality constraints (G, b), which are not supported")
                M = _fclib_matrix(group["M"], "M")
                H = _fclib_matrix(group["H"], "H")
                f = _dataset(group, "vectors/f")
                w = _dataset(group, "vectors/w")
                mu = _dataset(group, "vectors/mu")
                W, q = _reduce_global(M, H, f, w)
                return W, q, mu, "fclib_global"
        except KeyError as exc:
            raise _Bad(f"a required FCLIB entry is missing ({exc})") from None
        raise _Bad("it has neither an /fclib_local nor an /fclib_global group")


def _check_dimension(group):
    if "spacedim" in group:
        dim = int(np.asarray(group["spacedim"][()]).ravel()[0])
        if dim != 3:
            raise _Bad(f"spacedim is {dim}, only 3D problems are supported")


def _dataset(group, name):
    return np.asarray(group[name][()], dtype=np.float64).ravel()


def _header(group, key):
    return int(np.asarray(group[key][()]).ravel()[0])


def _fclib_matrix(group, name):
    """Decode a CSparse-encoded FCLIB matrix group into a SciPy matrix."""
    rows, cols, nz = _header(group, "m"), _header(group, "n"), _header(group, "nz")
    p = np.asarray(group["p"][()], dtype=np.int64).ravel()
    i = np.asarray(group["i"][()], dtype=np.int64).ravel()
    x = np.asarray(group["x"][()], dtype=np.float64).ravel()
    try:
        if nz >= 0:  # triplets: i = row indices, p = column indices
            if min(p.size, i.size, x.size) < nz:
                raise _Bad(f"matrix {name} declares {nz} triplets but stores fewer")
            return sp.coo_matrix((x[:nz], (i[:nz], p[:nz])), shape=(rows, cols)).tocsr()
        if nz == -1:  # compressed columns
            return sp.csc_matrix((x[: p[-1]], i[: p[-1]], p), shape=(rows, cols))
        if nz == -2:  # compressed rows
            return sp.csr_matrix((x[: p[-1]], i[: p[-1]], p), shape=(rows, cols))
    except (ValueError, IndexError) as exc:
        raise _Bad(f"matrix {name} is inconsistent ({exc})") from None
    raise _Bad(f"matrix {name} has an unknown storage code nz = {nz}")


def _reduce_global(M, H, f, w):
    """Local form of ``M v = H r + f, u = Hᵀ v + w``: W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w."""
    n = M.shape[0]
    if M.shape != (n, n) or H.shape[0] != n or f.shape != (n,) or w.shape != (H.shape[1],):
        raise _Bad(f"global sizes disagree (M {M.shape}, H {H.shape}, f {f.shape}, w {w.shape})")
    try:
        lu = spla.splu(sp.csc_matrix(M))
    except RuntimeError as exc:
        raise _Bad(f"the mass matrix M is singular ({exc})") from None
    Minv_H = lu.solve(H.toarray())
    Minv_f = lu.solve(f)
    W = H.T @ Minv_H
    q = H.T @ Minv_f + w
    W = 0.5 * (W + W.T)  # symmetric in exact arithmetic; remove the round-off asymmetry
    return sp.csr_matrix(np.asarray(W)), np.asarray(q).ravel()


# ----------------------------------------------------------------------------- Siconos text


class _Tokens:
    """Cursor over the whitespace-separated tokens of a text file."""

    def __init__(self, words):
        self.words = words
        self.at = 0

    def take(self, count, what):
        if self.at + count > len(self.words):
            raise _Bad(f"the file ends early, while reading {what}")
        chunk = self.words[self.at : self.at + count]
        self.at += count
        return chunk

    def ints(self, count, what):
        try:
            return np.array([int(t) for t in self.take(count, what)], dtype=np.int64)
        except ValueError:
            raise _Bad(f"expected integers for {what}") from None

    def int(self, what):
        return int(self.ints(1, what)[0])

    def floats(self, count, what):
        try:
            return np.array(self.take(count, what), dtype=np.float64)
        except ValueError:
            raise _Bad(f"expected numbers for {what}") from None


def _read_siconos_text(path):
    raw = path.read_bytes()
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise _Bad("it is neither HDF5 nor a Siconos text file (non-text bytes)") from None
    tokens = _Tokens(text.split())
    dim = tokens.int("the dimension")
    if dim != 3:
        raise _Bad(f"the problem dimension is {dim}, only 3D problems are supported")
    nc = tokens.int("the number of contacts")
    storage = tokens.int("the storage type")
    size0, size1 = tokens.int("the matrix rows"), tokens.int("the matrix columns")
    if nc < 0 or size0 != 3 * nc or size1 != 3 * nc:
        raise _Bad(f"the matrix is {size0}×{size1} for {nc} contacts (expected {3 * nc}×{3 * nc})")
    if storage == 0:
        again = tokens.ints(2, "the dense matrix size")
        if tuple(again) != (size0, size1):
            raise _Bad(f"the dense matrix size is given as {size0}×{size1}, then as {again[0]}×{again[1]}")
        values = tokens.floats(size0 * size1, "the dense matrix")
        W = sp.csr_matrix(values.reshape((size0, size1), order="F"))
        kind = "siconos_dense"
    elif storage == 1:
        W = _sparse_block(tokens, size0, size1)
        kind = "siconos_sparse_block"
    else:
        raise _Bad(f"the matrix storage type {storage} is not supported (0 dense, 1 sparse block)")
    q = tokens.floats(size0, "q")
    mu = tokens.floats(nc, "mu")
    left = len(tokens.words) - tokens.at
    if left > 1:  # a local problem may end with one flag; a global one (GFC3D) goes on with H, q, b, μ
        raise _Bad(
            f"{left} values follow μ, where a local problem has at most one flag: a Siconos global problem "
            "(GFC3D text) is not read, only local ones and FCLIB HDF5"
        )
    return W, q, mu, kind


def _sparse_block(tokens, size0, size1):
    """Siconos SparseBlockStructuredMatrix: block row/column ends, block-row pointers, block columns,
    then each block's number and its values (column-major)."""
    nblocks = tokens.int("the number of blocks")
    block_rows, block_cols = tokens.int("the block rows"), tokens.int("the block columns")
    row_ends = tokens.ints(block_rows, "the block row sizes")
    col_ends = tokens.ints(block_cols, "the block column sizes")
    filled1, filled2 = tokens.int("the block row pointer count"), tokens.int("the block count")
    row_pointers = tokens.ints(filled1, "the block row pointers")
    block_columns = tokens.ints(filled2, "the block column indices")
    if (
        (row_ends.size and row_ends[-1] != size0)
        or (col_ends.size and col_ends[-1] != size1)
        or filled2 != nblocks
        or filled1 < 1
        or row_pointers[-1] != nblocks
        or filled1 - 1 > block_rows
    ):
        raise _Bad("the sparse block structure is inconsistent with the matrix size")
    row_starts = np.concatenate(([0], row_ends[:-1]))
    col_starts = np.concatenate(([0], col_ends[:-1]))
    all_rows, all_cols, all_values = [], [], []
    for block_row in range(filled1 - 1):
        r0, nr = row_starts[block_row], row_ends[block_row] - row_starts[block_row]
        for b in range(row_pointers[block_row], row_pointers[block_row + 1]):
            col = block_columns[b]
            if not 0 <= col < block_cols:
                raise _Bad(f"block {b} has a column index {col} out of range")
            c0, ncol = col_starts[col], col_ends[col] - col_starts[col]
            tokens.int(f"the number of block {b}")
            values = tokens.floats(nr * ncol, f"block {b}").reshape((nr, ncol), order="F")
            rr, cc = np.meshgrid(np.arange(r0, r0 + nr), np.arange(c0, c0 + ncol), indexing="ij")
            all_rows.append(rr.ravel())
            all_cols.append(cc.ravel())
            all_values.append(values.ravel())
    if not all_values:
        return sp.csr_matrix((size0, size1))
    return sp.coo_matrix(
        (np.concatenate(all_values), (np.concatenate(all_rows), np.concatenate(all_cols))), shape=(size0, size1)
    ).tocsr()

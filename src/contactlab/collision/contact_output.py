"""Where every pair function writes its contacts: one row of the output rows.

Every pair routine takes its output as one argument ``out``, the tuple :data:`PairOutput`
(point (N, 3) [m], normal (N, 3) unit from B into A, depth (N,) [m] (> 0 overlapping),
feature (N,) int64 (stable id of the contact within its pair)), and a row ``slot`` to write
from: one argument for the four arrays keeps the routines' signatures and call sites short.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .geometry import axpy, rotate

PairOutput = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # (point, normal, depth, feature)
Frame = tuple[np.ndarray, np.ndarray]  # (center (3,) [m], rotation (3, 3) body → world) of a collider
FEATURE_BITS = 24  # contact id = (collider pair) << FEATURE_BITS | feature within the pair


@njit(cache=True)
def pair_output(capacity: int) -> PairOutput:
    """Empty rows for ``capacity`` contacts: point (n, 3), normal (n, 3), depth (n,), feature (n,) int64."""
    return (np.empty((capacity, 3)), np.empty((capacity, 3)), np.empty(capacity), np.empty(capacity, dtype=np.int64))


@njit(cache=True)
def write_contact(
    out: PairOutput, slot: int, point: np.ndarray, normal: np.ndarray, depth: float, feature: int
) -> None:
    """Store one contact at row ``slot`` of ``out``."""
    out_point, out_normal, out_depth, out_feature = out
    for i in range(3):
        out_point[slot, i] = point[i]
        out_normal[slot, i] = normal[i]
    out_depth[slot] = depth
    out_feature[slot] = feature


@njit(cache=True)
def write_local_contact(
    point_local: np.ndarray,
    normal_local: np.ndarray,
    depth: float,
    feature: int,
    frame: Frame | None,
    out: PairOutput,
    slot: int,
) -> None:
    """Store at row ``slot`` one contact given in a collider's frame: point (3,) [m] and normal
    (3,) there, the collider's ``frame`` = (center (3,) [m], rotation (3, 3) body → world); None:
    they are in world coordinates already and stored as given (not through an identity frame,
    which could turn a −0.0 coordinate into +0.0)."""
    if frame is None:  # Numba compiles only the branch of the argument's type
        write_contact(out, slot, point_local, normal_local, depth, np.int64(feature))
        return
    center, rotation = frame
    point = axpy(center, 1.0, rotate(rotation, point_local))
    write_contact(out, slot, point, rotate(rotation, normal_local), depth, np.int64(feature))

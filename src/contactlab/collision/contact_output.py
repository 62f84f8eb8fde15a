"""Where every pair function writes its contacts: one row of the output arrays.

out_point (N, 3) [m], out_normal (N, 3) unit from B into A, out_depth (N,) [m] (> 0
overlapping), out_feature (N,) int64 (stable id of the contact within its pair).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .geometry import axpy, rotate


@njit(cache=True)
def write_contact(
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
    point: np.ndarray,
    normal: np.ndarray,
    depth: float,
    feature: int,
) -> None:
    """Store one contact at row ``slot``."""
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
    center: np.ndarray,
    rotation: np.ndarray,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
) -> None:
    """Store at row ``slot`` one contact given in a collider's frame: point (3,) [m] and normal
    (3,) there, the collider at ``center`` (3,) [m] with ``rotation`` (3, 3) body → world."""
    write_contact(
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
        axpy(center, 1.0, rotate(rotation, point_local)),
        rotate(rotation, normal_local),
        depth,
        np.int64(feature),
    )

"""Where every pair function writes its contacts: one row of the output arrays.

out_point (N, 3) [m], out_normal (N, 3) unit from B into A, out_depth (N,) [m] (> 0
overlapping), out_feature (N,) int64 (stable id of the contact within its pair).
"""

from numba import njit


@njit(cache=True)
def write_contact(out_point, out_normal, out_depth, out_feature, slot, point, normal, depth, feature):
    """Store one contact at row ``slot``."""
    for i in range(3):
        out_point[slot, i] = point[i]
        out_normal[slot, i] = normal[i]
    out_depth[slot] = depth
    out_feature[slot] = feature

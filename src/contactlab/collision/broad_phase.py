"""Broad phase: sweep and prune over axis-aligned bounding boxes (compiled).

Sorting the boxes by their lower x bound and sweeping keeps the work near O(n log n + k)
for spread-out scenes, k being the number of overlapping pairs.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def overlapping_pairs(lower, upper):
    """Pairs (i, j), i < j, whose boxes overlap; lower/upper (N, 3) [m] → int64 array (K, 2)."""
    count = lower.shape[0]
    order = np.argsort(lower[:, 0])
    capacity = max(16, 4 * count)
    pairs = np.empty((capacity, 2), dtype=np.int64)
    found = 0
    for position in range(count):
        i = order[position]
        upper_x = upper[i, 0]
        for next_position in range(position + 1, count):
            j = order[next_position]
            if lower[j, 0] > upper_x:
                break
            if (lower[j, 1] <= upper[i, 1] and lower[i, 1] <= upper[j, 1]
                    and lower[j, 2] <= upper[i, 2] and lower[i, 2] <= upper[j, 2]):
                if found == capacity:
                    grown = np.empty((2 * capacity, 2), dtype=np.int64)
                    grown[:capacity] = pairs
                    pairs = grown
                    capacity *= 2
                pairs[found, 0] = min(i, j)
                pairs[found, 1] = max(i, j)
                found += 1
    return pairs[:found]


def brute_force_pairs(lower, upper):
    """The same pairs by testing every pair (NumPy, O(n²)): the reference for tests."""
    overlap = ((lower[:, None, :] <= upper[None, :, :]) & (lower[None, :, :] <= upper[:, None, :])).all(axis=2)
    i, j = np.nonzero(np.triu(overlap, k=1))
    return np.stack([i, j], axis=1).astype(np.int64)

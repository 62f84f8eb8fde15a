"""Sutherland–Hodgman clipping of a contact polygon by one plane (shared by box–box and hull–hull)."""

from numba import njit


@njit(cache=True)
def clip_polygon(source, label, count, distance, target, target_label):
    """Keep the part of polygon ``source`` (rows of 3) whose signed distance to a plane is ≤ 0.

    distance: (≥ count,) each point's signed distance to the plane (> 0: cut away). Each point
    carries a ``label`` (an incident corner): its own, or for a crossing point the corner that
    was cut off there, so that a corner cut by a hair keeps its label. A point exactly on the
    plane is kept once and never duplicated. Writes into ``target``/``target_label`` and
    returns the new count.
    """
    out = 0
    for cur in range(count):
        prev = cur - 1 if cur > 0 else count - 1
        d_prev = distance[prev]
        d_cur = distance[cur]
        if d_cur <= 0.0:
            if d_prev > 0.0 and d_cur < 0.0:      # entering: the crossing replaces the cut corner prev
                s = d_prev / (d_prev - d_cur)
                for c in range(3):
                    target[out, c] = source[prev, c] + s * (source[cur, c] - source[prev, c])
                target_label[out] = label[prev]
                out += 1
            for c in range(3):
                target[out, c] = source[cur, c]
            target_label[out] = label[cur]
            out += 1
        elif d_prev < 0.0:                       # leaving: the crossing replaces the cut corner cur
            s = d_prev / (d_prev - d_cur)
            for c in range(3):
                target[out, c] = source[prev, c] + s * (source[cur, c] - source[prev, c])
            target_label[out] = label[cur]
            out += 1
    return out

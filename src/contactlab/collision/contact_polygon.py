"""The contact polygon of two faces, and the few points kept of it (box–box and hull–hull).

Both polytope pairs find their contact the same way once the separating axis has picked a
reference face and an incident face: the incident face is clipped by the reference face's
side planes (:func:`clip_polygon`, Sutherland–Hodgman, one plane at a time), corners that are
nearly straight are dropped (:func:`drop_collinear`: crossings that round-off would slide
anywhere along an edge lying flush), and the polygon is reduced to at most four points
(:func:`reduce_to_four`: the deepest, then those spanning the largest area). Each pair module
keeps its own frame, tolerances and feature numbers; what is here is the shared geometry, and
:func:`claim_feature`, which keeps the features of one pair distinct.

Compiled (``@njit(cache=True)``), float64, no fastmath; no allocation.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .geometry import row_difference

MAX_POINTS = 4  # points kept of a contact polygon, at most
REDUCE_TIE = 1e-6  # relative tolerance of a tie in the reduction to 4 points


@njit(cache=True)
def clip_polygon(
    source: np.ndarray,
    label: np.ndarray,
    count: int,
    distance: np.ndarray,
    target: np.ndarray,
    target_label: np.ndarray,
) -> int:
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
            if d_prev > 0.0 and d_cur < 0.0:  # entering: the crossing replaces the cut corner prev
                s = d_prev / (d_prev - d_cur)
                for c in range(3):
                    target[out, c] = source[prev, c] + s * (source[cur, c] - source[prev, c])
                target_label[out] = label[prev]
                out += 1
            for c in range(3):
                target[out, c] = source[cur, c]
            target_label[out] = label[cur]
            out += 1
        elif d_prev < 0.0:  # leaving: the crossing replaces the cut corner cur
            s = d_prev / (d_prev - d_cur)
            for c in range(3):
                target[out, c] = source[prev, c] + s * (source[cur, c] - source[prev, c])
            target_label[out] = label[cur]
            out += 1
    return out


@njit(cache=True)
def drop_collinear(
    points: np.ndarray, labels: np.ndarray, count: int, tolerance: float, normal: np.ndarray, depth_tolerance: float
) -> int:
    """Remove corners of the clipped polygon within ``tolerance`` [m] of the chord of their two
    neighbours (near-duplicates, or crossings of an incident edge with a side plane that it
    nearly touches all along, as with faces stacked flush: such a crossing lands anywhere along
    the edge), compacting ``points`` and ``labels`` in place; stops at 2 points.

    A corner deeper along −``normal`` (3,) than both neighbours by more than ``depth_tolerance``
    [m] is kept all the same: it carries the depth. (A dropped corner is thus never more than
    ``depth_tolerance`` deeper than a neighbour that stays; ``inf``: no such exception.)
    ``points`` (≥ count, 3) [m], ``labels`` (≥ count,). Returns the new count."""
    removed = True
    while removed and count > 2:
        removed = False
        for k in range(count):
            prev = (k + count - 1) % count
            nxt = (k + 1) % count
            c0, c1, c2 = row_difference(points, nxt, prev)
            k0, k1, k2 = row_difference(points, k, prev)
            chord2 = c0 * c0 + c1 * c1 + c2 * c2
            if chord2 > tolerance * tolerance:
                x0 = c1 * k2 - c2 * k1
                x1 = c2 * k0 - c0 * k2
                x2 = c0 * k1 - c1 * k0
                distance = np.sqrt((x0 * x0 + x1 * x1 + x2 * x2) / chord2)
            else:
                distance = np.sqrt(k0 * k0 + k1 * k1 + k2 * k2)
            if distance > tolerance:
                continue
            h = normal[0] * points[k, 0] + normal[1] * points[k, 1] + normal[2] * points[k, 2]
            h_prev = normal[0] * points[prev, 0] + normal[1] * points[prev, 1] + normal[2] * points[prev, 2]
            h_next = normal[0] * points[nxt, 0] + normal[1] * points[nxt, 1] + normal[2] * points[nxt, 2]
            if h < min(h_prev, h_next) - depth_tolerance:
                continue
            for r in range(k, count - 1):
                for c in range(3):
                    points[r, c] = points[r + 1, c]
                labels[r] = labels[r + 1]
            count -= 1
            removed = True
            break
    return count


@njit(cache=True)
def first_near_best(score: np.ndarray, count: int) -> int:
    """Index of the first of ``score[:count]`` within a relative ``REDUCE_TIE`` of the largest one."""
    best = score[0]
    for k in range(1, count):
        best = max(best, score[k])
    threshold = best - REDUCE_TIE * abs(best)
    for k in range(count):
        if score[k] >= threshold:
            return k
    return 0


@njit(cache=True)
def reduce_to_four(
    points: np.ndarray,
    height: np.ndarray,
    keep: np.ndarray,
    count: int,
    axis: np.ndarray,
    depth_tolerance: float,
    score: np.ndarray,
) -> int:
    """Choose at most 4 of the ``count`` candidates ``keep[:count]`` (rows of ``points`` (·, 3)
    [m] with ``height`` (·,) [m]: lower is deeper) in the plane normal to unit ``axis`` (3,).

    The deepest (the earliest within ``depth_tolerance`` [m] of the lowest), the farthest from
    it, the one making the largest triangle with those two, the one adding most area to that
    triangle. Near-ties (distances and areas within a relative ``REDUCE_TIE``) go to the
    earliest candidate, so that round-off cannot switch between equivalent choices (the two
    squares of a regular octagon, say). The chosen ones are written to ``keep[:n]`` in their
    original (polygon) order; returns n (≤ 4). ``score``: ≥ count floats of scratch.

    Distances are measured in the plane: points given in a frame whose third axis is ``axis``
    with that coordinate 0 (as box–box gives them) are scored exactly as in two dimensions.
    """
    if count <= MAX_POINTS:
        return count
    lowest = np.inf
    for k in range(count):
        lowest = min(lowest, height[keep[k]])
    first = 0
    while height[keep[first]] > lowest + depth_tolerance:
        first += 1
    p0 = points[keep[first]]
    # the farthest from the deepest, measured in the contact plane
    for k in range(count):
        d0 = points[keep[k], 0] - p0[0]
        d1 = points[keep[k], 1] - p0[1]
        d2 = points[keep[k], 2] - p0[2]
        along = d0 * axis[0] + d1 * axis[1] + d2 * axis[2]
        score[k] = d0 * d0 + d1 * d1 + d2 * d2 - along * along
    score[first] = -1.0
    second = first_near_best(score, count)
    # (differences and products written out per component, as in drop_collinear: no temporaries)
    e0 = points[keep[second], 0] - p0[0]
    e1 = points[keep[second], 1] - p0[1]
    e2 = points[keep[second], 2] - p0[2]
    # the largest triangle with those two: |(e × d) · axis|
    for k in range(count):
        d0 = points[keep[k], 0] - p0[0]
        d1 = points[keep[k], 1] - p0[1]
        d2 = points[keep[k], 2] - p0[2]
        score[k] = abs((e1 * d2 - e2 * d1) * axis[0] + (e2 * d0 - e0 * d2) * axis[1] + (e0 * d1 - e1 * d0) * axis[2])
    score[first] = -1.0
    score[second] = -1.0
    third = first_near_best(score, count)
    d0 = points[keep[third], 0] - p0[0]
    d1 = points[keep[third], 1] - p0[1]
    d2 = points[keep[third], 2] - p0[2]
    area = (e1 * d2 - e2 * d1) * axis[0] + (e2 * d0 - e0 * d2) * axis[1] + (e0 * d1 - e1 * d0) * axis[2]
    orientation = 1.0 if area >= 0.0 else -1.0
    # the fourth: the point farthest outside an edge of the triangle (oriented counter-clockwise)
    tri0 = keep[first]
    tri1 = keep[second]
    tri2 = keep[third]
    for k in range(count):
        p = keep[k]
        outside = 0.0
        for e in range(3):
            s = tri0 if e == 0 else (tri1 if e == 1 else tri2)
            t = tri1 if e == 0 else (tri2 if e == 1 else tri0)
            a0, a1, a2 = row_difference(points, t, s)
            b0, b1, b2 = row_difference(points, p, s)
            twice_area = (a1 * b2 - a2 * b1) * axis[0] + (a2 * b0 - a0 * b2) * axis[1] + (a0 * b1 - a1 * b0) * axis[2]
            outside = max(outside, -orientation * twice_area)
        score[k] = outside
    score[first] = -1.0
    score[second] = -1.0
    score[third] = -1.0
    fourth = first_near_best(score, count)
    use_fourth = score[fourth] > 0.0
    out = 0
    for k in range(count):
        if k == first or k == second or k == third or (use_fourth and k == fourth):
            keep[out] = keep[k]
            out += 1
    return out


@njit(cache=True)
def claim_feature(feature: int, used: np.ndarray) -> int:
    """The first free feature number (0..255) from ``feature`` on (+1 mod 256), marked used in
    ``used`` (256,) bool: so the ≤ 4 contacts of a pair always differ in feature."""
    f = feature & 255
    while used[f]:
        f = (f + 1) & 255
    used[f] = True
    return f

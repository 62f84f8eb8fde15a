"""A sphere (or particle) against a static triangle mesh: its contacts are the local minima
of the distance.

Conventions as in :mod:`contactlab.collision.narrow_phase`: the mesh is always side B, the
normal points from the mesh INTO the dynamic shape A (the direction that separates A),
``depth`` > 0 when penetrating, contacts with ``depth ≥ −margin`` are kept (speculative), and
each ``point`` lies midway between the two surfaces. Meshes are
:class:`~contactlab.meshes.MeshGeometry` tuples (``TriangleMesh.geometry``), built once.

Inside and outside (see :mod:`contactlab.meshes`): a one-sided mesh (the default) has its
outside in front of its triangles (where the winding normal points); a point behind is
inside, by the sign of the pseudo-normal of the closest feature. Which side a point *came
from* is not known to a static query, so a sphere whose centre has crossed a thin one-sided
sheet from the front is pushed back out to the front, and one approaching from behind is
pushed through it. One-sided is meant for closed meshes (or surfaces whose back is never
reached, such as a terrain); an open sheet that can be approached from both sides should be
``two_sided``: it has no inside, and a shape is pushed back to the side its centre is on.
Crossing a thin sheet within one step is prevented by the swept test
:func:`~.mesh_sweep.sweep_sphere_mesh` (or by speculative contacts with a margin ≥ the step's motion).

Sphere (or particle, radius ≥ 0) against a mesh — :func:`sphere_mesh`
    For every triangle near the centre (BVH query, then the exact distance) the closest
    point ``q`` is found with its Voronoi region: the face, one of the 3 edges or one of the
    3 vertices (a point over the boundary of a triangle, within the tolerance, counts as the
    face). The nearest of them decides, by its pseudo-normal, whether the centre is inside a
    one-sided mesh (Bærentzen–Aanæs: exact for a closed mesh).

    * **Inside**: one contact, out through the nearest feature (as ``sphere_box`` does),
      depth = radius + distance. The search reaches ``mesh.max_depth`` below the surface;
      a centre deeper than that is lost.
    * **Outside** (and always for a two-sided mesh): the contacts are the **local minima of
      the distance from the centre over the mesh surface** within ``radius + margin``, each
      reported once. An edge or vertex point ``q`` of triangle t is dropped when another
      triangle that contains ``q`` (within the tolerance) has a closest point nearer the
      centre: ``q`` is then not a local minimum (the "ghost" edge contact of a sphere rolling
      over a floor made of several triangles). Points that coincide are one contact: a face
      point before an edge point before a vertex point, then the lowest triangle index.
      Features the centre is behind (the far side of a thin solid) give none.

    So a sphere resting on the shared diagonal of a flat two-triangle square gets exactly one
    contact (normal +z); a sphere in a concave corner gets one per wall. A face contact's
    normal is the triangle normal exactly; an edge or vertex contact's is the direction from
    ``q`` to the centre (reversed inside). ``feature = 16 · triangle + region`` (region 0: the
    face, 1–3: edges (0,1), (1,2), (2,0), 4–6: vertices 0, 1, 2), stable while the sphere
    stays over the same feature. At most ``max_contacts``, the deepest.

Closest features and pseudo-normals: :mod:`.mesh_features`. Compiled (``@njit(cache=True)``),
float64, no fastmath.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from .contact_output import PairOutput, pair_output
from .mesh_features import (
    EDGE2,
    FACE,
    FEATURES_PER_TRIANGLE,
    closest_point_on_triangle,
    features_near,
    keep_deepest,
    nearest_feature,
    signed_normal,
    write_kept,
)
from .primitive_pairs import Sphere

if TYPE_CHECKING:
    from ..meshes import MeshGeometry


@njit(cache=True)
def sphere_mesh(
    sphere: Sphere, mesh: MeshGeometry, margin: float, out: PairOutput, slot: int, max_contacts: int
) -> int:
    """Sphere (or particle) A (a :data:`.primitive_pairs.Sphere`: centre (3,) [m], radius [m] ≥ 0)
    against the static mesh B.

    Writes at most ``max_contacts`` contacts (the deepest) from ``slot`` on and returns how
    many; ``feature = 16 · triangle + region``. Rules (module docstring): a centre inside a
    one-sided mesh gets one contact, through the nearest feature; a centre outside gets one
    per local minimum of the distance within ``radius + margin``.
    """
    center, radius = sphere
    out_point, out_normal, out_depth, out_feature = out
    reach = radius + margin
    tol = mesh.tolerance
    candidates, closest, distance, region = features_near(
        mesh, center, reach, np.empty((32, 3)), np.empty(32), np.empty(32, dtype=np.int64)
    )
    nearest = nearest_feature(candidates, distance, region)
    if nearest < 0 or distance[nearest] > reach:
        # nothing within reach: a centre deeper than that inside a one-sided mesh?
        if mesh.two_sided or mesh.max_depth <= 0.0:
            return 0
        candidates, closest, distance, region = features_near(
            mesh, center, reach + mesh.max_depth, closest, distance, region
        )
        nearest = nearest_feature(candidates, distance, region)
        if nearest < 0 or distance[nearest] > reach + mesh.max_depth:
            return 0
    q = closest[nearest]
    signed, nx, ny, nz = signed_normal(
        mesh, candidates[nearest], region[nearest], center, q[0], q[1], q[2], distance[nearest]
    )
    if signed < 0.0:
        if max_contacts < 1:
            return 0
        # inside: one contact, out through the nearest feature (as sphere_box does)
        out_normal[slot, 0], out_normal[slot, 1], out_normal[slot, 2] = nx, ny, nz
        for i in range(3):
            out_point[slot, i] = 0.5 * (center[i] - radius * out_normal[slot, i] + q[i])
        out_depth[slot] = radius - signed
        out_feature[slot] = FEATURES_PER_TRIANGLE * candidates[nearest] + region[nearest]
        return 1
    n = candidates.shape[0]
    keep = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        keep[i] = distance[i] <= reach
    # 1. not a local minimum: another triangle containing q_i is nearer the centre
    for i in range(n):
        if not keep[i] or region[i] == FACE:
            continue
        for j in range(n):
            if j == i or not distance[j] < distance[i] - tol:
                continue
            other = mesh.triangles[candidates[j]]
            px, py, pz, _ = closest_point_on_triangle(
                closest[i], mesh.vertices[other[0]], mesh.vertices[other[1]], mesh.vertices[other[2]]
            )
            ex, ey, ez = px - closest[i, 0], py - closest[i, 1], pz - closest[i, 2]
            if ex * ex + ey * ey + ez * ez <= tol * tol:
                keep[i] = False
                break
    # 2. one contact per point: face before edge before vertex, then the lowest triangle
    for i in range(n):
        if not keep[i]:
            continue
        rank_i = 0 if region[i] == FACE else (1 if region[i] <= EDGE2 else 2)
        for j in range(n):
            if j == i or not keep[j]:
                continue
            rank_j = 0 if region[j] == FACE else (1 if region[j] <= EDGE2 else 2)
            if rank_j > rank_i or (rank_j == rank_i and candidates[j] > candidates[i]):
                continue
            ex = closest[j, 0] - closest[i, 0]
            ey = closest[j, 1] - closest[i, 1]
            ez = closest[j, 2] - closest[i, 2]
            if ex * ex + ey * ey + ez * ez <= tol * tol:
                keep[i] = False
                break
    # 3. normal, signed distance, depth; features the centre is behind (the far side of a
    #    thin solid) are dropped: the centre is outside
    rows = pair_output(n)
    point, normal, depth, feature = rows
    count = 0
    for i in range(n):
        if not keep[i]:
            continue
        t = candidates[i]
        signed, nx, ny, nz = signed_normal(
            mesh, t, region[i], center, closest[i, 0], closest[i, 1], closest[i, 2], distance[i]
        )
        this_depth = radius - signed
        if signed < 0.0 or this_depth < -margin:
            continue
        normal[count, 0], normal[count, 1], normal[count, 2] = nx, ny, nz
        depth[count] = this_depth
        # midway between the sphere's surface (centre − r n) and the mesh point q
        point[count, 0] = 0.5 * (center[0] - radius * nx + closest[i, 0])
        point[count, 1] = 0.5 * (center[1] - radius * ny + closest[i, 1])
        point[count, 2] = 0.5 * (center[2] - radius * nz + closest[i, 2])
        feature[count] = FEATURES_PER_TRIANGLE * t + region[i]
        count += 1
    # 4. the deepest max_contacts
    return write_kept(keep_deepest(depth[:count], max_contacts), rows, out, slot)

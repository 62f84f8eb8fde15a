"""Contacts of dynamic shapes against static triangle meshes: the one dispatcher for them.

Conventions as in :mod:`.sphere_mesh`: the mesh is always side B, the normal points from the
mesh INTO the dynamic shape A, ``depth`` > 0 when penetrating, contacts with ``depth ≥ −margin``
are kept. The routines per shape:

* spheres and particles: :func:`.sphere_mesh.sphere_mesh` (the local minima of the distance);
* boxes and convex hulls: :func:`.polytope_mesh.box_mesh`, :func:`.polytope_mesh.convex_mesh`
  (corners as points, and the mesh vertices inside);
* capsules: :func:`.capsule_mesh.capsule_mesh` (a sphere of the capsule's radius at points of
  its segment, with the same rules).

Batch — :func:`shapes_against_mesh`: every dynamic shape against one mesh, by kind.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .. import shapes
from ..compiling import njit
from .capsule_mesh import capsule_mesh
from .contact_output import pair_output
from .convex import stored_hull
from .polytope_mesh import box_mesh, convex_mesh
from .sphere_mesh import sphere_mesh

if TYPE_CHECKING:
    from ..meshes import MeshGeometry

MAX_PER_SHAPE = 8  # the usual cap of contacts per shape against one mesh (as MAX_PER_PAIR)

SPHERE, BOX, POINT, CAPSULE, CONVEX = shapes.SPHERE, shapes.BOX, shapes.POINT, shapes.CAPSULE, shapes.CONVEX
MESH_PARTNERS = (SPHERE, POINT, BOX, CAPSULE, CONVEX)  # the dynamic shapes with a routine against a mesh


@njit(cache=True)
def shapes_against_mesh(
    kinds: np.ndarray,
    params: np.ndarray,
    centers: np.ndarray,
    rotations_: np.ndarray,
    margins: np.ndarray,
    mesh: MeshGeometry,
    max_per_shape: int,
    hull_store: tuple[np.ndarray, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Contacts of many dynamic shapes against one static mesh.

    kinds (N,), params (N, 4), centers (N, 3) [m], rotations_ (N, 3, 3), margins (N,) [m] per
    shape: spheres and particles (params[0]: radius), boxes (params[:3]: half extents),
    capsules (radius, half length) and convex hulls (params[0]: the hull index into
    ``hull_store``, the 10 packed hull arrays of ``Model.hull_store``; without a store hulls
    give none). max_per_shape: the cap of contacts per shape (``MAX_PER_SHAPE`` is the usual
    one). Returns point (C, 3), normal (C, 3), depth (C,), feature (C,) and owner (C,): the
    index of the shape each contact belongs to. Shapes with no routine (planes) give none.
    """
    count_shapes = kinds.shape[0]
    capacity = max(1, count_shapes * max_per_shape)
    rows = pair_output(capacity)
    point, normal, depth, feature = rows
    owner = np.empty(capacity, dtype=np.int64)
    count = np.int64(capacity) * 0  # (not the literal 0: that would compile the callees twice)
    for s in range(count_shapes):
        kind = kinds[s]
        written = 0
        if kind == SPHERE or kind == POINT:
            written = sphere_mesh((centers[s], params[s, 0]), mesh, margins[s], rows, count, max_per_shape)
        elif kind == BOX:
            written = box_mesh(
                ((centers[s], rotations_[s]), params[s, :3]), mesh, margins[s], rows, count, max_per_shape
            )
        elif kind == CAPSULE:
            capsule = ((centers[s], rotations_[s]), params[s, 0], params[s, 1])
            written = capsule_mesh(capsule, mesh, margins[s], rows, count, max_per_shape)
        elif kind == CONVEX and hull_store is not None:
            hull = stored_hull(hull_store, params[s, 0])
            written = convex_mesh((centers[s], rotations_[s]), hull, mesh, margins[s], rows, count, max_per_shape)
        for k in range(count, count + written):
            owner[k] = s
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]

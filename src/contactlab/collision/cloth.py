"""Contacts of cloth against static obstacles at triangle samples (SPEC P2c).

A cloth's vertices are particles, so collision detection already keeps each of them a radius
(the cloth's thickness) from every surface (P2b). A coarse cloth can still be pierced between
its vertices — a table's corner poking up through the middle of a triangle. Here every cloth
triangle is also sampled, ``samples × samples`` points per triangle (the centroids of its
k-subdivision, see ``collision.granularity.surface_contacts``), and each sample closer to an obstacle
than the thickness is a contact whose side A is the triangle's three particles with the
sample's barycentric weights: a response at the sample moves vertex i by its share w_i (D1).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .. import shapes
from ..contacts import Contacts, tangent_basis
from .granularity import SURFACES, surface_contacts
from .signed_distance import model_obstacle

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


def cloth_sample_contacts(
    model: Model, state: State, samples: int, normal: str, margin: float, feature_base: int
) -> Contacts:
    """Contacts of the samples of every cloth triangle with every static plane, sphere, box and mesh.

    samples: per triangle edge (k × k per triangle); normal: "object" (P4) or "vertex" (P5);
    margin [m]: gaps down to this beyond the thickness are kept; feature_base: the first
    contact-id pair number free for these contacts (ids are (feature_base + triangle · O +
    obstacle) << 24 | sample). Depth counts from the thickness: > 0 when a sample is closer
    to the surface than the cloth's thickness.
    """
    triangles = model.triangles
    obstacles = np.nonzero(np.isin(model.obstacle_shape, SURFACES))[0]
    if samples < 1 or len(triangles) == 0 or len(obstacles) == 0:
        return Contacts.empty()
    thickness = model.particle_radius
    reach = margin + float(thickness[triangles].max())
    per_triangle = samples * samples
    parts = []
    for o in obstacles:
        surface = (
            model.meshes[int(model.obstacle_params[o, 0])]
            if model.obstacle_shape[o] == shapes.MESH
            else model_obstacle(model, o)
        )
        found = surface_contacts(state.particle_position, triangles, surface, "samples", normal, reach, samples)
        depth = found.depth + np.einsum("ck,ck->c", found.weights, thickness[found.vertices])
        keep = depth >= -margin
        if not keep.any():
            continue
        triangle = found.feature[keep] // per_triangle
        material_a = model.particle_material[found.vertices[keep, 0]]
        material_b = np.full(keep.sum(), model.obstacle_material[o])
        count = int(keep.sum())
        t1, t2 = tangent_basis(found.normal[keep])
        friction, restitution = model.pair_materials(material_a, material_b)
        parts.append(
            Contacts(
                body_a=np.full(count, -1),
                body_b=np.full(count, -1),
                particles_a=found.vertices[keep],
                particles_b=np.full((count, 3), -1),
                weights_a=found.weights[keep],
                weights_b=np.zeros((count, 3)),
                point=found.point[keep],
                normal=found.normal[keep],
                depth=depth[keep],
                tangent1=t1,
                tangent2=t2,
                friction=friction,
                restitution=restitution,
                feature_id=((feature_base + triangle * model.obstacle_count + o) << 24)
                | (found.feature[keep] % per_triangle),
            )
        )
    return Contacts.concatenate(parts)

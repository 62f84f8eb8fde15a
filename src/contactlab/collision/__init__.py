"""Collision detection: ``collide(model, state) -> Contacts``. It knows nothing of responses.

Colliders are numbered globally: rigid bodies 0..B−1, particles B..B+P−1 (spheres of their
contact radius), static obstacles B+P..B+P+O−1. Dynamic pairs come from the sweep-and-prune
broad phase; each dynamic collider is tested against the obstacles its bounds reach.
"""

import numpy as np
from numba import njit

from .. import rotations, shapes
from ..contacts import Contacts, tangent_basis
from ..errors import InputError
from .broad_phase import overlapping_pairs, static_pairs
from .cloth import cloth_sample_contacts
from .granularity import GRANULARITIES, NORMALS, polytope_contacts
from .mesh import MAX_PER_SHAPE
from .mesh_pairs import shapes_against_mesh_extended
from .manifolds import generate_reusing
from .narrow_phase import generate_contacts, needs_hulls, supported


def check_supported(model):
    """Raise InputError naming the first pair of shapes in the model with no contact routine."""
    kinds = np.concatenate([model.body_shape, np.full(model.particle_count, shapes.POINT)])
    dynamic, counts = np.unique(kinds, return_counts=True)
    count_of = dict(zip(dynamic.tolist(), counts.tolist()))
    static = sorted(set(model.obstacle_shape.tolist()))
    for a in dynamic.tolist():
        partners = [b for b in dynamic.tolist() if b > a or (b == a and count_of[a] > 1)] + static
        for b in partners:
            if not supported(a, b):
                raise InputError("bodies", f"contact between a {shapes.NAMES[a]} and a {shapes.NAMES[b]} "
                                 "is not supported yet; change the shape of one of them")


MESH_PARTNERS = (shapes.SPHERE, shapes.POINT, shapes.BOX, shapes.CAPSULE, shapes.CONVEX)  # shapes meshes meet
FEATURE_BITS = 24   # contact id = (collider pair) << FEATURE_BITS | feature within the pair


def swept_distances(model, body_velocity, body_angular_velocity, particle_velocity, dt):
    """How far each body and particle may move in a step of dt [s] at the given velocities,
    (B + P,) [m]: h |v|, plus for a body how far its farthest point turns, h |ω| r. This is the
    ``sweep`` argument of :func:`collide`."""
    body_reach = model.body_radii
    body = dt * (np.linalg.norm(body_velocity, axis=1) + np.linalg.norm(body_angular_velocity, axis=1) * body_reach)
    return np.concatenate([body, dt * np.linalg.norm(particle_velocity, axis=1)])


def _colliders(model, state):
    """Global collider arrays: kinds (N,), params (N,4), centres (N,3), rotations (N,3,3)."""
    kinds, params, _, obstacle_rotations = model.collider_table
    B, P = model.body_count, model.particle_count
    centers = np.concatenate([state.body_position, state.particle_position, model.obstacle_position])
    rots = np.empty((len(kinds), 3, 3))          # C order, which the compiled pair routines are built for
    rots[:B] = rotations.to_matrix(state.body_orientation)
    rots[B:B + P] = np.eye(3)
    rots[B + P:] = obstacle_rotations
    return kinds, params, centers, rots


@njit(cache=True)
def _bounds(kinds, params, centers, rots, margin):
    """Axis-aligned boxes (N,3) lower and upper of the colliders, grown by margin (N,) [m];
    planes infinite. Half-widths: a box |R| h, a capsule |axis| h + r, a convex hull its
    bounding sphere, a sphere or particle its radius."""
    N = kinds.shape[0]
    lower = np.empty((N, 3))
    upper = np.empty((N, 3))
    for n in range(N):
        kind = kinds[n]
        for i in range(3):
            if kind == shapes.PLANE:
                half = np.inf
            elif kind == shapes.BOX:
                half = abs(rots[n, i, 0]) * params[n, 0] + abs(rots[n, i, 1]) * params[n, 1] + \
                    abs(rots[n, i, 2]) * params[n, 2]
            elif kind == shapes.CAPSULE:
                half = abs(rots[n, i, 2]) * params[n, 1] + params[n, 0]
            elif kind == shapes.CONVEX:
                half = params[n, 1]
            else:
                half = params[n, 0]
            half += margin[n]
            lower[n, i] = centers[n, i] - half
            upper[n, i] = centers[n, i] + half
    return lower, upper


def collide(model, state, margin=0.0, sweep=None, granularity="vertex", normal="object", samples=2,
            cloth_samples=0) -> Contacts:
    """All contacts of the state, including gaps down to −margin [m]; the contacts of
    :func:`collide_keeping` with nothing kept."""
    return collide_keeping(model, state, None, 0.0, margin, sweep, granularity, normal, samples, cloth_samples)[0]


def collide_keeping(model, state, manifolds, tolerance, margin=0.0, sweep=None, granularity="vertex",
                    normal="object", samples=2, cloth_samples=0):
    """All contacts of the state, including gaps down to −margin [m], and the contact manifolds
    to keep for the next step: (Contacts, Manifolds or None).

    manifolds: what the last step's call returned (None: nothing kept); tolerance [m]: how far
    a pair of boxes, hulls or planes may have moved, relative to each other, and still reuse
    its kept contacts (collision.manifolds); 0 computes every pair afresh and keeps nothing.

    granularity ("object" | "vertex" | "samples", SPEC P2a/b/c), normal ("object" | "vertex",
    SPEC P4/P5) and samples (per triangle edge, for "samples") choose how boxes and convex
    bodies touch static planes, spheres, boxes and meshes (see collision.granularity); the
    defaults are the corner contacts with the surface's normal.

    sweep: optional (B + P,) distances [m] each body and particle may travel in the coming
    step. A pair's gaps are then reported down to −(margin + sweep_a + sweep_b), so a contact
    that the step's motion could close is found before it is crossed (speculative contacts:
    this is how nothing tunnels through a thin wall, however fast it moves).

    cloth_samples: besides its vertices (particles), sample every cloth triangle k × k times
    against the static obstacles (P2c, see collision.cloth); 0: vertices only. The vertices of
    one cloth never collide with each other here (their springs keep them apart).
    """
    B, P, O = model.body_count, model.particle_count, model.obstacle_count
    dynamic = B + P
    kinds, params, centers, rots = _colliders(model, state)
    # each collider reaches half the margin plus its own sweep; a pair, the sum of the two
    reach = np.full(dynamic + O, 0.5 * float(margin))
    if sweep is not None:
        reach[:dynamic] += sweep
    lower, upper = _bounds(kinds, params, centers, rots, reach)
    dyn_pairs = overlapping_pairs(lower[:dynamic], upper[:dynamic])
    if len(getattr(model, "triangles", ())):                 # neighbours within one cloth: no contact
        cloth = np.concatenate([np.full(B, -1), model.particle_cloth])
        same = (cloth[dyn_pairs[:, 0]] >= 0) & (cloth[dyn_pairs[:, 0]] == cloth[dyn_pairs[:, 1]])
        dyn_pairs = dyn_pairs[~same]
    # dynamic × static: planes by signed distance of the bounds, other obstacles by box overlap
    mesh_parts = [_against_mesh(model, g, kinds, params, centers, rots, reach, lower, upper, dynamic)
                  for g in range(dynamic, dynamic + O) if kinds[g] == shapes.MESH]
    pairs = np.concatenate([dyn_pairs, static_pairs(lower, upper, kinds, params, dynamic)]).astype(np.int64)
    if granularity != "vertex" or normal != "object":
        reach_all = margin + (sweep.max() if sweep is not None and len(sweep) else 0.0)
        surface_parts, bodies, obstacles = polytope_contacts(model, state, granularity, normal, samples,
                                                             reach_all, dynamic + O)
        replaced = np.isin(pairs[:, 0], bodies) & np.isin(pairs[:, 1], dynamic + obstacles)
        pairs = pairs[~replaced]
        mesh_parts = [tuple(column[~(np.isin(part[0], bodies) & np.isin(part[1], dynamic + obstacles))]
                            for column in part) for part in mesh_parts] + surface_parts
    families = model.pair_families          # only these pair routines are compiled (narrow_phase.FAMILIES)
    hulls = model.hull_store if needs_hulls(families) else None
    if tolerance > 0.0:
        contact_point, contact_normal, depth, feature, owner, manifolds = generate_reusing(
            pairs, kinds, params, centers, rots, reach, hulls, families, manifolds, tolerance, dynamic + O)
    else:
        contact_point, contact_normal, depth, feature, owner = generate_contacts(
            pairs, kinds, params, centers, rots, reach[pairs[:, 0]] + reach[pairs[:, 1]], hulls, families)
        manifolds = None
    parts = [(pairs[owner, 0], pairs[owner, 1], contact_point, contact_normal, depth, feature)] + mesh_parts
    a, b, contact_point, contact_normal, depth, feature = (np.concatenate(column) for column in zip(*parts))
    found = Contacts.empty() if len(a) == 0 else _assemble(model, a, b, contact_point, contact_normal, depth,
                                                           feature, dynamic + O)
    if cloth_samples > 0 and len(getattr(model, "triangles", ())):
        reach_cloth = margin + (sweep[B:].max(initial=0.0) if sweep is not None else 0.0)
        found = Contacts.concatenate([found, cloth_sample_contacts(model, state, cloth_samples, normal, reach_cloth,
                                                                   (dynamic + O) ** 2)])
    return found, manifolds


def _against_mesh(model, g, kinds, params, centers, rots, reach, lower, upper, dynamic):
    """Contacts of the dynamic colliders near mesh obstacle ``g`` (global index) with it."""
    mesh = model.meshes[int(params[g, 0])]
    grow = mesh.max_depth + reach[g]
    near = ((lower[:dynamic] <= mesh.bounds[1] + grow) & (mesh.bounds[0] - grow <= upper[:dynamic])).all(axis=1)
    near &= np.isin(kinds[:dynamic], MESH_PARTNERS)
    chosen = np.nonzero(near)[0]
    point, normal, depth, feature, owner = shapes_against_mesh_extended(
        kinds[chosen], params[chosen], centers[chosen], rots[chosen], reach[chosen] + reach[g], model.hull_store,
        mesh.geometry, MAX_PER_SHAPE)
    return chosen[owner], np.full(len(owner), g), point, normal, depth, feature


def _side(model, collider):
    """Body index, particle indices (C,3) and weights (C,3) of each collider's side."""
    B, P = model.body_count, model.particle_count
    body = np.where(collider < B, collider, -1)
    particles = np.full((len(collider), 3), -1, dtype=np.int64)
    weights = np.zeros((len(collider), 3))
    is_particle = (collider >= B) & (collider < B + P)
    particles[is_particle, 0] = collider[is_particle] - B
    weights[is_particle, 0] = 1.0
    return body, particles, weights


def _assemble(model, a, b, point, normal, depth, feature, total):
    body_a, particles_a, weights_a = _side(model, a)
    body_b, particles_b, weights_b = _side(model, b)
    materials = model.collider_table[2]
    mat_a, mat_b = materials[a], materials[b]
    t1, t2 = tangent_basis(normal)
    friction, restitution = model.pair_materials(mat_a, mat_b)
    return Contacts(
        body_a=body_a, body_b=body_b, particles_a=particles_a, particles_b=particles_b,
        weights_a=weights_a, weights_b=weights_b, point=point, normal=normal, depth=depth,
        tangent1=t1, tangent2=t2, friction=friction, restitution=restitution,
        feature_id=((a * total + b) << FEATURE_BITS) | feature,
    )

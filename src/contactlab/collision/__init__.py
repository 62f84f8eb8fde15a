"""Collision detection: ``collide(model, state) -> Contacts``. It knows nothing of responses.

Colliders are numbered globally: rigid bodies 0..B−1, particles B..B+P−1 (spheres of their
contact radius), static obstacles B+P..B+P+O−1. Dynamic pairs come from the sweep-and-prune
broad phase; each dynamic collider is tested against the obstacles its bounds reach.
"""

from __future__ import annotations

from collections import namedtuple
from typing import TYPE_CHECKING

import numpy as np
from numba import types
from numba.extending import overload

from .. import rotations, shapes
from ..compiling import in_python, inlined, njit
from ..contacts import ContactArrays, Contacts, tangent_frames
from ..errors import InputError
from ..model import derived
from .broad_phase import GRID_FROM, boxes_overlapping, static_pairs
from .cloth import cloth_face_contacts, cloth_sample_contacts
from .cloth_self import cloth_self_contacts
from .contact_output import FEATURE_BITS as FEATURE_BITS  # re-exported: contact ids are (pair << it) | feature
from .families import keeps_manifolds, pair_families
from .geometry import norm
from .granularity import GRANULARITIES as GRANULARITIES  # re-exported: the option values
from .granularity import NORMALS as NORMALS
from .granularity import DetectionSettings as DetectionSettings  # re-exported: collide_keeping takes it
from .granularity import polytope_contacts
from .manifolds import Manifolds, reuse_or_generate
from .mesh_contacts import MAX_PER_SHAPE, MESH_PARTNERS, shapes_against_mesh
from .narrow_phase import generate_contacts, needs_hulls, supported

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


@derived
def check_supported(model: Model) -> None:
    """Raise InputError naming the first pair of shapes in the model with no contact routine
    (checked once a model: kept with it once it passes)."""
    kinds = np.concatenate([model.body_shape, np.full(model.particle_count, shapes.POINT)])
    dynamic, counts = np.unique(kinds, return_counts=True)
    count_of = dict(zip(dynamic.tolist(), counts.tolist()))
    static = sorted(set(model.obstacle_shape.tolist()))
    for a in dynamic.tolist():
        partners = [b for b in dynamic.tolist() if b > a or (b == a and count_of[a] > 1)] + static
        for b in partners:
            if not supported(a, b):
                raise InputError(
                    "bodies",
                    f"contact between a {shapes.NAMES[a]} and a {shapes.NAMES[b]} "
                    "is not supported yet; change the shape of one of them",
                )


def swept_distances(
    model: Model, body_velocity: np.ndarray, body_angular_velocity: np.ndarray, particle_velocity: np.ndarray, dt: float
) -> np.ndarray:
    """How far each body and particle may move in a step of dt [s] at the given velocities,
    (B + P,) [m]: h |v|, plus for a body how far its farthest point turns, h |ω| r. This is the
    ``sweep`` argument of :func:`collide` (``swept_reach``, which the compiled loop runs, with no
    margin)."""
    return swept_reach(
        colliders(model).radius,
        np.asarray(body_velocity, dtype=float),
        np.asarray(body_angular_velocity, dtype=float),
        np.asarray(particle_velocity, dtype=float),
        float(dt),
        0.0,
    )[: model.body_count + model.particle_count]


@njit(cache=True)
def swept_reach(
    radius: np.ndarray,
    body_velocity: np.ndarray,
    angular_velocity: np.ndarray,
    particle_velocity: np.ndarray,
    h: float,
    margin: float,
) -> np.ndarray:
    """How far each collider reaches in a step of h [s], (N,) [m] for the N of ``radius`` (each
    collider's bounding radius [m], bodies first, then particles and obstacles): half the
    contact ``margin`` [m], plus for a body the distance it sweeps, h (|v| + |ω| r), and for a
    particle h |v| (body_velocity, angular_velocity (B, 3), particle_velocity (P, 3))."""
    B, P = body_velocity.shape[0], particle_velocity.shape[0]
    reach = np.full(radius.shape[0], 0.5 * margin)
    for b in range(B):
        reach[b] += h * (_norm(body_velocity[b]) + _norm(angular_velocity[b]) * radius[b])
    for p in range(P):
        reach[B + p] += h * _norm(particle_velocity[p])
    return reach


_norm = inlined(norm)  # geometry.norm, inlined into swept_reach


Colliders = namedtuple(
    "Colliders",
    (
        "kinds",  # (N,) int64 shape kind of each collider (contactlab.shapes)
        "params",  # (N, 4) its shape parameters [m] (Model.collider_table)
        "radius",  # (N,) bounding radii [m]
        "materials",  # (N,) int64 material index
        "material_friction",  # (M,)
        "material_restitution",  # (M,)
        "obstacle_position",  # (O, 3) [m]
        "obstacle_rotation",  # (O, 3, 3) obstacle → world
        # (B + P,) int64 the cloth of each body and particle (−1: none), whose vertices make no
        # pair with one another
        "cloth_of",
        "body_count",  # B
    ),
)
Colliders.__doc__ = """A model's colliders as detection reads them, bodies 0..B−1, particles B..B+P−1, obstacles
B+P..N−1: what does not move. Writable copies (Numba types a read-only array apart), built once a Model
(``colliders``); the compiled loop's LoopModel holds the same value."""


@derived
def colliders(model: Model) -> Colliders:
    """The Colliders of ``model``, built on first use and kept with it."""
    kinds, params, materials, obstacle_rotation = model.collider_table
    copy = np.array  # np.array copies: a writable, contiguous array
    return Colliders(
        copy(kinds, dtype=np.int64),
        copy(params, dtype=float),
        copy(shapes.bounding_radii(kinds, params), dtype=float),
        copy(materials, dtype=np.int64),
        copy(model.material_friction, dtype=float),
        copy(model.material_restitution, dtype=float),
        copy(model.obstacle_position, dtype=float),
        copy(obstacle_rotation, dtype=float),
        dynamic_cloth(model),
        model.body_count,
    )


def dynamic_cloth(model: Model) -> np.ndarray:
    """The cloth of each body and particle (B + P,) int64, −1 none (bodies never): ``Colliders``'
    ``cloth_of`` (whose vertices make no pair with one another), and the load paths of penalty's
    springs (``penalty_springs.along_springs``)."""
    return np.concatenate((np.full(model.body_count, -1, dtype=np.int64), np.asarray(model.particle_cloth, np.int64)))


Plan = namedtuple("Plan", ("families", "hull_store", "large"))
Plan.__doc__ = """What the broad and narrow phase compile for a scene: its pair families (``pair_families``),
its hull store (None where no family needs hulls) and ``large`` (True: at least GRID_FROM bodies and
particles, the grid broad phase; None: never). What detection and a sample's fresh pass both take."""


@derived
def detection_plan(model: Model) -> Plan:
    """The Plan of ``model``'s detection, built once a Model."""
    families = pair_families(model)
    large = True if model.body_count + model.particle_count >= GRID_FROM else None
    return Plan(families, model.hull_store if needs_hulls(families) else None, large)


def keeping_for(model: Model, tolerance: float) -> bool | None:
    """Whether ``model``'s detection keeps manifolds at this manifold ``tolerance`` [m]: True
    where it is > 0 and a pair family of the scene keeps them (``keeps_manifolds``), else None —
    the ``keeping`` of :func:`detect`, which as None compiles no reuse."""
    return True if tolerance > 0.0 and keeps_manifolds(pair_families(model)) else None


def state_poses(model: Model, state: State) -> tuple[np.ndarray, np.ndarray]:
    """The colliders' centres (N, 3) [m] and rotations (N, 3, 3) at ``state``'s positions
    (``collider_poses``)."""
    table = colliders(model)
    return collider_poses(
        state.body_position,
        rotations.to_matrix(state.body_orientation),
        state.particle_position,
        table.obstacle_position,
        table.obstacle_rotation,
    )


@njit(cache=True)
def collider_poses(
    body_position: np.ndarray,
    body_rotation: np.ndarray,
    particle_position: np.ndarray,
    obstacle_position: np.ndarray,
    obstacle_rotation: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, 3) [m] and rotations (N, 3, 3) (collider → world, C order, which the
    compiled pair routines are built for) of every collider: bodies (B, 3) and (B, 3, 3),
    particles (P, 3) (unrotated), obstacles (O, 3) and (O, 3, 3)."""
    B, P, O = body_position.shape[0], particle_position.shape[0], obstacle_position.shape[0]
    centers = np.empty((B + P + O, 3))
    rots = np.zeros((B + P + O, 3, 3))
    for n in range(B + P + O):
        for i in range(3):
            if n < B:
                centers[n, i] = body_position[n, i]
            elif n < B + P:
                centers[n, i] = particle_position[n - B, i]
                rots[n, i, i] = 1.0
            else:
                centers[n, i] = obstacle_position[n - B - P, i]
            for j in range(3):
                if n < B:
                    rots[n, i, j] = body_rotation[n, i, j]
                elif n >= B + P:
                    rots[n, i, j] = obstacle_rotation[n - B - P, i, j]
    return centers, rots


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
                half = (
                    abs(rots[n, i, 0]) * params[n, 0]
                    + abs(rots[n, i, 1]) * params[n, 1]
                    + abs(rots[n, i, 2]) * params[n, 2]
                )
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


@njit(cache=True)
def candidate_pairs(
    kinds: np.ndarray,
    params: np.ndarray,
    centers: np.ndarray,
    rots: np.ndarray,
    reach: np.ndarray,
    dynamic: int,
    cloth_of: np.ndarray,
    large: bool | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The broad phase: (lower, upper) bounds (N, 3) [m] of the colliders grown by ``reach``
    (N,) [m], and the candidate pairs (K, 2) int64 — the dynamic pairs (colliders 0 … dynamic−1)
    whose bounds overlap, sorted, then each dynamic collider against the static obstacles
    (``static_pairs``; meshes apart). ``cloth_of`` (dynamic,) int: the cloth of each dynamic
    collider (−1 none); two vertices of one cloth make no pair (their springs keep them apart).
    Always an array, so that a lone body's run compiles the same loop as a stack's (one kind of
    run, not one per count). ``large``: as
    ``broad_phase.boxes_overlapping`` takes it."""
    lower, upper = _bounds(kinds, params, centers, rots, reach)
    statics = static_pairs(lower, upper, kinds, params, dynamic)
    if dynamic < 2:  # one body or none: its static pairs are all (no empty sweep, no copy a step)
        return lower, upper, statics
    dynamic_pairs = boxes_overlapping(lower[:dynamic], upper[:dynamic], large)
    pairs = np.empty((dynamic_pairs.shape[0] + statics.shape[0], 2), dtype=np.int64)
    count = 0
    for k in range(dynamic_pairs.shape[0]):
        a, b = dynamic_pairs[k, 0], dynamic_pairs[k, 1]
        if cloth_of[a] >= 0 and cloth_of[a] == cloth_of[b]:
            continue
        pairs[count, 0], pairs[count, 1] = a, b
        count += 1
    for k in range(statics.shape[0]):
        pairs[count, 0], pairs[count, 1] = statics[k, 0], statics[k, 1]
        count += 1
    return lower, upper, pairs[:count]


@njit(cache=True, inline="always")
def detect(
    table: Colliders,
    plan: Plan,
    keeping: bool | None,
    at: tuple[np.ndarray, np.ndarray],
    reach: np.ndarray,
    kept: tuple,
    tolerance: float,
    replaced: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[ContactArrays, tuple, bool]:
    """Detection (stage 3 of every loop): the contacts of the colliders at centres and rotations
    ``at`` = ((N, 3) [m], (N, 3, 3)) within ``reach`` (N,) [m] of each other (speculative contacts),
    from the broad phase (``candidate_pairs``), the narrow phase and their assembly. Box, hull
    and plane pairs that barely moved reuse the ``kept`` manifolds (Manifolds' eight fields)
    when ``tolerance`` [m] > 0. ``plan``: what the broad and narrow phase are compiled for (its
    ``large`` None: never a grid broad phase); ``keeping`` None: never a kept manifold
    (``keeping_for``); ``replaced`` = (mask of a, mask of b), two (N,) bool: the pairs (a, b)
    another granularity makes (``collision.granularity``), None: none. Both as None leave their
    code uncompiled.

    The one detection: the compiled loop inlines it, ``collide_keeping`` runs it as Python
    (``compiling.in_python``: the same code calling the same compiled kernels). Returns (ContactArrays, the manifolds to
    keep, whether the broad phase found any pair)."""
    centers, rots = at
    dynamic = table.kinds.shape[0] - table.obstacle_position.shape[0]
    _, _, pairs = candidate_pairs(table.kinds, table.params, centers, rots, reach, dynamic, table.cloth_of, plan.large)
    pairs = _without_replaced(pairs, replaced)
    if pairs.shape[0] == 0:  # nothing near: no narrow phase, nothing kept, nothing to assemble
        return no_contacts(), _none_kept(kept), False
    point, normal, depth, feature, owner, made = _kept_or_fresh(keeping, table, plan, pairs, at, reach, kept, tolerance)
    if depth.shape[0] == 0:
        return no_contacts(), made, True
    contacts = assemble_contacts(pairs[owner, 0], pairs[owner, 1], point, normal, depth, feature, table)
    return contacts, made, True


def _kept_or_fresh(keeping, table, plan, pairs, at, reach, kept, tolerance):  # type: ignore[no-untyped-def]
    """The narrow phase of ``detect`` over ``pairs`` (K, 2): (point, normal, depth, feature, owner
    — ``generate_contacts``' —, the manifolds to keep). Pairs that moved less than ``tolerance``
    [m] reuse their ``kept`` manifolds (``reuse_or_generate``) where ``keeping``, else all are
    generated afresh and nothing is kept. (Unannotated: Numba holds an implementation to the
    signature of the function it implements, annotations included.)"""
    if keeping is None or not tolerance > 0.0:
        return _fresh(table, plan, pairs, at, reach, kept)
    found, made = reuse_or_generate(table, plan, pairs, at, reach, kept, tolerance)
    return (*found, made)


# compiled, chosen by the type of ``keeping``: as None, the reuse is not compiled at all
@overload(_kept_or_fresh, inline="always")
def _kept_or_fresh_compiled(keeping, table, plan, pairs, at, reach, kept, tolerance):  # type: ignore[no-untyped-def]
    if isinstance(keeping, types.NoneType):
        return lambda keeping, table, plan, pairs, at, reach, kept, tolerance: _fresh(
            table, plan, pairs, at, reach, kept
        )
    return _kept_or_fresh


def _without_replaced(pairs, replaced):  # type: ignore[no-untyped-def]
    """``pairs`` (K, 2) less those (a, b) where ``replaced`` = (mask of a, mask of b), two (N,)
    bool, marks both: their contacts come from ``granularity.polytope_contacts`` instead.
    ``pairs`` itself where ``replaced`` is None."""
    if replaced is None:
        return pairs
    side_a, side_b = replaced
    return pairs[~(side_a[pairs[:, 0]] & side_b[pairs[:, 1]])]


# compiled, chosen by the type of ``replaced``: as None, nothing of the filter is compiled
@overload(_without_replaced, inline="always")
def _without_replaced_compiled(pairs, replaced):  # type: ignore[no-untyped-def]
    if isinstance(replaced, types.NoneType):
        return lambda pairs, replaced: pairs
    return _without_replaced


@njit(cache=True, inline="always")
def _fresh(table, plan, pairs, at, reach, kept):
    """``_kept_or_fresh`` with nothing kept: every pair's contacts generated, no manifold to keep."""
    pair_reach = reach[pairs[:, 0]] + reach[pairs[:, 1]]  # a pair's contacts: its two reaches summed
    found = generate_contacts(
        pairs, table.kinds, table.params, at[0], at[1], pair_reach, plan.hull_store, plan.families
    )
    return (*found, _none_kept(kept))


@njit(cache=True, inline="always")
def _none_kept(kept):
    """No manifold to keep: ``kept``'s eight fields, empty."""
    return (kept[0][:0], kept[1][:0], kept[2][:0], kept[3][:0], kept[4][:0], kept[5][:0], kept[6][:0], kept[7][:0])


@njit(cache=True)
def no_contacts() -> ContactArrays:
    """The ContactArrays of no contact, from two empty arrays (every field a view of one): what
    ``assemble_contacts`` gives for none, without its dozen allocations a step."""
    real = np.empty((0, 3))
    whole = np.empty((0, 3), dtype=np.int64)
    flat, ids = real.reshape(0), whole.reshape(0)
    return ContactArrays(ids, ids, whole, whole, real, real, real, real, flat, real, real, flat, flat, ids)


def collide(
    model: Model,
    state: State,
    margin: float = 0.0,
    sweep: np.ndarray | None = None,
    granularity: str = "vertex",
    normal: str = "object",
    samples: int = 2,
    cloth_samples: int = 0,
) -> Contacts:
    """All contacts of the state, including gaps down to −margin [m]; the contacts of
    :func:`collide_keeping` with nothing kept."""
    settings = DetectionSettings(margin, granularity, normal, samples, cloth_samples)
    return collide_keeping(model, state, None, 0.0, settings, sweep)[0]


def collide_keeping(
    model: Model,
    state: State,
    manifolds: Manifolds | None,
    tolerance: float,
    settings: DetectionSettings,
    sweep: np.ndarray | None = None,
    particle_motion: np.ndarray | None = None,
) -> tuple[Contacts, Manifolds | None]:
    """All contacts of the state, including gaps down to −margin [m], and the contact manifolds
    to keep for the next step: (Contacts, Manifolds or None), detected as ``settings`` (a
    :class:`DetectionSettings`: margin, granularity, normal, samples, cloth_samples, cloth_faces) say.

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
    against the static obstacles (P2c, see collision.cloth); 0: vertices only. Either way a box's
    or sphere's edge or corner that reaches a triangle between its vertices makes a contact there
    (``collision.cloth.cloth_face_contacts``) unless ``cloth_faces`` is False. The vertices of
    one cloth make no particle contacts with each other (their springs keep them apart); the
    cloths whose ``self_collision`` is on meet themselves and each other as surfaces instead,
    vertex–triangle and edge–edge (collision.cloth_self); particle_motion (P, 3) [m], each
    particle's predicted displacement over the step, lets those reach only as far as the
    particles move relative to each other (None: as far as the sweep).
    """
    margin, granularity, normal, samples = settings.margin, settings.granularity, settings.normal, settings.samples
    cloth_samples = settings.cloth_samples
    B, P, O = model.body_count, model.particle_count, model.obstacle_count
    dynamic = B + P
    table, plan = colliders(model), detection_plan(model)
    centers, rots = state_poses(model, state)
    # each collider reaches half the margin plus its own sweep; a pair, the sum of the two
    reach = np.full(dynamic + O, 0.5 * float(margin))
    if sweep is not None:
        reach[:dynamic] += sweep
    # dynamic × static: planes by signed distance of the bounds, other obstacles by box overlap
    parts = []
    meshes = mesh_table(model)
    if meshes is not None:
        bounds = _bounds(table.kinds, table.params, centers, rots, reach)
        parts.append(mesh_contacts(meshes, table.kinds, table.params, centers, rots, reach, bounds, dynamic))
    replaced = None
    if granularity != "vertex" or normal != "object":
        reach_all = margin + (sweep.max() if sweep is not None and len(sweep) else 0.0)
        surface_parts, bodies, obstacles = polytope_contacts(
            model, state, granularity, normal, samples, reach_all, dynamic + O
        )
        replaced = (np.zeros(dynamic + O, dtype=np.bool_), np.zeros(dynamic + O, dtype=np.bool_))
        replaced[0][bodies] = True
        replaced[1][dynamic + np.asarray(obstacles, dtype=np.int64)] = True
        parts = [tuple(column[~(replaced[0][part[0]] & replaced[1][part[1]])] for column in part) for part in parts]
        parts += surface_parts
    keeping = keeping_for(model, tolerance)
    kept = tuple(vars(manifolds if manifolds is not None and keeping else Manifolds.empty()).values())
    arrays, made, _ = in_python(detect)(table, plan, keeping, (centers, rots), reach, kept, tolerance, replaced)
    found = Contacts.from_arrays(arrays)
    if parts:
        a, b, point, unit, depth, feature = (np.concatenate(column) for column in zip(*parts))
        if len(a):
            # the pairs' contacts found outside ``detect`` (meshes, other granularities)
            outside = Contacts.from_arrays(assemble_contacts(a, b, point, unit, depth, feature, table))
            found = Contacts.concatenate([found, outside])
    if len(model.triangles):
        reach_cloth = margin + (sweep[B:].max(initial=0.0) if sweep is not None else 0.0)
        if settings.cloth_faces:
            found = Contacts.concatenate([found, cloth_face_contacts(model, state, reach_cloth, (dynamic + O) ** 2)])
        if cloth_samples > 0:
            sampled = cloth_sample_contacts(model, state, cloth_samples, normal, reach_cloth, (dynamic + O) ** 2)
            found = Contacts.concatenate([found, sampled])
    if len(model.triangles) and model.cloth_self_collision.any():
        found = Contacts.concatenate([found, cloth_self_contacts(model, state, margin, sweep, particle_motion)])
    return found, (Manifolds(*made) if tolerance > 0.0 else None)


def pass_through_depths(model: Model, contacts: Contacts) -> np.ndarray:
    """(C,) [m]: for each contact, the overlap at which one side would reach the other's middle
    — the sum of the two colliders' half thicknesses (``Model.collider_half_thickness``). Deeper
    than that the contact's normal no longer says which way is out: a force along it may push
    a body on through. See ``half_thickness_sums``."""
    return half_thickness_sums(
        np.asarray(contacts.feature_id, dtype=np.int64),
        np.asarray(contacts.particles_a, dtype=np.int64),
        np.asarray(model.collider_half_thickness, dtype=float),
        np.asarray(model.particle_radius, dtype=float),
        model.body_count + model.particle_count,
    )


@njit(cache=True)
def half_thickness_sums(
    feature_id: np.ndarray, particles_a: np.ndarray, thickness: np.ndarray, particle_radius: np.ndarray, dynamic: int
) -> np.ndarray:
    """``pass_through_depths``, compiled (the penalty step and its compiled loop take it): the
    colliders are read from the contact ids (collider pair a · N + b; cloth samples: N² +
    triangle · O + obstacle, see collision.cloth, side A then the cloth's thickness, its first
    vertex's radius). feature_id (C,) int64, particles_a (C, 3), thickness (N,) [m],
    particle_radius (P,) [m], ``dynamic`` = B + P. Returns (C,) [m]."""
    total = thickness.shape[0]
    obstacles = max(total - dynamic, 1)
    out = np.empty(feature_id.shape[0])
    for c in range(feature_id.shape[0]):
        pair = feature_id[c] >> FEATURE_BITS
        if pair >= total * total:
            out[c] = particle_radius[particles_a[c, 0]] + thickness[dynamic + (pair - total * total) % obstacles]
        else:
            out[c] = thickness[pair // total] + thickness[pair % total]
    return out


MeshTable = namedtuple("MeshTable", ("obstacle", "lower", "upper", "max_depth", "geometry", "hull_store"))
MeshTable.__doc__ = """A model's static meshes as ``mesh_contacts`` takes them: the global collider index of each
mesh obstacle (M,) int64, its bounds (M, 3), (M, 3) [m], its max_depth (M,) [m], the MeshGeometry of each (a
tuple of M) and the model's hull store (for hulls against a mesh)."""


@derived
def mesh_table(model: Model) -> MeshTable | None:
    """The MeshTable of ``model``, None where it has no mesh obstacle; built once per Model."""
    dynamic = model.body_count + model.particle_count
    found = [o for o in range(model.obstacle_count) if model.obstacle_shape[o] == shapes.MESH]
    if not found:
        return None
    kinds, params, _, _ = model.collider_table
    meshes = [model.meshes[int(params[dynamic + o, 0])] for o in found]
    return MeshTable(
        np.array([dynamic + o for o in found], dtype=np.int64),
        np.array([mesh.bounds[0] for mesh in meshes], dtype=float),
        np.array([mesh.bounds[1] for mesh in meshes], dtype=float),
        np.array([mesh.max_depth for mesh in meshes], dtype=float),
        tuple(mesh.geometry for mesh in meshes),
        model.hull_store,
    )


@njit(cache=True)
def mesh_contacts(
    meshes: MeshTable,
    kinds: np.ndarray,
    params: np.ndarray,
    centers: np.ndarray,
    rots: np.ndarray,
    reach: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    dynamic: int,
) -> tuple:
    """The contacts of the dynamic colliders (the first ``dynamic`` of kinds (N,), params (N, 4),
    centers (N, 3) [m], rots (N, 3, 3)) with the static meshes of ``meshes``, mesh after mesh:
    each collider whose broad-phase ``bounds`` (lower, upper (N, 3) [m], grown by ``reach`` (N,))
    overlap a mesh's bounds grown by its max_depth and reach, and that has a routine against
    meshes (MESH_PARTNERS), against that mesh (``shapes_against_mesh``). Returns (a, b) global
    collider indices (C,) int64 (b the mesh), point, normal (C, 3), depth (C,) [m], feature (C,)
    int64."""
    lower, upper = bounds
    parts = []
    for m in range(meshes.obstacle.shape[0]):
        g = meshes.obstacle[m]
        grow = meshes.max_depth[m] + reach[g]
        chosen = np.zeros(dynamic, dtype=np.int64)
        count = 0
        for n in range(dynamic):
            near = False
            for kind in MESH_PARTNERS:
                near |= kinds[n] == kind
            for i in range(3):
                near &= lower[n, i] <= meshes.upper[m, i] + grow and meshes.lower[m, i] - grow <= upper[n, i]
            if near:
                chosen[count] = n
                count += 1
        chosen = chosen[:count]
        point, normal, depth, feature, owner = shapes_against_mesh(
            kinds[chosen],
            params[chosen],
            centers[chosen],
            rots[chosen],
            reach[chosen] + reach[g],
            meshes.geometry[m],
            MAX_PER_SHAPE,
            meshes.hull_store,
        )
        parts.append((chosen[owner], np.full(owner.shape[0], g, dtype=np.int64), point, normal, depth, feature))
    total = 0
    for part in parts:
        total += part[0].shape[0]
    a, b = np.empty(total, dtype=np.int64), np.empty(total, dtype=np.int64)
    point, normal = np.empty((total, 3)), np.empty((total, 3))
    depth, feature = np.empty(total), np.empty(total, dtype=np.int64)
    start = 0
    for part in parts:
        end = start + part[0].shape[0]
        a[start:end], b[start:end], point[start:end], normal[start:end] = part[0], part[1], part[2], part[3]
        depth[start:end], feature[start:end] = part[4], part[5]
        start = end
    return a, b, point, normal, depth, feature


@njit(cache=True)
def assemble_contacts(
    a: np.ndarray,
    b: np.ndarray,
    point: np.ndarray,
    normal: np.ndarray,
    depth: np.ndarray,
    feature: np.ndarray,
    table: Colliders,
) -> ContactArrays:
    """The ContactArrays of contacts found between global colliders a and b (C,) int64 of
    ``table``, with point, normal (C, 3), depth (C,) [m] and feature (C,) int64 from the narrow
    phase: each side a body (index < B), a particle (weight 1) or static; the tangents
    (``tangent_basis``); the pair's materials combined as ``Model.pair_materials`` does
    (μ = √(μ_a μ_b), ε the larger); the persistent id (collider pair a · N + b) << FEATURE_BITS |
    feature, N the colliders."""
    materials, material_friction, material_restitution = (
        table.materials,
        table.material_friction,
        table.material_restitution,
    )
    total = table.kinds.shape[0]
    body_count = table.body_count
    particle_count = total - table.obstacle_position.shape[0] - body_count
    C = a.shape[0]
    body = np.full((2, C), -1, dtype=np.int64)
    particles = np.full((2, C, 3), -1, dtype=np.int64)
    weights = np.zeros((2, C, 3))
    friction = np.empty(C)
    restitution = np.empty(C)
    feature_id = np.empty(C, dtype=np.int64)
    for c in range(C):
        for side in range(2):
            collider = a[c] if side == 0 else b[c]
            if collider < body_count:
                body[side, c] = collider
            elif collider < body_count + particle_count:
                particles[side, c, 0] = collider - body_count
                weights[side, c, 0] = 1.0
        mat_a, mat_b = materials[a[c]], materials[b[c]]
        friction[c] = np.sqrt(material_friction[mat_a] * material_friction[mat_b])
        restitution[c] = max(material_restitution[mat_a], material_restitution[mat_b])
        feature_id[c] = ((a[c] * total + b[c]) << FEATURE_BITS) | feature[c]
    unit = np.ascontiguousarray(normal)
    t1, t2 = tangent_frames(unit)
    return ContactArrays(
        body[0],
        body[1],
        particles[0],
        particles[1],
        weights[0],
        weights[1],
        point,
        unit,
        depth,
        t1,
        t2,
        friction,
        restitution,
        feature_id,
    )

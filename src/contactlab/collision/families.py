"""Which pair routines a scene needs: the pair families (``FAMILIES``), the family of a pair of
shape kinds, and the families tuple of a scene that the compiled narrow phase
(:mod:`contactlab.collision.narrow_phase`, ``generate_contacts``) is specialised on.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from .. import shapes
from ..model import derived

if TYPE_CHECKING:
    from ..model import Model

SPHERE, BOX, PLANE, POINT, CAPSULE, CONVEX = (
    shapes.SPHERE,
    shapes.BOX,
    shapes.PLANE,
    shapes.POINT,
    shapes.CAPSULE,
    shapes.CONVEX,
)


# -- which pair routines a scene needs ------------------------------------------------------
#
# Compiling every pair routine costs some 30 s on a cold cache, most of it for pairs a scene
# never has (box–box and capsule–box alone are 10 s; a ball on the floor needs sphere_plane
# only). So the dispatch (``narrow_phase.generate_contacts``) is specialised on a *families*
# tuple, one entry per routine in FAMILIES: ``True`` where the scene can have such a pair,
# ``None`` where it cannot. Numba types the two apart, and the dispatch's branches for the
# ``None`` entries are dropped before it is typed, so their routines are never compiled. Each
# distinct tuple is one cached specialization (a scene of spheres and boxes on planes: four
# routines).

FAMILIES = (
    "sphere_sphere",
    "sphere_capsule",
    "sphere_box",
    "sphere_plane",
    "capsule_capsule",
    "capsule_box",
    "capsule_plane",
    "box_box",
    "box_plane",
    "sphere_convex",
    "capsule_convex",
    "convex_convex",
    "convex_plane",
)
HULL_FAMILIES = frozenset(("sphere_convex", "capsule_convex", "convex_convex", "convex_plane"))  # need hull_store
# the families whose pairs keep manifolds (``manifolds.kept_pairs``: boxes, hulls and planes)
KEPT_FAMILIES = ("box_box", "box_plane", "convex_convex", "convex_plane")
ALL_FAMILIES = (True,) * len(FAMILIES)  # every routine (collide_pair; tests)

_CLASS = {SPHERE: "sphere", POINT: "sphere", CAPSULE: "capsule", BOX: "box", CONVEX: "convex", PLANE: "plane"}
_ROUTINE = {
    ("sphere", "sphere"): "sphere_sphere",
    ("sphere", "capsule"): "sphere_capsule",
    ("sphere", "box"): "sphere_box",
    ("sphere", "plane"): "sphere_plane",
    ("capsule", "capsule"): "capsule_capsule",
    ("capsule", "box"): "capsule_box",
    ("capsule", "plane"): "capsule_plane",
    ("box", "box"): "box_box",
    ("box", "plane"): "box_plane",
    ("sphere", "convex"): "sphere_convex",
    ("capsule", "convex"): "capsule_convex",
    ("box", "convex"): "convex_convex",
    ("convex", "convex"): "convex_convex",
    ("convex", "plane"): "convex_plane",
}


def family(kind_a: int, kind_b: int) -> str | None:
    """The name in FAMILIES of the routine for a pair of shape kinds, in either order; None for
    a pair this narrow phase has no routine for (two planes; meshes, see collision.mesh_contacts)."""
    a, b = _CLASS.get(int(kind_a)), _CLASS.get(int(kind_b))
    return _ROUTINE.get((a, b)) or _ROUTINE.get((b, a))


def families_of(kind_pairs: Iterable[tuple[int, int]]) -> tuple:
    """The families tuple (see FAMILIES) of an iterable of (kind_a, kind_b) pairs."""
    present = {family(a, b) for a, b in kind_pairs}
    return tuple(True if name in present else None for name in FAMILIES)


def scene_families(dynamic_kinds: np.ndarray, static_kinds: np.ndarray) -> tuple:
    """The families tuple of a scene: every pair of two dynamic kinds present, a kind with itself
    included, and of a dynamic kind with a static one.

    A kind's pair with itself is compiled in even where the scene holds one collider of it: a
    box on the floor and a stack of boxes then share their families, and so their kind of run
    (``kernel_variants.variant_of``), where a second loop would cost tens of seconds and the
    routine a few; a dispatch branch never taken costs nothing.

    dynamic_kinds: (B + P,) the bodies' kinds and POINT per particle; static_kinds: (O,)."""
    kinds = np.unique(np.asarray(dynamic_kinds, dtype=np.int64)).tolist()
    statics = set(np.asarray(static_kinds, dtype=np.int64).tolist())
    pairs = [(a, b) for i, a in enumerate(kinds) for b in kinds[i:]]
    pairs += [(a, b) for a in kinds for b in statics]
    return families_of(pairs)


@derived
def pair_families(model: Model) -> tuple:
    """Which pair routines ``model``'s colliders can need (its families tuple, :func:`scene_families`
    of its bodies' and particles' kinds and its obstacles'): the compiled narrow phase is
    specialised on it, so only those routines are compiled; built on first use and kept with the model."""
    B, P = model.body_count, model.particle_count
    kinds = model.collider_table[0]
    return scene_families(kinds[: B + P], kinds[B + P :])


def needs_hulls(families: tuple) -> bool:
    """Whether a families tuple includes a routine that reads the hull store."""
    return any(flag is not None and name in HULL_FAMILIES for name, flag in zip(FAMILIES, families))


def keeps_manifolds(families: tuple) -> bool:
    """Whether a families tuple includes a pair that keeps manifolds (KEPT_FAMILIES): without
    one, no manifold is ever kept, and the reuse need not be compiled."""
    return any(flag is not None and name in KEPT_FAMILIES for name, flag in zip(FAMILIES, families))

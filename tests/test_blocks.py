"""Block Gauss-Seidel per contact manifold (issue 38, item 2; contactlab.methods.blocks): the
blocks, each block's exact LCP against Lemke's, and a box's weight split in one update."""

import numpy as np
import pytest
from conftest import cube_on_plane
from test_sweeps import problem, sphere_lattice

from contactlab import ModelBuilder
from contactlab.lcp import solve_lcp
from contactlab.methods import blocks, jacobian_rows, sequential

DT = 1 / 240


def two_boxes_on_a_floor():
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    b.add_body("box", half_extents=(0.05,) * 3, mass=1.0, position=(0, 0, 0.05), material="m")
    b.add_body("box", half_extents=(0.05,) * 3, mass=2.0, position=(0.01, 0.02, 0.15), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


def rows_of(model):
    """(contacts, rows, order, u) of the model at its start, as test_sweeps.problem makes them."""
    return problem(model)[1:5]


def test_blocks_hold_one_pair_of_bodies_each_in_the_sweep_order():
    """Two stacked boxes: the lower box's four floor corners are one block, the four corners
    between the boxes another; the upper block is swept first (its contacts are higher)."""
    contacts, rows, order, _ = rows_of(two_boxes_on_a_floor())
    members, starts = blocks.manifold_blocks(rows, order)
    assert sorted(members) == list(range(contacts.count)) and np.diff(starts).tolist() == [4, 4]
    first = members[:4]
    assert set(contacts.body_b[first]) == {1} and set(contacts.body_b[members[4:]]) == {-1}
    rank = np.argsort(order)
    for k in range(2):  # each block in the sweep order
        assert np.all(np.diff(rank[members[starts[k] : starts[k + 1]]]) > 0)
    # a lattice of spheres: one contact per pair of spheres, a block of its own; a particle's alone
    contacts, rows, order, _ = rows_of(sphere_lattice(side=3, layers=3))
    members, starts = blocks.manifold_blocks(rows, order)
    sizes = np.diff(starts)
    assert sizes.max() <= blocks.BLOCK and sorted(members) == list(range(contacts.count))


def test_a_blocks_normals_are_the_exact_lcp_answer():
    """Each block's LCP (x ≥ 0, w = A x + q ≥ 0, xᵀ w = 0, A its Delassus block, regularized) is
    solved as Lemke's algorithm solves it, for the two boxes and the velocities of a fall."""
    contacts, rows, order, u = rows_of(two_boxes_on_a_floor())
    u[0::6] += 0.2  # both boxes drifting sideways, the upper one falling faster: every contact approaches
    u[8] -= 0.3
    members, starts = blocks.manifold_blocks(rows, order)
    couplings = blocks.block_couplings(rows, members, starts)
    target = np.zeros(contacts.count)
    impulses = np.zeros((contacts.count, 3))
    for k in range(2):
        block = members[starts[k] : starts[k + 1]]
        A = couplings[k]
        # the block's coupling is J M⁻¹ Jᵀ of its normal rows: what a unit impulse does to each
        for b, c in enumerate(block):
            moved = np.zeros_like(u)
            jacobian_rows.apply_impulse(c, rows, 1.0, 0.0, 0.0, moved)
            np.testing.assert_allclose(jacobian_rows.row_products(rows, moved)[block, 0], A[:, b], atol=1e-12)
        q = jacobian_rows.row_products(rows, u)[block, 0] - target[block]
        scratch = (np.empty((4, 4)), np.empty(4), np.empty(4), np.empty(4), np.empty(4, np.int64))
        v = u.copy()
        blocks.block_normals(block, 4, A, rows, target, impulses, v, scratch)
        epsilon = blocks.REGULARIZATION * np.trace(A) / 4
        exact = solve_lcp(A + epsilon * np.eye(4), -q, method="lemke").lam
        np.testing.assert_allclose(impulses[block, 0], exact, rtol=1e-6, atol=1e-12)
        # the pushing corners stop, short by the regularization's ε λ (3e-10 m/s here); the others
        # separate
        w, x = jacobian_rows.row_products(rows, v)[block, 0], impulses[block, 0]
        np.testing.assert_allclose(w[x > 0], -epsilon * x[x > 0], atol=1e-13)
        assert np.all(w[x == 0] >= 0) and (x > 0).any()


def test_one_block_update_splits_a_resting_boxs_weight_evenly():
    """A box resting flat, no warm start: one block update gives each corner a quarter of m g h
    and stops it; one Gauss-Seidel sweep cannot (its first corner takes what it can alone)."""
    model, _ = cube_on_plane(mass=2.0)
    contacts, rows, order, u = rows_of(model)
    target = np.zeros(contacts.count)
    cold = np.zeros((contacts.count, 3))
    v = u.copy()
    impulses, sweeps, change = blocks.solve_in_blocks(rows, contacts.friction, target, v, (1, 1e-7), cold, order)
    np.testing.assert_allclose(impulses[:, 0], 2.0 * 9.81 * DT / 4, rtol=1e-6)
    np.testing.assert_allclose(v, 0.0, atol=1e-9)
    w = u.copy()
    plain, _, _ = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, w, (1, 1e-7), cold, (order, None)
    )
    assert np.ptp(plain[:, 0]) > 0.1 * plain[:, 0].max()


@pytest.mark.parametrize("side", [3])
def test_the_blocks_converge_to_the_plain_sweeps_answer(side):
    """On a lattice of spheres with friction pushed out of its overlaps, the block sweeps and the
    plain sweeps reach the same velocities (the LCP's answer) to the tolerance."""
    model = sphere_lattice(side=side, layers=3, friction=0.5)
    state, contacts, rows, order, u0, target = problem(model)
    cold = np.zeros((contacts.count, 3))
    u_blocks, u_plain = u0.copy(), u0.copy()
    blocks.solve_in_blocks(rows, contacts.friction, target, u_blocks, (2000, 1e-12), cold, order)
    sequential.solve_sequential_impulses(rows, contacts.friction, target, u_plain, (2000, 1e-12), cold, (order, None))
    np.testing.assert_allclose(u_blocks, u_plain, atol=1e-8)

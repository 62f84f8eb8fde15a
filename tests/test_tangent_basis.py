"""The contact tangent basis (contacts.tangent_basis): orthonormal and right-handed for any
normal, and continuous near the axes, where resting contacts' normals live — friction impulses
are stored along (t1, t2) and warm-start the next step, so a basis that jumps when a face
normal wobbles by a micro-radian applies last step's friction in the wrong direction."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from contactlab.contacts import tangent_basis

AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 1e-3))
def test_the_basis_is_orthonormal_and_right_handed(vector):
    n = np.array(vector)[None] / np.linalg.norm(vector)
    t1, t2 = tangent_basis(n)
    frame = np.stack([t1[0], t2[0], n[0]])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) > 0.999999  # (t1, t2, n) right-handed


def test_exact_axes_keep_the_basis_they_always_had():
    """n = ±x: t1 = n × ŷ; n = ±y, ±z: t1 = n × x̂ (so scenes resting on axis-aligned faces step
    exactly as before the basis was made continuous)."""
    t1, _ = tangent_basis(AXES)
    expected = [np.cross(n, [0, 1, 0]) if abs(n[0]) == 1 else np.cross(n, [1, 0, 0]) for n in AXES]
    np.testing.assert_array_equal(t1, np.array(expected))


def test_a_normal_a_hair_off_an_axis_keeps_the_axis_basis(rng):
    """Micro-radian wobbles of every sign around every axis (the noise of a resting box's face
    normal from step to step) move t1 and t2 by about as much, never by 90°."""
    exact_t1, exact_t2 = tangent_basis(AXES)
    for _ in range(50):
        wobbled = AXES + rng.normal(scale=1e-6, size=AXES.shape)
        wobbled /= np.linalg.norm(wobbled, axis=1, keepdims=True)
        t1, t2 = tangent_basis(wobbled)
        assert np.abs(t1 - exact_t1).max() < 1e-5
        assert np.abs(t2 - exact_t2).max() < 1e-5

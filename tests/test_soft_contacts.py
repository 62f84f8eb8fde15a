"""Soft contacts in substeps (issue 38, item 2; Box2D v3's soft step: ``contact_hertz``): the
implicit spring's coefficients, the sag it settles at — the closed form g/ω² per unit of load
over effective mass —, and the bounces it leaves alone."""

import numpy as np
import pytest
from conftest import ball_on_plane, cube_on_plane
from test_impulse import _two_box_stack

from contactlab import InputError, simulate
from contactlab.methods import sequential

G = 9.81
DT = 1 / 240


def soft(hertz):
    """Every step in 8 substeps with soft contacts of ``hertz``, each followed by a relaxing sweep."""
    return {"substeps": 8, "substep_when": "always", "contact_hertz": hertz}


def test_the_soft_rows_coefficients_are_the_implicit_damped_springs():
    """Catto's soft constraint for a spring of ω = 2π f, ζ = 10, over a substep h: bias rate
    ω / (2ζ + hω), mass scale a₂/(1 + a₂) and impulse scale 1/(1 + a₂), a₂ = hω (2ζ + hω), so that
    the two scales add to 1; the frequency capped at a quarter of the substep rate; 0 Hz rigid."""
    h = DT / 8
    bias_rate, mass_scale, impulse_scale = sequential.soft_contact(60.0, h)
    omega = 2 * np.pi * 60.0
    a2 = h * omega * (20.0 + h * omega)
    assert bias_rate == pytest.approx(omega / (20.0 + h * omega), rel=1e-14)
    assert mass_scale == pytest.approx(a2 / (1 + a2), rel=1e-14)
    assert mass_scale + impulse_scale == pytest.approx(1.0, rel=1e-14)
    assert sequential.soft_contact(1e6, h) == sequential.soft_contact(0.25 / h, h)
    assert sequential.soft_contact(0.0, h) == (0.0, 1.0, 0.0)


@pytest.mark.parametrize("method", ["impulse", "constraints"])
@pytest.mark.parametrize("hertz", [30.0, 60.0])
def test_a_resting_box_sinks_to_the_springs_static_deflection(method, hertz):
    """A cube on the floor settles where its soft corners carry its weight: each corner's row is a
    spring of stiffness k_eff ω² (k_eff its effective mass), and a quarter of the weight on each
    sinks it by g/ω² (0.28 mm at 30 Hz, 69 µm at 60 Hz), whatever its mass. It creeps sideways a
    little (33 µm in 2 s at 30 Hz; the rigid contacts' substeps: none), the sweep order's
    asymmetry acting on corners that now sink and rise."""
    model, _ = cube_on_plane(mass=3.0)
    run = simulate(model, method, DT, 2.0, soft(hertz))
    sag = G / (2 * np.pi * hertz) ** 2
    np.testing.assert_allclose(0.05 - run.state.body_position[0, 2], sag, rtol=1e-3)
    assert np.abs(run.state.body_position[0, :2]).max() < 5e-5


def test_a_heavy_box_sinks_a_light_one_by_the_mass_ratio():
    """1:1000 at 240 Hz: the light box's corners carry 1001 times its own weight, so it sinks
    1001 g/ω²; the corners between the boxes (effective mass that of the light box and the
    heavy one in series) 1000 weights of the heavy box: 1001 g/ω² more for it. A rigid contact
    holds both within 1 mm (test_impulse); a soft one sags with the mass ratio. The light box's
    corners sink unevenly (4.2–4.5 mm: the stack leans, the light box pushed 1 mm aside), so the
    heavy box's sag meets its closed form within 1 % (8.600 mm against 8.637), the light box's
    to 0.1 %."""
    run = simulate(_two_box_stack(1000.0), "impulse", DT, 3.0, soft(240.0))
    sag = G / (2 * np.pi * 240.0) ** 2
    sunk = [0.05, 0.15] - run.state.body_position[:, 2]
    np.testing.assert_allclose(sunk[0], 1001 * sag, rtol=1e-3)
    np.testing.assert_allclose(sunk[1], 2002 * sag, rtol=1e-2)


@pytest.mark.parametrize("restitution", [0.5, 0.8])
def test_soft_contacts_leave_the_bounces_alone(restitution):
    """A bounce is a rigid row (its target kept through the substeps) and the relaxing sweep reads
    the gaps the substep started from: the apexes follow h₀ ε²ⁿ as without soft contacts."""
    model = ball_on_plane(restitution=restitution, height=1.0)
    run = simulate(model, "constraints", 0.001, 2.5, soft(240.0))
    z, vz = run.arrays["body_position"][:, 0, 2] - 0.1, run.arrays["body_velocity"][:, 0, 2]
    turning = np.nonzero((vz[:-1] > 0) & (vz[1:] <= 0))[0]
    apexes = np.array([z[i : i + 2].max() for i in turning])
    np.testing.assert_allclose(apexes[:3], restitution ** (2 * np.arange(1, 4)), rtol=0.01)


def test_contact_hertz_must_not_be_negative():
    with pytest.raises(InputError, match="contact_hertz"):
        simulate(ball_on_plane(), "impulse", DT, 0.1, {"contact_hertz": -1.0})

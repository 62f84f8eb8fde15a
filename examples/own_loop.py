"""Your own loop: a Stepper steps the model, you read and change the state between steps.

    python3 examples/own_loop.py

A rubber ball (restitution 0.8) is dropped from 1 m onto the floor. The loop below is the
user's, as with MuJoCo's ``mj_step``: it steps the ball with the impulse method one millisecond
at a time, reads the height and the vertical velocity after each step (a sensor), keeps the
apex of every rebound (its own recording), and after the second rebound's apex acts (control):
it catches the ball, setting its velocity to zero in place, and holds it by setting it to zero
again before each step. It prints the apexes next to the closed form ε² h₀ and ε⁴ h₀ (h₀ the
height of the drop, the ball's radius left out), and where the held ball ends: a step of
symplectic Euler from rest moves it by −g dt² (the step's gravity acts before the next
zeroing), so n held steps lower it by n g dt² — the loop's control, to the last bit of the
integrator.
"""

from contactlab import ModelBuilder, Stepper

RADIUS, DROP, RESTITUTION = 0.1, 1.0, 0.8

builder = ModelBuilder()
builder.add_material("rubber", friction=0.5, restitution=RESTITUTION)
builder.add_body("sphere", radius=RADIUS, mass=1.0, position=(0.0, 0.0, RADIUS + DROP), material="rubber")
builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
model = builder.finalize()

stepper = Stepper(model, "impulse", dt=0.001)  # built once: the method, its options, dt
state = stepper.state  # the arrays the next step starts from: read them, write into them
apexes, rising, caught_at, held_steps = [], False, None, 0
while stepper.time < 2.5:
    if caught_at is not None:
        state.body_velocity[0] = 0.0  # control: hold the ball where it was caught
        held_steps += 1
    stepper.step()
    height, vertical = state.body_position[0, 2] - RADIUS, state.body_velocity[0, 2]
    if rising and vertical <= 0.0:  # sensor: the rebound's apex
        apexes.append(height)
        if len(apexes) == 2:
            caught_at = height
            state.body_velocity[0] = 0.0
    rising = vertical > 0.0

for k, apex in enumerate(apexes, start=1):
    print(f"apex {k}: {apex:.4f} m (closed form {RESTITUTION ** (2 * k) * DROP:.4f} m)")
held = state.body_position[0, 2] - RADIUS
expected = caught_at - held_steps * 9.81 * stepper.dt**2
print(f"held {held_steps} steps: at {held:.6f} m (caught at {caught_at:.6f} m, n g dt² lower: {expected:.6f} m)")
print(f"{stepper.steps_made} steps, {stepper.time:.3f} s, through the compiled loop: {stepper.compiled}")

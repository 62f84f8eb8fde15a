"""Plausibility: a scene whose numbers look like a unit slip gets one warning line before it runs.

A scene in which a ball has ``radius = 4`` meant as centimetres, or ``duration = 1500`` meant as
milliseconds, is valid — and runs to metres of penetration or three quarters of a million
steps without a word. :func:`warnings_for` looks for what such slips leave behind, each a
sentence naming the value and saying that metres, kilograms and seconds are the units:

* **a body far larger or smaller than the others**: its bounding radius more than
  :data:`SIZE_RATIO` times the bodies' median (or less than 1/SIZE_RATIO; with two bodies,
  the larger more than SIZE_RATIO times the other);
* **a body or particle starting deep inside something**: an initial overlap deeper than
  :data:`START_DEPTH_FRACTION` of the body's radius (1 cm into a 10 cm ball is a modelling
  choice; 3 m is not);
* **a run of very many steps**: more than :data:`MANY_STEPS` (duration / dt). The command line
  asks for ``--yes`` before it starts such a run (docs/cli.md); the API only warns.

They are warnings (``PlausibilityWarning``), never errors: a boulder beside pebbles is a
scene someone may mean. ``simulate`` issues them; ``warnings.simplefilter("ignore",
PlausibilityWarning)`` silences them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .collision import collide
from .model import derived

if TYPE_CHECKING:
    from .model import Model
    from .state import State


SIZE_RATIO = 20.0  # a body this many times the others' median size (or 1/this) is flagged
START_DEPTH_FRACTION = 0.25  # an initial overlap deeper than this share of the body's radius is flagged
MANY_STEPS = 500_000  # runs of more steps are flagged (the CLI asks for --yes)


class PlausibilityWarning(UserWarning):
    """A scene value that looks like a unit slip (contactlab.plausibility)."""


def warnings_for(model: Model, state: State, dt: float, steps: int) -> list[str]:
    """The sentences of every plausibility check ``model`` (at ``state``), stepped ``steps``
    times at ``dt`` [s], fails; [] when none does."""
    return [*_sizes(model), *_start_depths(model, state), *_step_count(dt, steps)]


def _sizes(model):
    """A body whose bounding radius is SIZE_RATIO times the bodies' median (of the other one,
    for two), or 1/SIZE_RATIO of it (three bodies or more)."""
    radii = np.asarray(model.body_radii, dtype=float)
    if len(radii) < 2:
        return []
    found = []
    for body, radius in enumerate(radii):
        typical = float(np.median(radii)) if len(radii) > 2 else float(radii[1 - body])
        ratio = radius / typical if typical > 0 else 1.0
        if ratio > SIZE_RATIO or (len(radii) > 2 and ratio < 1 / SIZE_RATIO):
            than = "the bodies' median" if len(radii) > 2 else "the other body's"
            found.append(
                f"{_body(model, body)} has a bounding radius of {radius:.3g} m, {ratio:.3g}× {than} "
                f"{typical:.3g} m: lengths are in metres"
            )
            if len(found) == 3:
                break
    return found


def _start_depths(model, state):
    """The sentences of the start-depth check: a collision pass, made once a model for its own
    initial positions (a study runs one model from there many times) and kept with it."""
    if all(a.tobytes() == b.tobytes() for a, b in zip(state.positions, model.initial.positions)):
        return list(_initial_start_depths(model))
    return _depth_sentences(model, state)


@derived
def _initial_start_depths(model):
    """``_depth_sentences`` at ``model``'s initial state, kept with the model."""
    return tuple(_depth_sentences(model, model.initial))


def _depth_sentences(model, state):
    """A sentence for each of up to three bodies starting deeper than START_DEPTH_FRACTION of
    its radius inside what it touches at ``state`` (a collision pass)."""
    contacts = collide(model, state)
    if not contacts.count:
        return []
    found, seen = [], set()
    for contact in np.argsort(-contacts.depth):
        depth = float(contacts.depth[contact])
        body = int(contacts.body_a[contact]) if contacts.body_a[contact] >= 0 else int(contacts.body_b[contact])
        if body < 0 or body in seen:
            continue
        seen.add(body)
        radius = float(model.body_radii[body])
        if depth > START_DEPTH_FRACTION * radius:
            found.append(
                f"{_body(model, body)} starts {depth:.3g} m deep inside what it touches (its bounding "
                f"radius is {radius:.3g} m): lengths are in metres; move it out, or is a size or a "
                f"position in other units?"
            )
        if len(found) == 3 or depth <= 0:
            break
    return found


def _step_count(dt, steps):
    if steps <= MANY_STEPS:
        return []
    return [f"the run makes {steps:,} steps (duration {steps * dt:.6g} s at dt = {dt:g} s): times are in seconds"]


def _body(model, body):
    return f"body {model.body_names[body]!r}"

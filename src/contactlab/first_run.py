"""Whether a command's run compiles its kernels or steps them as Python: the probe and the choice
(``contactlab run`` and ``demo`` call :func:`settle` before they write anything; see
:mod:`contactlab.kernel_variants` for the record of the kinds this machine has compiled, and
docs/cli.md, "Compiled or stepped as Python").
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from typing import TYPE_CHECKING

from . import interrupts
from .kernel_variants import compile_estimate, compiled_variants, variant_of

if TYPE_CHECKING:
    from .scene import Scene

CHOICE = "CONTACTLAB_KERNELS"  # set by settle() for the process it starts again: "probe" or "compiled"
INTERPRET_SHARE = 0.5  # step as Python where that takes at most this share of the compile it saves
PROBE_STEPS = 10  # the steps a probe times
PROBE_SECONDS = 1.0  # the most those may take by the first step's time, else the first step's time tells
FEW_COLLIDERS = 12  # bodies and particles: a probe without a contact still bounds such a scene's steps


def probe(scene: Scene, steps: int) -> float:
    """How long ``steps`` steps of ``scene`` take as this process runs them [s]: a run of one step
    (what a run sets up once, and first uses, in it) untimed, then one of one step and one of
    PROBE_STEPS more, whose difference is the cost of a step (the second only where the first says
    it takes at most about PROBE_SECONDS). Runs nothing of the real run: no file, no output;
    a probe the scene stops early (it diverges) counts as cheap: the run itself then says why.

    Steps without a contact are cheap as Python, those of a pile at rest are not (sphere_pile:
    under 0.1 s a step in the air, seconds once its thousand contacts form): where the probe's
    steps met no contact and the scene holds more than FEW_COLLIDERS bodies and particles, what
    they cost says nothing of the run's, and the answer is infinite (compile). A scene of a few
    colliders has few contacts whatever happens, and its probe stands."""
    from .errors import SimulationDiverged
    from .simulation import simulate

    met = [0]  # the most contacts a probe run met

    def seconds(count: int) -> float:
        started = time.perf_counter()
        with warnings.catch_warnings():  # the run itself says what the scene warrants
            warnings.simplefilter("ignore")
            try:
                run = simulate(scene.model, scene.method, scene.dt, count * scene.dt, options, scene.integrator)
            except SimulationDiverged:
                return 0.0
        met[0] = max(met[0], int(run.summary["max_contacts"]))
        return time.perf_counter() - started

    options = scene.options[scene.method]
    seconds(1)
    once = seconds(1)  # what a run costs besides its steps, and one step
    if once * PROBE_STEPS > PROBE_SECONDS or steps <= PROBE_STEPS:  # slow steps, or few: that is enough
        needed = once * steps
    else:
        needed = once + max(0.0, seconds(1 + PROBE_STEPS) - once) / PROBE_STEPS * (steps - 1)
    colliders = scene.model.body_count + scene.model.particle_count
    return needed if met[0] > 0 or colliders <= FEW_COLLIDERS else math.inf


def settle(scene: Scene, steps: int, restart: bool) -> None:
    """Before ``contactlab run`` writes anything: go on as this process is (compiled, or as Python
    where that was chosen), or start the command again in this process (``os.execv``), as Python to
    probe, or compiled after a probe (see the module docstring). ``restart`` False (a command
    called as a function, ``cli.main(argv)``): nothing changes."""
    choice = os.environ.get(CHOICE)
    if not restart or choice == "compiled" or ("NUMBA_DISABLE_JIT" in os.environ and choice != "probe"):
        return
    if choice != "probe":
        variant = variant_of(scene.model, scene.method, scene.options[scene.method], scene.integrator)
        if variant is not None and variant not in compiled_variants():
            _again(probe=True)
        return
    estimate = compile_estimate()
    needed = probe(scene, steps)
    if needed > INTERPRET_SHARE * estimate:
        _again(probe=False)
    print(
        f"stepping as Python: about {needed:.0f} s, where compiling this kind of run first would take "
        f"about {estimate:.0f} s ('contactlab compile' builds every kind once)",
        file=sys.stderr,
        flush=True,
    )


def _again(probe: bool) -> None:
    """Start this command anew in this process: as Python to probe (``probe``), else compiled."""
    interrupts.check()  # a Ctrl-C while the scene loaded stops here, not in the next process
    environment = dict(os.environ, **{CHOICE: "probe" if probe else "compiled"})
    if probe:
        environment["NUMBA_DISABLE_JIT"] = "1"
    else:
        environment.pop("NUMBA_DISABLE_JIT", None)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], environment)

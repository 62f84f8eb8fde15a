"""Where a first run's compiling goes: each compiled function's own share, and LLVM's.

    python3 benchmarks/compile_cost.py [SCENE] [METHOD] [loop|step|default]

Runs SCENE (default ``bouncing_ball``) under METHOD (default ``impulse``) once, in this process,
on an empty Numba cache of its own: through the compiled loop (``loop``: ``compiled_loop=True``),
through the methods' step (``step``), or at the defaults. Prints the wall time, then the
compilations by their own time (each one's time less that of the compilations nested in it),
then the time in Numba's three LLVM stages (per-function passes, the final module's optimization
with every linked callee, machine code), in all and for the largest libraries, then every
contactlab function compiled for more than one set of argument types in the run, with the
arguments that differ: a literal where a variable was meant (``Literal[bool](True)`` beside
``bool``), a read-only array beside a writable one, each a whole compile again. Issue 36's
compile-cost figures (benchmarks/README.md, twenty-third and twenty-fifth rounds) come from it.
"""

import collections
import os
import sys
import tempfile
import time

os.environ.setdefault("NUMBA_CACHE_DIR", tempfile.mkdtemp(prefix="compile_cost_"))

from numba.core import codegen, event  # noqa: E402

OWN, TOTAL, COUNT, LLVM = (collections.Counter() for _ in range(4))
_open = []  # [start, nested seconds] of the compilations under way


class _Compilations(event.Listener):
    def on_start(self, ev):
        _open.append([time.perf_counter(), 0.0])

    def on_end(self, ev):
        started, nested = _open.pop()
        spent = time.perf_counter() - started
        function = ev.data["dispatcher"].py_func
        name = f"{function.__module__.split('.')[-1]}.{function.__name__}"
        OWN[name] += spent - nested
        TOTAL[name] += spent
        COUNT[name] += 1
        if _open:
            _open[-1][1] += spent


def _timed(stage):
    original = getattr(codegen.JITCodeLibrary, stage)

    def timed(library, *args, **kwargs):
        started = time.perf_counter()
        result = original(library, *args, **kwargs)
        spent = time.perf_counter() - started
        LLVM[(stage, library.name.split(".")[-1][:40])] += spent
        LLVM[(stage, "all")] += spent
        return result

    setattr(codegen.JITCodeLibrary, stage, timed)


def main(argv):
    name = argv[0] if argv else "bouncing_ball"
    method = argv[1] if len(argv) > 1 else "impulse"
    path = argv[2] if len(argv) > 2 else "loop"
    for stage in ("_optimize_functions", "_optimize_final_module", "_finalize_specific"):
        _timed(stage)
    event.register("numba:compile", _Compilations())
    from contactlab import simulate
    from contactlab.scene import load_scene

    scene = load_scene(name)
    started = time.perf_counter()
    simulate(scene.model, method, scene.dt, scene.duration, compiled_loop={"loop": True, "step": False}.get(path))
    print(f"{name} {method} ({path}): {time.perf_counter() - started:.1f} s wall, {sum(COUNT.values())} compilations")
    print("\nown s   total s   times  function")
    for function, own in OWN.most_common(25):
        print(f"{own:6.2f}  {TOTAL[function]:8.2f}  {COUNT[function]:6d}  {function}")
    print("\nLLVM s  stage                   library")
    for (stage, library), spent in sorted(LLVM.items(), key=lambda item: -item[1])[:15]:
        print(f"{spent:6.2f}  {stage:22s}  {library}")
    print("\ncompiled more than once: function, then each argument whose type differs")
    for dispatcher in _dispatchers():
        signatures = [tuple(str(kind) for kind in signature) for signature in dispatcher.signatures]
        if len(signatures) > 1:
            function = dispatcher.py_func
            print(f"{len(signatures)}x  {function.__module__}.{function.__name__}")
            for index in range(min(map(len, signatures))):
                kinds = sorted({signature[index] for signature in signatures})
                if len(kinds) > 1:
                    print(f"      argument {index}: " + " | ".join(kind[:60] for kind in kinds))


def _dispatchers():
    """Every compiled function of contactlab's modules loaded in this process, once each."""
    from numba.core.registry import CPUDispatcher

    seen = {}
    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("contactlab"):
            for value in vars(module).values():
                if isinstance(value, CPUDispatcher):
                    seen[id(value)] = value
    return list(seen.values())


if __name__ == "__main__":
    main(sys.argv[1:])

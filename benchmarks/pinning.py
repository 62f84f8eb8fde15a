"""Thread pinning for the benchmark scripts, to run before NumPy or Numba is imported.

BLAS and every other thread pool get one thread (a benchmark measures contactlab's own
threads, not OpenBLAS's), and NUMBA_NUM_THREADS is set from ``--numba-threads N`` (or
``--numba-threads=N``; default 2): Numba reads it once, when it loads.
"""

import os


def pin_threads(argv):
    """Set the thread environment variables from the command line ``argv``."""
    numba_threads = "2"
    for i, arg in enumerate(argv):
        if arg == "--numba-threads" and i + 1 < len(argv):
            numba_threads = argv[i + 1]
        elif arg.startswith("--numba-threads="):
            numba_threads = arg.split("=", 1)[1]
    for name in (
        "OPENBLAS_NUM_THREADS",
        "OMP_NUM_THREADS",
        "MKL_NUM_THREADS",
        "VECLIB_MAXIMUM_THREADS",
        "NUMEXPR_NUM_THREADS",
    ):
        os.environ[name] = "1"
    os.environ["NUMBA_NUM_THREADS"] = numba_threads

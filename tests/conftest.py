"""Test-session set-up: each pytest-xdist worker computes on one thread.

The README's test command runs the suite on two worker processes (``-n 2``; CI has two
cores). A worker that also started two Numba (or BLAS) threads would ask for four cores on
two, and an OpenMP layer spin-waits on the cores it does not get (issue #14 measured 8x
slower steps that way). The variables must be set before NumPy and Numba are imported,
which is why this is done here, at conftest import, and only inside a worker (a serial
``pytest`` keeps every core).
"""

import os

if "PYTEST_XDIST_WORKER" in os.environ:
    for variable in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                     "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")

"""How softgrains uses threads: a wait policy that behaves on a busy machine, and one thread
for kernels too small to share (issue 14, item 5; benchmarks/threads_busy.py).

Numba's parallel kernels run on its OpenMP layer (GNU libgomp from the pip wheels). At its
default wait policy a thread that finishes its share spins for up to ~300k iterations
before sleeping; on a machine whose cores are busy with other processes a kernel then waits
for a descheduled partner, and the dense compaction ran 3× slower with 2 threads than with
1 (1.81 against 0.61 s a step with one competing process per core, 2026-12-05).
``OMP_WAIT_POLICY=PASSIVE`` makes the waiting threads sleep at once; it is set when the
package is imported, unless the user has set it (libgomp reads it when Numba first loads
it, so a program that ran an OpenMP library before importing softgrains keeps its policy).

A parallel kernel's fork and join cost 5–50 µs; a grain of the compaction (~300 points at
D/h 10) takes ~300 µs for its internal forces and tangent, and gains nothing from a second
thread. :func:`threads_for` runs kernels over fewer than :data:`PARALLEL_MIN_POINTS` points
on the calling thread alone. Instead, :func:`over_bodies` shares the bodies of a coupling
iteration among the run's threads: each body's Newton matrix, LU and compliance columns are
LAPACK calls that release the GIL.
"""

from __future__ import annotations

import os
import types
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor, wait
from typing import TypeVar

import numba

T = TypeVar("T")
R = TypeVar("R")

# below this many points a kernel runs on one thread (measured on this 2-core machine:
# internal forces and tangent at 316 points 1.04× faster on 2 threads, at 1264 points 1.3–2×)
PARALLEL_MIN_POINTS = 1000


def set_wait_policy() -> None:
    """Idle OpenMP threads sleep instead of spinning (OMP_WAIT_POLICY=PASSIVE), unless the
    environment says otherwise."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


class threads_for:  # noqa: N801 (used as a context manager, like a function)
    """``with threads_for(n_points): kernel(...)``: the Numba kernels inside run on one
    thread when ``n_points`` < PARALLEL_MIN_POINTS, else on the threads set for the run."""

    __slots__ = ("serial", "previous")

    def __init__(self, n_points: int) -> None:
        self.serial = n_points < PARALLEL_MIN_POINTS
        self.previous = 0

    def __enter__(self) -> None:
        if self.serial:
            self.previous = numba.get_num_threads()
            if self.previous > 1:
                numba.set_num_threads(1)

    def __exit__(self, *exc) -> None:
        if self.serial and self.previous > 1:
            numba.set_num_threads(self.previous)


class ParallelKernel:
    """A Numba kernel with ``prange`` loops compiled twice, on demand: parallel, and as a
    serial twin run wherever the calling thread has one Numba thread (a run on one thread,
    a body below PARALLEL_MIN_POINTS inside :class:`threads_for`, the workers of
    :func:`over_bodies`). The same loops in the same order give the same results; the
    twin only spares the compilation of the parallel version where it never runs: Numba's
    parfor lowering made ``point_stresses`` take 15.2 s to compile instead of 5.6 s, and
    the frictional example's first step from cold caches 56.7 s instead of 37.1 s
    (2026-12-06, this 2-core machine beside two other runs; a fresh clone's README job
    compiles in each of its two processes, each on one thread)."""

    def __init__(self, function: Callable, **options) -> None:
        self.parallel = numba.njit(parallel=True, **options)(function)
        # a function of its own name: Numba's cache files are named after the function's
        # qualified name, and its index key holds no compile flags (the twin and the
        # parallel version would read each other's machine code)
        twin = types.FunctionType(function.__code__, function.__globals__,
                                  f"{function.__name__}_serial", function.__defaults__,
                                  function.__closure__)
        twin.__qualname__ = f"{function.__qualname__}_serial"
        twin.__doc__ = function.__doc__
        self.serial = numba.njit(**options)(twin)
        self.__doc__, self.__name__ = function.__doc__, function.__name__

    def __call__(self, *args):
        kernel = self.serial if numba.get_num_threads() == 1 else self.parallel
        return kernel(*args)


def parallel_kernel(**options) -> Callable[[Callable], ParallelKernel]:
    """``@parallel_kernel(cache=True)`` in place of ``@njit(parallel=True, cache=True)``
    for a kernel called from Python (:class:`ParallelKernel`)."""
    return lambda function: ParallelKernel(function, **options)


_pools: dict[int, ThreadPoolExecutor] = {}


def concurrent_kernels() -> bool:
    """Whether Numba's threading layer lets several Python threads run parallel kernels at
    once: OpenMP and TBB do; the workqueue layer (chosen where neither is installed, e.g.
    macOS without libomp) aborts the process ("Concurrent access has been detected").
    False before the first parallel kernel has chosen the layer."""
    try:
        return numba.threading_layer() in ("omp", "tbb")
    except ValueError:
        return False


def over_bodies(function: Callable[[T], R], items: Iterable[T]) -> list[R]:
    """``[function(x) for x in items]`` with the items shared among the run's Numba threads
    (``numba.get_num_threads()`` Python threads, each running its kernels on one thread):
    for per-body work that is independent between bodies and spends its time in calls that
    release the GIL. The results come in the items' order and are those of the serial loop;
    every item is finished before the first exception in that order is raised (so the
    items after a failing one have run too: a caller undoes the whole step, not a part of
    it, as Simulation.step's retry does). Serial where
    the threading layer does not allow concurrent kernels (:func:`concurrent_kernels`)."""
    items = list(items)
    threads = numba.get_num_threads()
    if threads < 2 or len(items) < 2 or not concurrent_kernels():
        return [function(x) for x in items]
    if threads not in _pools:
        _pools[threads] = ThreadPoolExecutor(threads, thread_name_prefix="softgrains-body",
                                             initializer=numba.set_num_threads, initargs=(1,))
    futures = [_pools[threads].submit(function, x) for x in items]
    wait(futures)
    return [f.result() for f in futures]

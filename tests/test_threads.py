"""Threads that behave on a busy machine (issue 14, item 5; softgrains/threads.py)."""

import os
import subprocess
import sys

POLICY = "import softgrains, os; print(os.environ.get('OMP_WAIT_POLICY'))"


def _policy_in_a_fresh_process(**env) -> str:
    clean = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", POLICY], env=clean | env, check=True,
                         capture_output=True, text=True)
    return out.stdout.strip()


def test_importing_softgrains_makes_idle_openmp_threads_sleep():
    assert _policy_in_a_fresh_process() == "PASSIVE"


def test_a_wait_policy_the_user_set_is_kept():
    assert _policy_in_a_fresh_process(OMP_WAIT_POLICY="ACTIVE") == "ACTIVE"


# The tests below run in a fresh process with 2 Numba threads: the suite's workers run on
# one thread each (tests/conftest.py), where threads_for and over_bodies have nothing to do.
TWO_THREADS = """
import numba, numpy as np
from softgrains import threads
from softgrains.grid.shape_functions import SHAPE_FUNCTIONS, compute_stencils
from softgrains.threads import PARALLEL_MIN_POINTS, over_bodies, threads_for

assert numba.get_num_threads() == 2
n = PARALLEL_MIN_POINTS + 17
x = np.random.default_rng(3).uniform(1.0, 9.0, (n, 2))

def stencils(points):
    base, N, dN = np.empty((n, 2), np.int64), np.empty((n, 9)), np.empty((n, 9, 2))
    with threads_for(points):
        compute_stencils(x, np.zeros(2), 0.5, SHAPE_FUNCTIONS["bspline2"], base, N, dN)
    return base, N, dN
"""


def _run_with_two_threads(code: str, **env) -> None:
    """Run TWO_THREADS + code in a fresh process with NUMBA_NUM_THREADS=2; fail with its
    output where it fails."""
    out = subprocess.run([sys.executable, "-c", TWO_THREADS + code],
                         env=os.environ | {"NUMBA_NUM_THREADS": "2"} | env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr


def test_small_kernels_run_on_one_thread_and_the_count_comes_back():
    _run_with_two_threads("""
with threads_for(PARALLEL_MIN_POINTS - 1):
    assert numba.get_num_threads() == 1
assert numba.get_num_threads() == 2
with threads_for(PARALLEL_MIN_POINTS):
    assert numba.get_num_threads() == 2
try:
    with threads_for(1):
        raise RuntimeError("inside")
except RuntimeError:
    pass
assert numba.get_num_threads() == 2  # back after a failing kernel too
for serial, parallel in zip(stencils(1), stencils(n), strict=True):
    np.testing.assert_array_equal(serial, parallel)  # the same values on one and on two
""")


def test_bodies_shared_among_threads_give_the_serial_results_in_order():
    """Two worker threads, each running its kernels on one thread; the results in the
    items' order; the first failure in that order raised after every item has finished."""
    _run_with_two_threads("""
import time
stencils(n)  # a parallel kernel chooses the threading layer
results = over_bodies(lambda i: (i, numba.get_num_threads(), stencils(n)[1].sum()), range(40))
assert [i for i, _, _ in results] == list(range(40)) and threads._pools
assert {inner for _, inner, _ in results} == {1}
assert len({s for _, _, s in results}) == 1 and numba.get_num_threads() == 2
finished = []
def work(i):
    if i in (7, 23):
        raise ValueError(f"body {i}")
    time.sleep(0.01)
    finished.append(i)
    return i
try:
    over_bodies(work, range(30))
    raise AssertionError("no failure reported")
except ValueError as error:
    assert str(error) == "body 7", error
assert sorted(finished) == [i for i in range(30) if i not in (7, 23)]
""")


def test_bodies_run_one_after_the_other_on_the_workqueue_layer():
    """Numba's workqueue layer aborts the process when two threads run parallel kernels at
    once ("Concurrent access has been detected"): over_bodies then runs serially."""
    _run_with_two_threads("""
stencils(n)
assert numba.threading_layer() == "workqueue"
results = over_bodies(lambda i: stencils(n)[1].sum(), range(6))
assert len(set(results)) == 1 and not threads._pools
""", NUMBA_THREADING_LAYER="workqueue")


def test_a_kernel_called_on_one_thread_is_not_compiled_parallel():
    """ParallelKernel: on one thread the serial twin runs (and alone is compiled: Numba's
    parfor lowering is most of a cold run's compile time); on two the parallel version."""
    _run_with_two_threads("""
with threads_for(1):
    stencils(1)
assert compute_stencils.serial.signatures and not compute_stencils.parallel.signatures
stencils(n)
assert compute_stencils.parallel.signatures
""")


KERNEL = """
import numba
from softgrains.threads import parallel_kernel

@parallel_kernel(cache=True)
def thread_of_each_iteration(out):
    for i in numba.prange(out.size):
        out[i] = numba.get_thread_id()
"""


def test_the_serial_twin_and_the_parallel_kernel_keep_their_own_cache(tmp_path):
    """Numba's cache index holds no compile flags: a twin of the same name would hand its
    machine code to the parallel kernel in the next process. Cached serial first, the
    parallel kernel in a fresh process must still spread the loop over two threads."""
    (tmp_path / "twins.py").write_text(KERNEL)
    env = os.environ | {"NUMBA_NUM_THREADS": "2", "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
                        "PYTHONPATH": str(tmp_path)}
    call = ("import numba, numpy as np; from twins import thread_of_each_iteration as k; "
            "numba.set_num_threads({}); out = np.zeros(1000, np.int64); k(out); "
            "print(sorted(set(out.tolist())))")
    used = [subprocess.run([sys.executable, "-c", call.format(threads)], env=env, check=True,
                           capture_output=True, text=True, timeout=300).stdout.strip()
            for threads in (1, 2)]
    assert used == ["[0]", "[0, 1]"]

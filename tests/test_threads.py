"""Threads that behave on a busy machine (issue 14, item 5; softgrains/threads.py)."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from softgrains.grid.shape_functions import SHAPE_FUNCTIONS, compute_stencils
from softgrains.threads import PARALLEL_MIN_POINTS, over_bodies, threads_for

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


def test_small_kernels_run_on_one_thread_and_the_count_comes_back():
    before = numba.get_num_threads()
    with threads_for(PARALLEL_MIN_POINTS - 1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before
    with threads_for(PARALLEL_MIN_POINTS):
        assert numba.get_num_threads() == before


def test_the_thread_count_comes_back_after_a_kernel_fails():
    before = numba.get_num_threads()
    try:
        with threads_for(1):
            raise RuntimeError("inside")
    except RuntimeError:
        pass
    assert numba.get_num_threads() == before


def test_a_kernel_gives_the_same_values_on_one_thread_and_on_all():
    rng = np.random.default_rng(3)
    n = PARALLEL_MIN_POINTS + 17
    x = rng.uniform(1.0, 9.0, (n, 2))

    def stencils(points):
        base, N, dN = np.empty((n, 2), np.int64), np.empty((n, 9)), np.empty((n, 9, 2))
        with threads_for(points):
            compute_stencils(x, np.zeros(2), 0.5, SHAPE_FUNCTIONS["bspline2"], base, N, dN)
        return base, N, dN

    for serial, parallel in zip(stencils(1), stencils(n), strict=True):
        np.testing.assert_array_equal(serial, parallel)


def test_bodies_shared_among_threads_give_the_serial_results_in_order():
    items = list(range(40))
    before = numba.get_num_threads()
    results = over_bodies(lambda i: (i, numba.get_num_threads()), items)
    assert [i for i, _ in results] == items
    if before > 1:  # the workers run their kernels on one thread each
        assert {threads for _, threads in results} == {1}
    assert numba.get_num_threads() == before


def test_the_first_failing_body_in_order_is_reported():
    def work(i):
        if i in (7, 23):
            raise ValueError(f"body {i}")
        return i

    with pytest.raises(ValueError, match="body 7"):
        over_bodies(work, range(30))

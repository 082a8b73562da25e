"""Determinism (issue #5): the same case and seed give bit-identical results run after run
with the same thread count (docs/reliability.md says what the thread count changes)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from reliability_cases import COMPACTION, case_dict

from softgrains import Simulation, load_case


def _run() -> Simulation:
    sim = Simulation(load_case(case_dict(COMPACTION, simulation={"steps": 45})))
    rows = []
    while not sim.at_end:
        sim.step()
        rows.append(sim.series_row())
    sim.rows = rows
    return sim


def test_same_case_same_seed_same_results_bit_for_bit():
    a, b = _run(), _run()
    assert a.protocol.phase == "compaction"  # both phases and the contacts were exercised
    for name in ("x", "v", "a", "F", "sigma", "vol", "body_velocity", "body_offset"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    assert np.array_equal(a.state.contacts.impulse, b.state.contacts.impulse)
    assert a.rows == b.rows


SHARED_BODIES = """
import sys, numba, numpy as np
sys.path.insert(0, {here!r})
import test_determinism as t
import softgrains.contact.coupling as coupling
import softgrains.solver as solver
import softgrains.threads as threads
assert numba.get_num_threads() == 2
shared = t._run()
coupling.over_bodies = solver.over_bodies = lambda function, items: [function(x)
                                                                     for x in items]
serial = t._run()
assert threads._pools, "the bodies were never shared among threads"
for name in ("x", "v", "a", "F", "sigma", "vol", "body_velocity", "body_offset"):
    assert np.array_equal(getattr(shared.state, name), getattr(serial.state, name)), name
assert np.array_equal(shared.state.contacts.impulse, serial.state.contacts.impulse)
assert shared.rows == serial.rows
print("same")
"""


def test_bodies_shared_among_threads_give_the_serial_run_bit_for_bit():
    """threads.over_bodies runs the per-body work of a step (set-up, Newton directions,
    compliances, line searches, G2P) on 2 threads; each body's result is its own, so the
    run is the serial loop's, bit for bit (in a process of its own: the test workers
    compute on 1 thread)."""
    here = str(Path(__file__).parent)
    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    env.pop("PYTEST_XDIST_WORKER", None)
    out = subprocess.run([sys.executable, "-c", SHARED_BODIES.format(here=here)], env=env,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("same")

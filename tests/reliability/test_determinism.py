"""Determinism (issue #5): the same case and seed give bit-identical results run after run
with the same thread count (docs/reliability.md says what the thread count changes)."""

from __future__ import annotations

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

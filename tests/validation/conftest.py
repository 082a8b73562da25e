"""Helpers for the physics validation cases (VALIDATION.md): run an example case with overrides."""

from pathlib import Path

import pytest

from softgrains import Simulation, load_case

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def simulate(example: str, overrides: dict, observe=None, every: int = 1):
    """Run examples/<example> with overrides; return (sim, [observe(sim) every `every` steps])."""
    sim = Simulation(load_case(EXAMPLES / example, overrides))
    record = [observe(sim)] if observe else []
    for k in range(sim.n_steps):
        sim.step()
        if observe and (k + 1) % every == 0:
            record.append(observe(sim))
    return sim, record


def total_energy(sim) -> float:
    return sim.series_row()["total_energy"]


@pytest.fixture(scope="session")
def run_example():
    return simulate


@pytest.fixture
def energy():
    return total_energy


@pytest.fixture
def momentum():
    return lambda sim: (sim.model.mass[:, None] * sim.state.v).sum(axis=0)

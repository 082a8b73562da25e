"""Observables computed from the State (ALGORITHM.md §9); observers never touch the solver."""

from softgrains.observe.bodies import body_records
from softgrains.observe.energies import kinetic_energy, strain_energy

__all__ = ["body_records", "kinetic_energy", "strain_energy"]

"""Frictional contact between bodies by Contact Dynamics (ALGORITHM.md §4–6): contact nodes
and normals (detection.py), gaps (gap.py), the local Signorini–Coulomb law (local_law.py),
the contact problem of one coupling iteration as data (problem.py) and its solvers
(solvers.py), and the coupled contact–bulk loop (coupling.py)."""

from softgrains.contact.detection import ContactNodes, NodalField, find_contact_nodes, nodal_field
from softgrains.contact.local_law import OPEN, SLIP, STICK, local_impulse
from softgrains.contact.problem import ContactProblem, natural_map_residual, residual_norm
from softgrains.contact.solvers import ContactResult, ContactSolverOptions, solve

__all__ = ["OPEN", "SLIP", "STICK", "ContactNodes", "ContactProblem", "ContactResult",
           "ContactSolverOptions", "NodalField", "find_contact_nodes", "local_impulse",
           "natural_map_residual", "nodal_field", "residual_norm", "solve"]

"""Frictional contact between bodies by Contact Dynamics (ALGORITHM.md §4–6). In progress:
contact nodes and normals (detection.py), the local Signorini–Coulomb law (local_law.py)."""

from softgrains.contact.detection import ContactNodes, NodalField, find_contact_nodes, nodal_field
from softgrains.contact.local_law import OPEN, SLIP, STICK, local_impulse

__all__ = ["OPEN", "SLIP", "STICK", "ContactNodes", "NodalField", "find_contact_nodes",
           "local_impulse", "nodal_field"]

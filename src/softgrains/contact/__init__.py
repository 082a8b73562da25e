"""Frictional contact between bodies by Contact Dynamics (ALGORITHM.md §4–6). In progress:
contact nodes and normals (detection.py)."""

from softgrains.contact.detection import ContactNodes, NodalField, find_contact_nodes, nodal_field

__all__ = ["ContactNodes", "NodalField", "find_contact_nodes", "nodal_field"]

"""Clamped faces with B-splines: the odd reflection of the ghost nodes behind a face.

A ``[[boundary]]`` box that prescribes every velocity component fixes the lattice nodes
inside it. With quadratic B-splines a point next to the box also reaches nodes strictly
inside it (the ghost nodes, one layer behind the face). Fixing them leaves the field at the
face off its prescribed value: for a face at node f, v(x_f) = v̄ + (v_{f+1} − v̄)/8, so the
clamp gives way by O(h) (VALIDATION.md A4: the cantilever's corner u_x converged at first
order, 9% too large at h = 0.125 m).

The odd reflection about the face, v_{f−k} = 2 v̄ − v_{f+k}, holds the face at v̄ exactly and
keeps linear fields exact. It is applied to the shape functions of the points on the body's
side of the face (g a ghost node, m = 2f − g its mirror):

    N_f ← N_f + 2 N_g,   N_m ← N_m − N_g,   N_g ← 0        (the same for ∇N),

so that every transfer, the Newton matrix and the contacts' compliance see it, and the ghost
nodes carry no mass and leave the active set. Next to the face the first free node's
weight becomes N_{f+1} − N_{f−1} = (x − x_f)/h: linear, as a finite element's. Only boxes
that prescribe every component and whose face lies on a node plane take it (a roller,
prescribing some components, keeps its nodes fixed; so does a face between node planes).
The kernel surfaces' velocity stencils (contact/surfaces.velocity_stencil) renormalise the
plain functions over the active nodes with a first-moment correction; in front of one face,
whose ghost nodes are inactive, that gives the reflected functions again. Points inside a
box keep their functions: a body reaching into the box has its functions change across
the face (weights jump by up to 1/8 there), which a clamp whose material ends at the face
never sees.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from softgrains.grid.lattice import Lattice

NODE_PLANE_TOLERANCE = 1e-9  # of h: a box face this close to a node plane lies on it


def clamp_faces(lattice: Lattice, constraints) -> np.ndarray:
    """The faces of the boxes (``DirichletBox``) that prescribe every velocity component and
    lie on node planes inside the lattice: rows (axis, face node, direction, box's first
    nodes (d), box's last nodes (d)); direction +1 for the box's upper face (the body
    beyond it at higher coordinates), −1 for its lower face. A box one node thick has no
    ghost nodes."""
    d, h, origin = lattice.dim, lattice.h, lattice.node_origin
    rows = []
    beyond = np.asarray(lattice.n_nodes, dtype=float)
    for box in constraints:
        if not np.all(box.components):
            continue
        # in node units, clipped to just beyond the lattice (a box may reach far past it)
        lower = np.clip((np.asarray(box.lower) - origin) / h, -1.0, beyond)
        upper = np.clip((np.asarray(box.upper) - origin) / h, -1.0, beyond)
        first = np.ceil(lower - NODE_PLANE_TOLERANCE).astype(np.int64)
        last = np.floor(upper + NODE_PLANE_TOLERANCE).astype(np.int64)
        for axis in range(d):
            if last[axis] - first[axis] < 1:
                continue
            for direction, plane in ((1, upper[axis]), (-1, lower[axis])):
                node = round(plane)
                inside = 0 <= node < lattice.n_nodes[axis]
                if inside and abs(plane - node) <= NODE_PLANE_TOLERANCE:
                    rows.append([axis, node, direction, *first, *last])
    return np.array(rows, dtype=np.int64).reshape(-1, 3 + 2 * d)


@njit(cache=True, nogil=True)
def reflect_ghost_nodes(x, node_origin, h, base, s, faces, N, dN):
    """Apply the odd reflection of the module docstring to the stencils (N, ∇N) of the
    points x (base: each stencil's first lattice node per axis, width s) for every face,
    for the points on the face or beyond it and, along the other axes, strictly within the
    box's extent (the face's own reach: near a corner the body wraps round, reflecting
    across both faces would give negative weights and depend on their order). Returns the
    number of stencil entries moved, or −1 if a ghost's mirror lies outside a point's
    stencil (a stencil too narrow for the reflection: a defect, not an input)."""
    n, ns = N.shape
    d = base.shape[1]
    moved = 0
    for p in range(n):
        for f in range(faces.shape[0]):
            axis, face, direction = faces[f, 0], faces[f, 1], faces[f, 2]
            if direction * ((x[p, axis] - node_origin[axis]) / h - face) < 0.0:
                continue  # the point is inside the box, behind this face
            beside = False
            for j in range(d):
                xi = (x[p, j] - node_origin[j]) / h
                if j != axis and (xi <= faces[f, 3 + j] or xi >= faces[f, 3 + d + j]):
                    beside = True
            if beside:
                continue  # beyond the face's plane but not in front of the face
            stride = s**axis
            for k in range(ns):
                inside = True
                rem = k
                g_axis = 0
                offset = 0
                for j in range(d):
                    o = rem % s
                    rem //= s
                    g = base[p, j] + o
                    if g < faces[f, 3 + j] or g > faces[f, 3 + d + j]:
                        inside = False
                    if j == axis:
                        g_axis, offset = g, o
                if not inside or direction * (g_axis - face) >= 0:
                    continue  # not a ghost node of this face
                shift = face - g_axis  # to the face node; twice that to the mirror
                if offset + 2 * shift < 0 or offset + 2 * shift >= s:
                    return -1
                at_face = k + shift * stride
                at_mirror = k + 2 * shift * stride
                N[p, at_face] += 2.0 * N[p, k]
                N[p, at_mirror] -= N[p, k]
                N[p, k] = 0.0
                for j in range(d):
                    dN[p, at_face, j] += 2.0 * dN[p, k, j]
                    dN[p, at_mirror, j] -= dN[p, k, j]
                    dN[p, k, j] = 0.0
                moved += 1
    return moved

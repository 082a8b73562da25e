"""Where a contact takes each body's velocity (its site), and the body-side maps of the
coupled loop (coupling.py).

A site is a node (nodal contacts, detection.py/gap.py) or a point (point-to-surface contacts,
surfaces.py) whose velocity is a weighted sum of the body's nodal velocities,
v_s = Σ_I H_sI v_I, with an exact normal rate in place of the sampled one along a surface's
normal. The contact problem (problem.py) is posed on sites: V_s = H V_rows,
W_sites = H W_rows Hᵀ, and impulses q at the sites act on the node rows as Hᵀ q.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from softgrains.contact.detection import ContactNodes, node_position
from softgrains.contact.surfaces import (
    SurfaceContacts,
    merge,
    shape_distance,
    surface_contacts,
    wall_contacts,
)
from softgrains.grid.lattice import Lattice


def subset(contacts: ContactNodes, keep: np.ndarray) -> ContactNodes:
    """The contacts selected by ``keep`` (a mask or indices)."""
    return ContactNodes(contacts.node[keep], contacts.alpha[keep], contacts.beta[keep],
                        contacts.normal[keep], contacts.local_alpha[keep],
                        contacts.local_beta[keep],
                        None if contacts.site is None else contacts.site[keep],
                        None if contacts.position is None else contacts.position[keep])


class Slots:
    """The deformable bodies in contact, their contact sites and compliances.

    A site is where a contact takes a body's velocity: a node (nodal contacts) or a point
    (surface contacts, surfaces.py) whose velocity is a weighted sum of nodal velocities,
    v_s = Σ_I H_sI v_I. Per body: the distinct node rows its sites touch and H (sites ×
    rows; None when every site is a node of its own). The contact problem sees sites:
    V_s = H V_rows, W_sites = H W_rows Hᵀ (per component), and an impulse q at the sites
    acts on the rows as Hᵀ q.
    """

    def __init__(self, steps: dict, contacts: ContactNodes, stencils=None) -> None:
        n = len(contacts)
        self.d = contacts.normal.shape[1]
        self.bodies: list[int] = []
        self.rows: list[np.ndarray] = []
        self.H: list = []  # per body: None (nodal sites) or the sparse map (sites·d × rows·d)
        self.a_slot = -np.ones(n, np.int64)
        self.a_col = np.zeros(n, np.int64)
        self.b_slot = -np.ones(n, np.int64)
        self.b_col = np.zeros(n, np.int64)
        if stencils is None:
            stencils = nodal_stencils(steps, contacts)
        sides = ((contacts.alpha, stencils[0], self.a_slot, self.a_col),
                 (contacts.beta, stencils[1], self.b_slot, self.b_col))
        body_ids = sorted({int(b) for b in np.r_[contacts.alpha, contacts.beta]
                           if int(b) in steps})
        for slot, body in enumerate(body_ids):
            parts = [(np.flatnonzero(bodies == body), st, slots, cols)
                     for bodies, st, slots, cols in sides]
            keys = np.concatenate([st.key[c] for c, st, *_ in parts])
            site_keys, first, inverse = np.unique(keys, return_index=True,
                                                  return_inverse=True)
            start = 0
            for c, _st, slots, cols in parts:
                slots[c] = slot
                cols[c] = inverse[start:start + c.size]
                start += c.size
            site_rows = np.concatenate([st.rows[c] for c, st, *_ in parts])[first]
            if site_rows.shape[1] == 1:  # nodal sites: keys are the rows, in order
                self.H.append(None)
                rows = site_rows[:, 0]
            else:
                rows, H = _site_map(parts, first, site_keys.size, self.d)
                self.H.append(H)
            self.bodies.append(body)
            self.rows.append(rows)
        self.k_size = np.array([self.sites(s) for s in range(len(self.bodies))], np.int64)
        self.k_off = np.r_[0, np.cumsum(self.k_size)][:-1].astype(np.int64)
        self.response: list[np.ndarray | None] = [None] * len(body_ids)
        self.W: list[np.ndarray | None] = [None] * len(body_ids)

    def sites(self, slot: int) -> int:
        H = self.H[slot]
        return self.rows[slot].size if H is None else H.shape[0] // self.d

    def span(self, slot: int) -> slice:
        """Body ``slot``'s sites in the arrays over all contact sites (V, Q)."""
        return slice(self.k_off[slot], self.k_off[slot] + self.k_size[slot])

    def stack(self, value: Callable) -> np.ndarray:
        """value(body, its node rows), taken at the sites (H value) of every body in contact
        and stacked in slot order: an array over all contact sites (e.g. their velocities)."""
        return np.concatenate([value(body, rows) if H is None else
                               (H @ value(body, rows).ravel()).reshape(-1, self.d)
                               for body, rows, H in zip(self.bodies, self.rows, self.H,
                                                        strict=True)])

    def to_rows(self, slot: int, q: np.ndarray) -> np.ndarray:
        """Impulses q (sites, d) of body ``slot`` as impulses on its node rows, Hᵀ q."""
        H = self.H[slot]
        return q if H is None else (H.T @ q.ravel()).reshape(-1, self.d)

    def compliance(self, slot: int, W: np.ndarray) -> np.ndarray:
        """The sites' compliance H W Hᵀ (per component) from the rows' W (k d × k d)."""
        H = self.H[slot]
        if H is None:
            return W
        return np.asarray(H @ (H @ W.T).T)


@dataclass(frozen=True)
class SideStencils:
    """One side (α or β) of every contact: the active node rows its velocity is taken
    from (−1: none), their weights, and a key naming the site (equal keys: one site)."""

    rows: np.ndarray  # (n, s)
    weights: np.ndarray  # (n, s)
    key: np.ndarray  # (n,)
    # optional: the site's velocity along ``rate_normal`` is Σ_k rate_vec_k·v_{rate_rows_k}
    # (exact rate of a smoothed surface), its other components Σ_k weights_k v_{rows_k}
    rate_rows: np.ndarray | None = None  # (n, r), −1: none
    rate_vec: np.ndarray | None = None  # (n, r, d)
    rate_normal: np.ndarray | None = None  # (n, d)


def _site_map(parts, first: np.ndarray, n_sites: int, d: int):
    """The distinct node rows of a body's sites and the sparse map Hd (sites·d × rows·d):
    v_site = Σ_k w_k v_{row_k}, except along a site's ``rate_normal`` n where a surface's
    exact normal velocity replaces it: v_site = (I − n nᵀ) Σ_k w_k v_k + n Σ_k a_kᵀ v_k."""
    def gather(name):
        arrays = [getattr(st, name) for _c, st, *_ in parts]
        if any(a is None for a in arrays):
            return None
        return np.concatenate([a[c] for a, (c, *_) in zip(arrays, parts, strict=True)])[first]
    site_rows, site_w = gather("rows"), gather("weights")
    rate_rows, rate_vec, rate_n = gather("rate_rows"), gather("rate_vec"), gather("rate_normal")
    all_rows = [site_rows[site_rows >= 0]]
    if rate_rows is not None:
        all_rows.append(rate_rows[rate_rows >= 0])
    rows = np.unique(np.concatenate(all_rows))
    eye = np.eye(d)
    if rate_n is None:
        proj = np.broadcast_to(eye, (n_sites, d, d))
    else:
        has = (rate_rows >= 0).any(axis=1)
        proj = eye - has[:, None, None] * np.einsum("si,sj->sij", rate_n, rate_n)
    # sampled part: block w_k (I − n nᵀ) at (site, row_k)
    s_idx, k_idx = np.nonzero(site_rows >= 0)
    blocks = site_w[s_idx, k_idx, None, None] * proj[s_idx]
    cols = np.searchsorted(rows, site_rows[s_idx, k_idx])
    all_s, all_c, all_b = [s_idx], [cols], [blocks]
    if rate_rows is not None:
        s2, k2 = np.nonzero(rate_rows >= 0)
        all_s.append(s2)
        all_c.append(np.searchsorted(rows, rate_rows[s2, k2]))
        all_b.append(np.einsum("si,sj->sij", rate_n[s2], rate_vec[s2, k2]))
    s_idx, cols, blocks = np.concatenate(all_s), np.concatenate(all_c), np.concatenate(all_b)
    i, j = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
    r = (s_idx[:, None, None] * d + i).ravel()
    c = (cols[:, None, None] * d + j).ravel()
    H = sp.csr_matrix((blocks.ravel(), (r, c)), shape=(n_sites * d, rows.size * d))
    return rows, H


def nodal_stencils(steps: dict, contacts: ContactNodes) -> tuple[SideStencils, SideStencils]:
    """Nodal contacts: each side's site is its node (key: the node's active row)."""
    out = []
    for bodies, local in ((contacts.alpha, contacts.local_alpha),
                          (contacts.beta, contacts.local_beta)):
        rows = -np.ones((len(contacts), 1), np.int64)
        for c in range(len(contacts)):
            s = steps.get(int(bodies[c]))
            if s is not None:
                rows[c, 0] = s.active_row[local[c]]
        out.append(SideStencils(rows, np.ones((len(contacts), 1)), rows[:, 0].copy()))
    return out[0], out[1]


def point_contacts(lattice: Lattice, steps: dict, walls: dict, contacts: ContactNodes,
                   spacing: float, reach: float, round_bodies=frozenset(),
                   grains: bool = True) -> tuple[ContactNodes, SurfaceContacts | None]:
    """Split the nodal contacts: those of every pair of deformable grains (``grains``) and of
    every grain and rectangular or round wall in ``walls`` are replaced by point-to-surface
    contacts at the grains' outer points (surfaces.py). Returns the nodal contacts left (the
    caller estimates their gaps) and the point contacts (None: there are none)."""
    grain = np.array([grains and int(a) in steps and int(b) in steps
                      for a, b in zip(contacts.alpha, contacts.beta, strict=True)], bool)
    shapes = {b: shape for b, (_, shape) in walls.items()
              if shape_distance(shape, np.zeros((1, lattice.dim))) is not None}
    wall = np.array([int(a) in steps and int(b) in shapes
                     for a, b in zip(contacts.alpha, contacts.beta, strict=True)], bool)
    pairs = sorted({(int(a), int(b)) for a, b in zip(contacts.alpha[grain],
                                                     contacts.beta[grain], strict=True)})
    wall_pairs = sorted({(int(a), int(b)) for a, b in zip(contacts.alpha[wall],
                                                          contacts.beta[wall], strict=True)})
    found = ([surface_contacts(pairs, steps, spacing, reach, round_bodies)] if pairs else []) \
        + ([wall_contacts(wall_pairs, steps, shapes, spacing, reach, round_bodies)]
           if wall_pairs else [])
    return subset(contacts, ~(grain | wall)), merge(found) if found else None


def with_point_contacts(lattice: Lattice, steps: dict, nodal: ContactNodes, gaps: np.ndarray,
                        sc: SurfaceContacts
                        ) -> tuple[ContactNodes, np.ndarray, tuple[SideStencils, SideStencils]]:
    """The nodal contacts (with their ``gaps``) and the point contacts ``sc`` as one set:
    the contacts, their gaps and both sides' stencils (nodal sides padded to the points'
    stencil width)."""
    nodal_sides = nodal_stencils(steps, nodal)
    width = sc.rows_alpha.shape[1]
    d = lattice.dim
    n_codes = max(steps) + 2
    owner = np.where(sc.owner_is_alpha, sc.alpha, sc.beta)
    own_key = -1 - sc.point * n_codes
    foreign_key = own_key - 1 - owner
    sides = []
    for which, (rows, weights) in enumerate(((sc.rows_alpha, sc.weights_alpha),
                                             (sc.rows_beta, sc.weights_beta))):
        mine = sc.owner_is_alpha if which == 0 else ~sc.owner_is_alpha
        at_nodes = nodal_sides[which]
        padded_rows = -np.ones((len(nodal), width), np.int64)
        padded_rows[:, 0] = at_nodes.rows[:, 0]
        padded_w = np.zeros((len(nodal), width))
        padded_w[:, 0] = 1.0
        width_r = sc.rate_rows.shape[1]
        rate_rows = -np.ones((len(nodal) + len(sc), width_r), np.int64)
        rate_vec = np.zeros((len(nodal) + len(sc), width_r, d))
        surface_side = ~mine  # the body whose surface the point is measured against
        rate_rows[len(nodal):][surface_side] = sc.rate_rows[surface_side]
        rate_vec[len(nodal):][surface_side] = sc.rate_vec[surface_side]
        sides.append(SideStencils(np.r_[padded_rows, rows], np.r_[padded_w, weights],
                                  np.r_[at_nodes.key, np.where(mine, own_key, foreign_key)],
                                  rate_rows, rate_vec,
                                  np.r_[np.zeros((len(nodal), d)), sc.rate_normal]))
    index = np.rint((sc.position - lattice.node_origin) / lattice.h).astype(np.int64)
    strides = np.r_[1, np.cumprod(lattice.n_nodes[:-1])].astype(np.int64)
    none = -np.ones(len(sc), np.int64)
    merged = ContactNodes(
        np.r_[nodal.node, index @ strides], np.r_[nodal.alpha, sc.alpha],
        np.r_[nodal.beta, sc.beta], np.r_[nodal.normal, sc.normal],
        np.r_[nodal.local_alpha, none], np.r_[nodal.local_beta, none],
        np.r_[np.full(len(nodal), -1), 2 * sc.point + (~sc.owner_is_alpha)],
        np.r_[node_position(lattice, nodal.node), sc.position])
    return merged, np.r_[gaps, sc.gap], (sides[0], sides[1])

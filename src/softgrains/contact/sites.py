"""Where a contact takes each body's velocity (its site), and the body-side maps of the
coupled loop (coupling.py).

A site is a node (nodal contacts, detection.py/gap.py), a point or a patch of points
(point-to-surface contacts, surfaces.py; patches.py groups them against walls) whose
velocity is a linear map of the body's nodal velocities, v_s = Σ_I H_sI v_I (d × d blocks:
a point's own interpolation, a surface's exact normal rate in place of the sampled one
along its normal, each point of a patch turned onto the patch's normal). The contact
problem (problem.py) is posed on sites: V_s = H V_rows, W_sites = H W_rows Hᵀ, and impulses
q at the sites act on the node rows as Hᵀ q.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from softgrains.contact.detection import ContactNodes, node_position
from softgrains.contact.patches import aggregate, group
from softgrains.contact.problem import relative_velocities
from softgrains.contact.surfaces import (
    SurfaceContacts,
    least_unsampled_gap,
    merge,
    shape_distance,
    stack_padded,
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


class Members:
    """The indices i with owner[i] == v, ascending, for any v, from one stable sort: what
    ``np.flatnonzero(owner == v)`` gives, without reading all of ``owner`` for each v (over
    every body, O(bodies × contacts))."""

    def __init__(self, owner: np.ndarray) -> None:
        self.order = np.argsort(owner, kind="stable")
        self.owners = owner[self.order]

    def __call__(self, value: int) -> np.ndarray:
        lo = np.searchsorted(self.owners, value, side="left")
        hi = np.searchsorted(self.owners, value, side="right")
        return self.order[lo:hi]


class Slots:
    """The deformable bodies in contact, their contact sites and compliances.

    A site is where a contact takes a body's velocity: a node (nodal contacts), a point or
    a patch of points (surface contacts, surfaces.py and patches.py), v_s = Σ_I H_sI v_I.
    Per body: the distinct node rows its sites touch and H (sites × rows; None when every
    site is a node of its own). The contact problem sees sites:
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
        body_ids = [int(b) for b in np.unique(np.r_[contacts.alpha, contacts.beta])
                    if int(b) in steps]
        members = [Members(bodies) for bodies, *_ in sides]
        for slot, body in enumerate(body_ids):
            parts = [(of(body), st, slots, cols)
                     for of, (_, st, slots, cols) in zip(members, sides, strict=True)]
            keys = np.concatenate([st.key[c] for c, st, *_ in parts])
            site_keys, first, inverse = np.unique(keys, return_index=True,
                                                  return_inverse=True)
            start = 0
            for c, _st, slots, cols in parts:
                slots[c] = slot
                cols[c] = inverse[start:start + c.size]
                start += c.size
            if np.all(site_keys >= 0):  # nodal sites: keys are the rows, in order
                self.H.append(None)
                rows = site_keys
            else:
                rows, H = _site_map(parts, first, site_keys.size, self.d)
                self.H.append(H)
            self.bodies.append(body)
            self.rows.append(rows)
        self.k_size = np.array([self.sites(s) for s in range(len(self.bodies))], np.int64)
        self.k_off = np.r_[0, np.cumsum(self.k_size)][:-1].astype(np.int64)
        # the bodies' impulse responses (BodyStep.contact_response; None: lumped)
        self.response: list = [None] * len(body_ids)
        self.W: list[np.ndarray | None] = [None] * len(body_ids)
        # ... and their rigid modes of inertia alone at the sites, G (k, d, m) with G_c G_c'ᵀ
        # their share of W_cc' (BodyStep.rigid_modes; coupling.py)
        self.rigid: list[np.ndarray | None] = [None] * len(body_ids)
        self.semidefinite = [False] * len(body_ids)  # W known to be PSD (coupling.py)
        # per body: the span of the impulses its contacts can carry (None: all; coupling.py)
        self.impulse_basis: list = [None] * len(body_ids)

    def restricted(self, chosen: np.ndarray) -> Slots:
        """The slots of the contacts ``chosen`` (indices, in that order): each body keeps
        the sites those contacts use (H's rows of them) and its node rows; bodies none of
        them touches drop out. (The working set of coupling.py: cheaper than new slots from
        the stencils.)"""
        d = self.d
        new = object.__new__(Slots)
        new.d = d
        new.a_slot, new.b_slot = self.a_slot[chosen], self.b_slot[chosen]
        new.a_col, new.b_col = self.a_col[chosen].copy(), self.b_col[chosen].copy()
        used = np.unique(np.r_[new.a_slot, new.b_slot])
        used = used[used >= 0]
        renumber = -np.ones(len(self.bodies) + 1, np.int64)  # (index −1: a wall, kept −1)
        renumber[used] = np.arange(used.size)
        new.bodies, new.rows, new.H = [], [], []
        a_members, b_members = Members(new.a_slot), Members(new.b_slot)
        for old in used:
            on_a, on_b = a_members(old), b_members(old)
            cols = np.unique(np.r_[new.a_col[on_a], new.b_col[on_b]])
            new.a_col[on_a] = np.searchsorted(cols, new.a_col[on_a])
            new.b_col[on_b] = np.searchsorted(cols, new.b_col[on_b])
            H = self.H[old]
            new.bodies.append(self.bodies[old])
            if H is None:  # nodal sites: the rows are the sites
                new.rows.append(self.rows[old][cols])
                new.H.append(None)
            else:
                new.rows.append(self.rows[old])
                new.H.append(_site_rows_of(H, cols, d))
        new.a_slot, new.b_slot = renumber[new.a_slot], renumber[new.b_slot]
        new.k_size = np.array([new.sites(s) for s in range(len(new.bodies))], np.int64)
        new.k_off = np.r_[0, np.cumsum(new.k_size)][:-1].astype(np.int64)
        new.response = [None] * len(new.bodies)
        new.W = [None] * len(new.bodies)
        new.rigid = [None] * len(new.bodies)
        new.semidefinite = [False] * len(new.bodies)
        new.impulse_basis = [None] * len(new.bodies)
        return new

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
                               _times(H, value(body, rows)).reshape(-1, self.d)
                               for body, rows, H in zip(self.bodies, self.rows, self.H,
                                                        strict=True)])

    def relative_velocities(self, V: np.ndarray, wall_va: np.ndarray, wall_vb: np.ndarray
                            ) -> np.ndarray:
        """w_c = v^α − v^β at each contact from the site velocities V (:meth:`stack`); a
        kinematic side moves at its wall velocity (wall_va, wall_vb per contact)."""
        return relative_velocities(self.a_slot, self.a_col, self.b_slot, self.b_col,
                                   self.k_off, wall_va, wall_vb, V)

    def to_rows(self, slot: int, q: np.ndarray) -> np.ndarray:
        """Impulses q (sites, d) of body ``slot`` as impulses on its node rows, Hᵀ q."""
        H = self.H[slot]
        if H is None:
            return q
        # (SciPy's H.T @ q makes a matrix object per call: ~1.5% of a run)
        out = np.zeros(H.shape[1])
        _transpose_times(H.indptr, H.indices, H.data, np.ascontiguousarray(q, float).ravel(),
                         out)
        return out.reshape(-1, self.d)

    def compliance(self, slot: int, W: np.ndarray) -> np.ndarray:
        """The sites' compliance H W Hᵀ (per component) from the rows' W (k d × k d)."""
        H = self.H[slot]
        if H is None:
            return W
        return np.asarray(H @ (H @ W.T).T)


@dataclass(frozen=True)
class SideStencils:
    """One side (α or β) of every contact: its site's velocity v = Σ_k B_k v_{rows_k} from
    the body's active node rows (−1: none) through d × d blocks B_k, and a key naming the
    site (equal keys: one site)."""

    rows: np.ndarray  # (n, s)
    blocks: np.ndarray  # (n, s, d, d)
    key: np.ndarray  # (n,)


def _site_map(parts, first: np.ndarray, n_sites: int, d: int):
    """The distinct node rows of a body's sites and the sparse map H (sites·d × rows·d)
    with v_site = Σ_k B_k v_{row_k}."""
    width = max(st.rows.shape[1] for _c, st, *_ in parts)
    site_rows = stack_padded([st.rows[c] for c, st, *_ in parts], width, -1)[first]
    site_blocks = stack_padded([st.blocks[c] for c, st, *_ in parts], width, 0.0)[first]
    rows, data, columns, indptr = _site_map_csr(site_rows, site_blocks)
    return rows, sp.csr_matrix((data, columns, indptr), shape=(n_sites * d, rows.size * d))


def _site_rows_of(H: sp.csr_matrix, sites: np.ndarray, d: int) -> sp.csr_matrix:
    """H's rows of ``sites`` (rows s·d … s·d + d − 1 each, in that order), as SciPy's
    ``H[(sites[:, None] * d + np.arange(d)).ravel()]`` gives them, by a kernel (SciPy's
    fancy row indexing took ~0.1 ms a body and working set, ~2% of a dense step)."""
    if sites.size and not (sites.min() >= 0 and (sites.max() + 1) * d <= H.shape[0]):
        raise IndexError(f"sites {sites.min()}…{sites.max()} asked of a map of "
                         f"{H.shape[0] // d} sites")
    indptr, indices, data = _csr_site_rows(H.indptr, H.indices, H.data, sites, d)
    return sp.csr_matrix((data, indices, indptr), shape=(sites.size * d, H.shape[1]))


@njit(cache=True)
def _csr_site_rows(indptr, indices, data, sites, d):
    """The CSR arrays of the rows s·d + i (i < d) of each site s in ``sites``, in order."""
    new_ptr = np.zeros(sites.size * d + 1, indptr.dtype)
    for e in range(sites.size):
        for i in range(d):
            r = sites[e] * d + i
            new_ptr[e * d + i + 1] = new_ptr[e * d + i] + indptr[r + 1] - indptr[r]
    new_indices = np.empty(new_ptr[-1], indices.dtype)
    new_data = np.empty(new_ptr[-1])
    for e in range(sites.size):
        for i in range(d):
            r = sites[e] * d + i
            at = new_ptr[e * d + i]
            for k in range(indptr[r], indptr[r + 1]):
                new_indices[at] = indices[k]
                new_data[at] = data[k]
                at += 1
    return new_ptr, new_indices, new_data


def _times(H: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    """H x (x's values flattened), by a kernel: SciPy's dispatch of ``H @ x`` cost more
    than the product on a grain's few hundred sites (~0.8% of a run)."""
    out = np.empty(H.shape[0])
    _csr_times(H.indptr, H.indices, H.data, np.ascontiguousarray(x, float).ravel(), out)
    return out


@njit(cache=True)
def _csr_times(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, x: np.ndarray,
               out: np.ndarray) -> None:
    """out = H x for H in CSR arrays (each row's terms summed in order, as SciPy does)."""
    for r in range(indptr.size - 1):
        acc = 0.0
        for e in range(indptr[r], indptr[r + 1]):
            acc += data[e] * x[indices[e]]
        out[r] = acc


@njit(cache=True)
def _transpose_times(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                     q: np.ndarray, out: np.ndarray) -> None:
    """out += Hᵀ q for H in CSR arrays (each column's terms summed in row order)."""
    for r in range(indptr.size - 1):
        for e in range(indptr[r], indptr[r + 1]):
            out[indices[e]] += data[e] * q[r]


@njit(cache=True)
def _site_map_csr(site_rows: np.ndarray, site_blocks: np.ndarray):
    """The distinct node rows ≥ 0 of ``site_rows`` (ascending) and H's CSR arrays: row
    s·d + i of H holds Σ B_k[i, j] at column c·d + j over site s's stencil entries k on the
    node row rows[c] (site_rows[s, k] = rows[c]), ascending in c (SciPy's canonical form,
    as the COO → CSR conversion of the same entries gives)."""
    n, width = site_rows.shape
    d = site_blocks.shape[2]
    top = site_rows.max() if site_rows.size else -1
    place = np.full(top + 1, -1, np.int64)  # a row's place in rows
    for s in range(n):
        for k in range(width):
            if site_rows[s, k] >= 0:
                place[site_rows[s, k]] = 0
    rows = np.flatnonzero(place == 0)
    place[rows] = np.arange(rows.size)
    order = np.empty(width, np.int64)
    distinct = np.empty(n, np.int64)
    column = np.empty((n, width), np.int64)
    summed = np.zeros((n, width, d, d))
    for s in range(n):
        valid = 0
        for k in range(width):  # insertion sort of the valid entries by node row
            row = site_rows[s, k]
            if row < 0:
                continue
            at = valid
            while at > 0 and site_rows[s, order[at - 1]] > row:
                order[at] = order[at - 1]
                at -= 1
            order[at] = k
            valid += 1
        count = 0
        for e in range(valid):  # one entry per distinct row, its blocks summed
            k = order[e]
            c = place[site_rows[s, k]] * d
            if count == 0 or column[s, count - 1] != c:
                column[s, count] = c
                count += 1
            for i in range(d):
                for j in range(d):
                    summed[s, count - 1, i, j] += site_blocks[s, k, i, j]
        distinct[s] = count
    indptr = np.zeros(n * d + 1, np.int64)
    for s in range(n):
        for i in range(d):
            indptr[s * d + i + 1] = indptr[s * d + i] + distinct[s] * d
    data = np.empty(indptr[-1])
    columns = np.empty(indptr[-1], np.int64)
    for s in range(n):
        for i in range(d):
            at = indptr[s * d + i]
            for e in range(distinct[s]):
                for j in range(d):
                    data[at] = summed[s, e, i, j]
                    columns[at] = column[s, e] + j
                    at += 1
    return rows, data, columns, indptr


def nodal_stencils(steps: dict, contacts: ContactNodes) -> tuple[SideStencils, SideStencils]:
    """Nodal contacts: each side's site is its node (key: the node's active row)."""
    d = contacts.normal.shape[1]
    out = []
    for bodies, local in ((contacts.alpha, contacts.local_alpha),
                          (contacts.beta, contacts.local_beta)):
        rows = -np.ones((len(contacts), 1), np.int64)
        for c in range(len(contacts)):
            s = steps.get(int(bodies[c]))
            if s is not None:
                rows[c, 0] = s.active_row[local[c]]
        blocks = np.broadcast_to(np.eye(d), (len(contacts), 1, d, d))
        out.append(SideStencils(rows, blocks, rows[:, 0].copy()))
    return out[0], out[1]


def point_blocks(rows: np.ndarray, weights: np.ndarray, rate_rows: np.ndarray,
                 rate_vec: np.ndarray, rate_normal: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A point site's velocity as blocks: v = Σ_k w_k v_k, except along ``rate_normal`` n
    where a surface's exact normal velocity replaces it (where the site has rate rows):
    v = (I − n nᵀ) Σ_k w_k v_k + n Σ_k a_kᵀ v_k."""
    d = rate_normal.shape[1]
    has = (rate_rows >= 0).any(axis=1)
    proj = np.eye(d) - has[:, None, None] * np.einsum("si,sj->sij", rate_normal, rate_normal)
    sampled = weights[:, :, None, None] * proj[:, None]
    rate = np.einsum("si,skj->skij", rate_normal, rate_vec)
    return np.concatenate([rows, rate_rows], axis=1), np.concatenate([sampled, rate], axis=1)


def _distinct_pairs(alpha: np.ndarray, beta: np.ndarray) -> list[tuple[int, int]]:
    """The distinct (α, β) of the contacts, in ascending order."""
    unique = np.unique(np.stack([alpha, beta], axis=1).reshape(-1, 2), axis=0)
    return [(int(a), int(b)) for a, b in unique]


def point_contacts(lattice: Lattice, steps: dict, walls: dict, contacts: ContactNodes,
                   spacing: float, reach: float, grains: bool = True,
                   one_pass: Callable[[int, int], bool] | None = None,
                   round_bodies: frozenset = frozenset()
                   ) -> tuple[ContactNodes, SurfaceContacts | None, float]:
    """Split the nodal contacts: those of every pair of deformable grains (``grains``) and of
    every grain and rectangular or round wall in ``walls`` are replaced by point-to-surface
    contacts at the grains' outer points (surfaces.py; where ``one_pass(α, β)``, one
    grain's of the pair, ``round_bodies``' first). Returns the nodal contacts left (the
    caller estimates their gaps), the point contacts (None: there are none) and the least
    gap of the points one pass leaves out (surfaces.least_unsampled_gap; NaN: none)."""
    deformable = np.fromiter(steps, np.int64, len(steps))
    alpha_deforms = np.isin(contacts.alpha, deformable)
    grain = alpha_deforms & np.isin(contacts.beta, deformable) & grains
    shapes = {b: shape for b, (_, shape) in walls.items()
              if shape_distance(shape, np.zeros((1, lattice.dim))) is not None}
    wall = alpha_deforms & np.isin(contacts.beta, np.fromiter(shapes, np.int64, len(shapes)))
    pairs, wall_pairs = (_distinct_pairs(contacts.alpha[which], contacts.beta[which])
                         for which in (grain, wall))
    single = frozenset(p for p in pairs if one_pass is not None and one_pass(*p))
    surfaces: dict = {}  # the grains' KernelSurfaces, shared by the passes and the report
    found = ([surface_contacts(pairs, steps, spacing, reach, single,
                               frozenset(round_bodies), surfaces)] if pairs else []) \
        + ([wall_contacts(wall_pairs, steps, shapes, spacing, reach)]
           if wall_pairs else [])
    unsampled = least_unsampled_gap(single, steps, spacing, reach, frozenset(round_bodies),
                                    surfaces) if single else np.nan
    return subset(contacts, ~(grain | wall)), merge(found) if found else None, unsampled


def with_point_contacts(lattice: Lattice, steps: dict, nodal: ContactNodes, gaps: np.ndarray,
                        sc: SurfaceContacts, walls_per_point: bool = False
                        ) -> tuple[ContactNodes, np.ndarray, np.ndarray,
                                   tuple[SideStencils, SideStencils], np.ndarray]:
    """The nodal contacts (with their ``gaps``) and the point contacts ``sc``, grouped into
    patches (patches.py; a point contact between grains, and with ``walls_per_point`` one
    against a wall too, is a patch of its own), as one set: the contacts, their gaps, the
    gaps to report (a patch's least member gap), both sides' stencils (padded to a
    common width) and, per point contact, its contact's index if it is a patch of its own
    (−1 for a member of a larger patch)."""
    d = lattice.dim
    alone = np.isin(sc.beta, list(steps)) | walls_per_point
    found = group(sc.alpha, sc.beta, sc.position, sc.normal, sc.gap, lattice.node_origin,
                  lattice.h, lattice.n_nodes,
                  alone=np.where(alone, 2 * sc.point + (~sc.owner_is_alpha), -1))
    no_rate = -np.ones_like(sc.rate_rows)
    nodal_sides = nodal_stencils(steps, nodal)
    sides = []
    for which, (rows, weights) in enumerate(((sc.rows_alpha, sc.weights_alpha),
                                             (sc.rows_beta, sc.weights_beta))):
        # the exact surface rate belongs to the body whose surface the point is measured on
        surface_side = ~sc.owner_is_alpha if which == 0 else sc.owner_is_alpha
        rate_rows = np.where(surface_side[:, None], sc.rate_rows, no_rate)
        patch_rows, patch_blocks = aggregate(found, *point_blocks(
            rows, weights, rate_rows, sc.rate_vec, sc.rate_normal))
        at_nodes = nodal_sides[which]
        width = max(patch_rows.shape[1], 1)
        padded_rows = -np.ones((len(nodal), width), np.int64)
        padded_rows[:, 0] = at_nodes.rows[:, 0]
        padded_blocks = np.zeros((len(nodal), width, d, d))
        padded_blocks[:, 0] = np.eye(d)
        sides.append(SideStencils(np.r_[padded_rows, patch_rows],
                                  np.r_[padded_blocks, patch_blocks],
                                  np.r_[at_nodes.key, -1 - np.arange(len(found))]))
    none = -np.ones(len(found), np.int64)
    merged = ContactNodes(
        np.r_[nodal.node, found.node], np.r_[nodal.alpha, found.alpha],
        np.r_[nodal.beta, found.beta], np.r_[nodal.normal, found.normal],
        np.r_[nodal.local_alpha, none], np.r_[nodal.local_beta, none],
        np.r_[np.full(len(nodal), -1), found.site],
        np.r_[node_position(lattice, nodal.node), found.position])
    lone = found.site[found.of_point] != -2
    return (merged, np.r_[gaps, found.gap], np.r_[gaps, found.least_gap],
            (sides[0], sides[1]), np.where(lone, len(nodal) + found.of_point, -1))

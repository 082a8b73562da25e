"""The generalized Jacobian of the Alart–Curnier function on its engaged rows (solvers.py).

    J = I − G + G ρ (W + εI)        (G: block-diagonal d × d per contact, ρ per contact)

A row where G vanishes (an open contact's components) is a row of the identity, so the
Newton step needs only the engaged rows E: J_EE dr_E = −Φ_E − J_EO dr_O. Block row c of
G ρ W is ρ_c G_c W_c,: : a Numba kernel builds J_EE and J_EO from W's d × d block rows
(delassus.py) as CSR in one pass (the sparse products, the slicing and the CSR → CSC
conversion took ~25% of a Newton iteration on 1600 contacts of a dense compaction).
:class:`NewtonMatrix` solves the Newton steps of one problem on a kept factorization,
updated by rows (the Woodbury identity) while G changes in few rows.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from softgrains.contact.delassus import BlockRows, as_block_rows, differing_rows, nonzero_rows
from softgrains.contact.ordering import DISSECTION_ROWS, dissection_order


@njit(cache=True)
def _split_rows(start, end, indices, blocks, G, rho, shift, identity, rows, position):
    """Rows ``rows`` of identity · I − G + ρ G (W + shift I), as two CSR matrices by their
    columns j: position[j] ≥ 0 → column position[j] of the first, else column
    −position[j] − 1 of the second; row i = c d + a is
    identity · e_i − G_c,a + ρ_c G_c,a (W_c,: + shift e_c,:)."""
    d = G.shape[1]
    m = rows.size
    ptr_in = np.zeros(m + 1, np.int64)
    ptr_out = np.zeros(m + 1, np.int64)
    for e in range(m):
        c = rows[e] // d
        inside = 0
        total = 0
        for k in range(start[c], end[c]):
            for q in range(d):
                total += 1
                if position[indices[k] * d + q] >= 0:
                    inside += 1
        ptr_in[e + 1] = ptr_in[e] + inside
        ptr_out[e + 1] = ptr_out[e] + total - inside
    cols_in = np.empty(ptr_in[m], np.int64)
    data_in = np.empty(ptr_in[m])
    cols_out = np.empty(ptr_out[m], np.int64)
    data_out = np.empty(ptr_out[m])
    g = np.empty(d)
    for e in range(m):
        i = rows[e]
        c, a = i // d, i % d
        for b in range(d):
            g[b] = rho[c] * G[c, a, b]
        at_in, at_out = ptr_in[e], ptr_out[e]
        for k in range(start[c], end[c]):
            c2 = indices[k]
            for q in range(d):
                value = 0.0
                for b in range(d):
                    value += g[b] * blocks[k, b, q]
                if c2 == c:
                    value += g[q] * shift - G[c, a, q] + (identity if a == q else 0.0)
                j = position[c2 * d + q]
                if j >= 0:
                    cols_in[at_in] = j
                    data_in[at_in] = value
                    at_in += 1
                else:
                    cols_out[at_out] = -j - 1
                    data_out[at_out] = value
                    at_out += 1
    return ptr_in, cols_in, data_in, ptr_out, cols_out, data_out


def _rows(W: BlockRows, G: np.ndarray, rho: np.ndarray, shift: float, identity: float,
          rows: np.ndarray, position: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Rows ``rows`` of identity · I − G + G ρ (W + shift I) split by ``position`` into
    two CSR matrices (:func:`_split_rows`; W's block rows of those contacts built)."""
    W.ensure(rows // G.shape[1])
    ptr_in, cols_in, data_in, ptr_out, cols_out, data_out = _split_rows(
        W.start, W.end, W.indices, W.data, G, rho, float(shift), float(identity), rows,
        position)
    inside = int(np.count_nonzero(position >= 0))
    return (sp.csr_matrix((data_in, cols_in, ptr_in), shape=(rows.size, inside)),
            sp.csr_matrix((data_out, cols_out, ptr_out),
                          shape=(rows.size, position.size - inside)))


def _engaged(G: np.ndarray) -> np.ndarray:
    """Whether each row of J (contact, component) is engaged: G's row is not zero (else
    it is a row of the identity)."""
    return nonzero_rows(G, G.shape[1])


def _positions(engaged: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows outside E, and each column's position for :func:`_split_rows`: its index in
    E, or −1 − its index among the others."""
    outside = np.ones(size, bool)
    outside[engaged] = False
    outside = np.flatnonzero(outside)
    position = np.empty(size, np.int64)
    position[engaged] = np.arange(engaged.size)
    position[outside] = -1 - np.arange(outside.size)
    return outside, position


def engaged_jacobian(W: sp.bsr_matrix | BlockRows, G: np.ndarray, rho: np.ndarray,
                     engaged: np.ndarray, dr: np.ndarray,
                     shift: float = 0.0) -> tuple[sp.csr_matrix, np.ndarray]:
    """(J_EE, J_EO dr_O) of J = I − G + G ρ (W + shift I): W as d × d block rows (a BSR
    matrix or delassus.BlockRows), G (n, d, d), ρ (n,), the engaged rows E (sorted), dr
    the step's values on the other rows (only dr_O is read). An engaged contact's block
    row must hold its diagonal block (the I − G terms are added there): engaged rows are
    movable (G vanishes where W_cc,nn = 0), and a contact touching a body is in its own
    block row (delassus.py)."""
    outside, position = _positions(engaged, dr.size)
    J_ee, J_eo = _rows(as_block_rows(W), G, rho, shift, 1.0, engaged, position)
    return J_ee, J_eo @ dr[outside]


# Row updates of a kept factorization (session 27): between two Newton iterations of one
# contact problem G changes in few rows (dense frictional compaction steps: fewer than 5 in
# half of the iterations, fewer than 40 in 90%), and the Tresca and proximal-point
# fallbacks solve many problems with the same W. A new factorization of J_EE (~1300 rows,
# ~14 ms) is replaced by the Woodbury identity on the kept one while at most UPDATE_ROWS
# rows differ from it (the optimum of 20 / 40 / 80 / 150 / 300 on 95 saved solves: 17.4 s
# with a factorization every iteration, 11.9 / 11.7 / 10.8 / 11.5 / 13.1 s, the same
# iterates to round-off)
UPDATE_ROWS = 80
# an updated solve is kept when its residual ‖J x − b‖ is within this fraction of ‖b‖,
# else J is factorised anew (the capacitance matrix of nearly dependent rows)
UPDATE_RESIDUAL = 1e-9
# a dissected J_EE's pivots: the diagonal while it is at least this fraction of the largest
# entry of its column (J_EE is factorised untransposed, below), so that the order holds
# (threshold pivoting's usual 0.1; with SuperLU's partial pivoting, 1.0, the 1000-grain
# J_EEᵀ's factors held 9.2 M entries, not 7.0 M; untransposed at 0.1, ~450 of the 20 290
# pivots leave the diagonal, 22 for J_EEᵀ)
DIAGONAL_PIVOT = 0.1
# the normwise backward error ‖J x − b‖∞ / (‖J‖∞ ‖x‖∞ + ‖b‖∞) a dissected factorization's
# first solve must meet, else J_EE is factorised again with partial pivoting (1.0)
BACKWARD_ERROR = 1e-12
# the kept solves J0⁻¹ e_r (|E| floats each) of one factorization: at most this many, then
# J is factorised anew
KEPT_SOLVES = 4 * UPDATE_ROWS


class _Factorization:
    """J0 = I − G0 + G0 ρ (W + shift I) factorised on its engaged rows E:
    x_O = b_O, J_EE x_E = b_E − J_EO b_O; and its solves for unit vectors, kept on E alone
    (Z = J0⁻¹ e_r is e_r on O: most rows of a large problem are open, and the kept
    columns of all N rows cost a fifth of a 1000-grain step to gather)."""

    def __init__(self, W: BlockRows, G: np.ndarray, rho: np.ndarray, shift: float,
                 pivot: float = DIAGONAL_PIVOT):
        self.G = G.copy()
        # E in the order J_EE is factorised: a large problem's by nested dissection
        # (ordering.py; SuperLU then keeps it, preferring diagonal pivots: ``pivot``),
        # else sorted
        self.engaged = np.flatnonzero(_engaged(G))
        self.dissected = self.engaged.size >= DISSECTION_ROWS
        if self.dissected:
            order = dissection_order(W, self.engaged)
            self.dissected = order is not None
            self.engaged = order if order is not None else self.engaged
        self.outside, self.position = _positions(self.engaged, G.shape[0] * G.shape[1])
        self.J_ee, self.J_eo = _rows(W, G, rho, shift, 1.0, self.engaged, self.position)
        self.factorise(pivot)

    def factorise(self, pivot: float) -> None:
        """J_EE = LU (SuperLU; a dissected J_EE with ``pivot`` as its diagonal pivots'
        threshold), the kept solves forgotten. Raises RuntimeError where J_EE is singular."""
        self.pivot = pivot
        if not self.engaged.size:
            self.lu, self.trans = None, "T"
        elif self.dissected:
            # J_EE itself, converted to CSC (6 ms at 20 290 rows): SuperLU solves several
            # right-hand sides at once only untransposed (the kept columns: 8 of them 24
            # against 57 ms, one 7.8 against 7.4 ms), for a factorization 15–20% slower
            # (~450 of 20 290 pivots off the diagonal, against 22 transposed; a similarity
            # scaling of the contacts by ρ^-½ left them: they are within contacts)
            self.lu, self.trans = spla.splu(self.J_ee.tocsc(), permc_spec="NATURAL",
                                            diag_pivot_thresh=pivot), "N"
        else:
            # not dissected (below DISSECTION_ROWS, or METIS failed): J_EEᵀ is the CSC
            # matrix of J_EE's CSR arrays, factorised without a conversion (SuperLU's
            # symmetric mode took a fifth less time but its other round-off made the
            # quasi-static D10 squeeze's loop stall at step 47: not kept, session 26; the
            # dissected path's diagonal pivots apply from DISSECTION_ROWS, which the D10
            # squeezes do not reach)
            self.lu, self.trans = spla.splu(self.J_ee.T), "T"
        # the kept solves' rows E as the columns of one array (|E|, capacity), and each row
        # r's column in it
        self.unit_solves = np.empty((self.engaged.size, 0))
        self.unit_column: dict[int, int] = {}

    def solve(self, b: np.ndarray) -> np.ndarray:
        """J0⁻¹ b for b (N,) or (N, k)."""
        x = b.copy()
        if self.lu is not None:
            x[self.engaged] = self.lu.solve(b[self.engaged] - self.J_eo @ b[self.outside],
                                            trans=self.trans)
        return x

    def backward_error(self, x: np.ndarray, b: np.ndarray) -> float:
        """‖J0 x − b‖∞ / (‖J0‖∞ ‖x‖∞ + ‖b‖∞) (the rows outside E: the identity's, so ‖J0‖∞ ≥
        1 where there are any; taken ≥ 1 always, a lenient bound)."""
        # (row sums from the CSR arrays: SciPy's abs() would sort a dissected J_EE's
        # columns in place first)
        m = self.engaged.size
        sums = np.zeros(m)
        for J in (self.J_ee, self.J_eo):
            sums += np.bincount(np.repeat(np.arange(m), np.diff(J.indptr)), np.abs(J.data),
                                minlength=m)
        norm = max(1.0, float(sums.max(initial=0.0)))
        scale = norm * np.abs(x).max(initial=0.0) + np.abs(b).max(initial=0.0)
        residual = np.abs(self.times(x) - b).max(initial=0.0)
        return float(residual / scale) if scale > 0.0 else float(residual)

    def times(self, x: np.ndarray) -> np.ndarray:
        """J0 x."""
        y = x.copy()
        if self.engaged.size:
            y[self.engaged] = self.J_ee @ x[self.engaged] + self.J_eo @ x[self.outside]
        return y

    def columns(self, rows: np.ndarray) -> np.ndarray:
        """Z_E, the rows E of Z = J0⁻¹ U (U the unit vectors of ``rows``; Z_O = U_O), as
        (|E|, m), from the kept solves: Z_E = J_EE⁻¹ (U_E − J_EO U_O)."""
        missing = [int(r) for r in rows if int(r) not in self.unit_column]
        if missing:
            kept, size = len(self.unit_column), self.engaged.size
            right = np.zeros((size, len(missing)))
            position = self.position[missing]
            inside = position >= 0
            right[position[inside], np.flatnonzero(inside)] = 1.0
            if not inside.all():
                right[:, ~inside] = -self.J_eo[:, -position[~inside] - 1].toarray()
            Z = self.lu.solve(right, trans=self.trans) if self.lu is not None else right
            if kept + len(missing) > self.unit_solves.shape[1]:  # room for twice as many
                grown = np.empty((size, 2 * (kept + len(missing))))
                grown[:, :kept] = self.unit_solves[:, :kept]
                self.unit_solves = grown
            self.unit_solves[:, kept:kept + len(missing)] = Z
            self.unit_column.update((r, kept + j) for j, r in enumerate(missing))
        return np.take(self.unit_solves, [self.unit_column[int(r)] for r in rows], axis=1)


class NewtonMatrix:
    """The Newton steps of one contact problem: dr solving J dr = b for
    J = I − G + G ρ (W + shift I) (W, ρ and the shift fixed, G given at each step).

    A row where G vanishes is a row of the identity, so only the engaged rows E are
    factorised (most contacts of a dense packing are open). The factorization of one J0 is
    kept; while J differs from it in at most UPDATE_ROWS rows R, J = J0 + U Dᵀ (U the unit
    vectors of R, Dᵀ the differences of those rows) and, by the Woodbury identity,
        dr = y − Z (I + Dᵀ Z)⁻¹ Dᵀ y,   y = J0⁻¹ b,   Z = J0⁻¹ U
    (Z's columns kept too). Where J_EE is singular (the LU fails or overflows) a damped
    least-squares step on the engaged rows."""

    def __init__(self, W: sp.bsr_matrix | BlockRows, rho: np.ndarray, shift: float = 0.0):
        self.W, self.rho, self.shift = as_block_rows(W), rho, float(shift)
        self.base: _Factorization | None = None
        self.factorizations = 0  # for the diagnostics and tests
        self.updates = 0
        self.repivoted = 0  # dissected factorizations redone with partial pivoting
        # the dissected factorizations' pivot threshold: partial pivoting (1.0) for the
        # rest of the problem once a factorization needed it
        self.pivot = DIAGONAL_PIVOT

    def solve(self, G: np.ndarray, b: np.ndarray) -> np.ndarray:
        if self.base is not None:
            dr = self._updated(G, b)
            if dr is not None:
                self.updates += 1
                return dr
        try:
            self.base = _Factorization(self.W, G, self.rho, self.shift, self.pivot)
            self.factorizations += 1
            dr = self.base.solve(b)
            if (self.base.dissected and self.pivot < 1.0
                    and (not np.all(np.isfinite(dr))
                         or not self.base.backward_error(dr, b) <= BACKWARD_ERROR)):
                # diagonal pivots that grew: the same order and J_EE, partial pivoting
                self.pivot = 1.0
                self.base.factorise(self.pivot)
                self.factorizations += 1
                self.repivoted += 1
                dr = self.base.solve(b)
        except RuntimeError:  # (SuperLU: J_EE singular)
            self.base, dr = None, None
        if dr is None or not np.all(np.isfinite(dr)):
            self.base = None
            return self._least_squares(G, b)
        return dr

    def _updated(self, G: np.ndarray, b: np.ndarray) -> np.ndarray | None:
        """The Woodbury solve on the kept factorization, or None (too many rows changed,
        or its residual is not small)."""
        base = self.base
        changed = np.flatnonzero(differing_rows(G, base.G, G.shape[1]))
        if changed.size == 0:
            dr = base.solve(b)
            return dr if np.all(np.isfinite(dr)) else None
        if changed.size > UPDATE_ROWS or len(base.unit_column) + changed.size > KEPT_SOLVES:
            return None
        # J is affine in G: the changed rows' differences are those of −ΔG + ρ ΔG (W + shift I),
        # split by their columns in E and O (D = [D_E D_O])
        D_e, D_o = _rows(self.W, G - base.G, self.rho, self.shift, 0.0, changed,
                         base.position)
        Z_e = base.columns(changed)  # Z = [Z_E; U_O]: Z_O has a 1 at (r_j, j) for r_j in O
        at = base.position[changed]
        open_rows = np.flatnonzero(at < 0)
        DZ = D_e @ Z_e
        if open_rows.size:
            DZ[:, open_rows] += D_o[:, -at[open_rows] - 1].toarray()
        y = base.solve(b)
        with np.errstate(over="ignore", invalid="ignore"):
            try:
                c = np.linalg.solve(np.eye(changed.size) + DZ,
                                    D_e @ y[base.engaged] + D_o @ y[base.outside])
            except np.linalg.LinAlgError:
                return None
            dr = y.copy()
            dr[base.engaged] -= Z_e @ c
            dr[changed[open_rows]] -= c[open_rows]
            residual = base.times(dr) - b
            residual[changed] += D_e @ dr[base.engaged] + D_o @ dr[base.outside]
            if not np.linalg.norm(residual) <= UPDATE_RESIDUAL * np.linalg.norm(b):
                return None  # (also where not finite)
        # a row of the identity (G_i = 0: an open contact's component) exactly, as a
        # factorization gives it (an impulse opened by the step is then exactly 0)
        identity = ~_engaged(G)
        dr[identity] = b[identity]
        return dr

    def _least_squares(self, G: np.ndarray, b: np.ndarray) -> np.ndarray:
        engaged = np.flatnonzero(_engaged(G))
        dr = b.copy()
        J_ee, coupling = engaged_jacobian(self.W, G, self.rho, engaged, dr, self.shift)
        dr[engaged] = spla.lsqr(J_ee, dr[engaged] - coupling, damp=1e-8)[0]
        return dr

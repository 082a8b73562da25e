"""The Delassus operator W of a contact problem, in given contact frames: its block rows
(assembled whole, :func:`assemble`, or each when first asked for, :class:`BlockRows`) and
its product with impulses (:func:`product`).

    w_c = q_c + Σ_c' W_cc' P_c',   W_cc' = Σ_s σ_c σ_c' R_c W_s[col_c, col_c'] R_c'ᵀ

over the bodies s that both contacts touch (σ = +1 on the α side, −1 on β; R_c: the frame
of contact c, rows n, t1 (, t2); the identity for global axes). Each contact touches at most
two deformable bodies, so block row c is the union of the contacts touching its one or two
bodies: a Numba kernel builds it directly as block-sparse rows (d × d blocks, columns
sorted), a contact touching both of c's bodies summed once (the COO build with its
duplicate sums and a separate rotation took ~0.17 s for 1600 contacts of a dense
compaction, at every coupling iteration). The solvers read only the rows of the contacts
that carry impulses or are engaged (W is symmetric: a column is a row), a few % of the
contacts of a large problem.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit


@njit(cache=True)
def _touches_of_contacts(n, contact):
    """first[c], second[c]: the indices of contact c's touches (−1 where none)."""
    first = -np.ones(n, np.int64)
    second = -np.ones(n, np.int64)
    for t in range(contact.size):
        c = contact[t]
        if first[c] < 0:
            first[c] = t
        else:
            second[c] = t
    return first, second


@njit(cache=True)
def _block_rows(rows, n, contact, slot_start, slot_end, first, second):
    """For the block rows ``rows`` (contacts): ptr (rows.size + 1) and their sorted block
    columns (the touches of contact c's bodies, each other contact once)."""
    bound = np.zeros(rows.size + 1, np.int64)
    for e in range(rows.size):
        c = rows[e]
        for t in (first[c], second[c]):
            if t >= 0:
                bound[e + 1] += slot_end[t] - slot_start[t]
    bound = np.cumsum(bound)
    columns = np.empty(bound[-1], np.int64)
    ptr = np.zeros(rows.size + 1, np.int64)
    mark = -np.ones(n, np.int64)
    for e in range(rows.size):
        c = rows[e]
        k = bound[e]
        for t in (first[c], second[c]):
            if t < 0:
                continue
            for j in range(slot_start[t], slot_end[t]):
                other = contact[j]
                if mark[other] != c:
                    mark[other] = c
                    columns[k] = other
                    k += 1
        columns[bound[e]:k] = np.sort(columns[bound[e]:k])
        ptr[e + 1] = ptr[e] + k - bound[e]
    indices = np.empty(ptr[-1], np.int64)
    for e in range(rows.size):
        indices[ptr[e]:ptr[e + 1]] = columns[bound[e]:bound[e] + ptr[e + 1] - ptr[e]]
    return ptr, indices


@njit(cache=True)
def _block_values(rows, contact, slot_start, slot_end, first, second, col, sign, base, kd, W,
                  frames, ptr, indices):
    """The d × d blocks of the block rows ``rows`` (their columns: ptr, indices):
    σ_c σ_c' R_c W_s[col_c, col_c'] R_c'ᵀ summed over shared bodies (touch t:
    W_s[i, j] = W[base[t] + i kd[t] + j])."""
    n, d = frames.shape[0], frames.shape[1]
    data = np.zeros((indices.size, d, d))
    position = -np.ones(n, np.int64)
    block = np.empty((d, d))
    for e in range(rows.size):
        c = rows[e]
        for k in range(ptr[e], ptr[e + 1]):
            position[indices[k]] = k
        for t in (first[c], second[c]):
            if t < 0:
                continue
            for j in range(slot_start[t], slot_end[t]):
                other = contact[j]
                s = sign[t] * sign[j]
                for p in range(d):  # block = W_s[col_t, col_j] R_otherᵀ
                    at = base[t] + (col[t] * d + p) * kd[t] + col[j] * d
                    for q in range(d):
                        acc = 0.0
                        for r in range(d):
                            acc += W[at + r] * frames[other, q, r]
                        block[p, q] = acc
                out = data[position[other]]
                for p in range(d):
                    for q in range(d):
                        acc = 0.0
                        for r in range(d):
                            acc += frames[c, p, r] * block[r, q]
                        out[p, q] += s * acc
    return data


class BlockRows:
    """W's d × d block rows in given contact frames (columns sorted), each assembled when
    first asked for (:meth:`ensure`): block row c is ``indices[start[c]:end[c]]`` and
    ``data[start[c]:end[c]]``. The products and the Newton matrices read only the rows of
    the contacts that carry impulses or are engaged — a few % of a large problem's (the
    whole W of a 1000-grain compaction front's 43 116 contacts is 240 MB, 0.4 s to build)."""

    def __init__(self, n: int, d: int, build=None) -> None:
        self.n, self.d, self._build = n, d, build
        self.start = np.zeros(n, np.int64)
        self.end = np.zeros(n, np.int64)
        self.built = np.zeros(n, bool)
        self.indices = np.empty(0, np.int64)
        self.data = np.empty((0, d, d))
        self.size = 0  # entries in use of indices and data

    @classmethod
    def from_bsr(cls, W: sp.bsr_matrix) -> BlockRows:
        """Every row of a BSR matrix with square d × d blocks."""
        d = W.blocksize[0]
        rows = cls(W.shape[0] // d, d)
        rows.start[:] = W.indptr[:-1]
        rows.end[:] = W.indptr[1:]
        rows.built[:] = True
        rows.indices, rows.data = W.indices.astype(np.int64), W.data
        rows.size = W.indices.size
        return rows

    def ensure(self, contacts: np.ndarray) -> BlockRows:
        """Assemble the rows of ``contacts`` not built yet."""
        contacts = np.asarray(contacts, np.int64)
        new = np.unique(contacts[~self.built[contacts]])
        if new.size:
            ptr, indices, data = self._build(new)
            if self.size + indices.size > self.indices.size:  # room for twice as many
                grown = 2 * (self.size + indices.size)
                self.indices = np.resize(self.indices, grown)
                data_grown = np.empty((grown, self.d, self.d))
                data_grown[:self.size] = self.data[:self.size]
                self.data = data_grown
            self.indices[self.size:self.size + indices.size] = indices
            self.data[self.size:self.size + indices.size] = data
            self.start[new] = self.size + ptr[:-1]
            self.end[new] = self.size + ptr[1:]
            self.built[new] = True
            self.size += indices.size
        return self


def _row_builder(contact, slot, col, sign, W, w_off, k_size, frames):
    """rows ↦ (ptr, indices, data) of those block rows of W (:func:`_block_rows`,
    :func:`_block_values`)."""
    n, d = frames.shape[0], frames.shape[1]
    slot_start = np.searchsorted(slot, slot, side="left")
    slot_end = np.searchsorted(slot, slot, side="right")
    first, second = _touches_of_contacts(n, contact)
    sign, base, kd = np.asarray(sign, float), w_off[slot], k_size[slot] * d
    W, frames = np.ascontiguousarray(W, float), np.ascontiguousarray(frames, float)

    def build(rows):
        ptr, indices = _block_rows(rows, n, contact, slot_start, slot_end, first, second)
        data = _block_values(rows, contact, slot_start, slot_end, first, second, col, sign,
                             base, kd, W, frames, ptr, indices)
        return ptr, indices, data

    return build


def block_rows(contact: np.ndarray, slot: np.ndarray, col: np.ndarray, sign: np.ndarray,
               W: np.ndarray, w_off: np.ndarray, k_size: np.ndarray,
               frames: np.ndarray) -> BlockRows:
    """W in the given frames, by block rows built on demand, from the touches (contact,
    body slot, column, sign) grouped by slot as ContactProblem.touches gives."""
    return BlockRows(frames.shape[0], frames.shape[1],
                     _row_builder(contact, slot, col, sign, W, w_off, k_size, frames))


def assemble(contact: np.ndarray, slot: np.ndarray, col: np.ndarray, sign: np.ndarray,
             W: np.ndarray, w_off: np.ndarray, k_size: np.ndarray,
             frames: np.ndarray) -> sp.bsr_matrix:
    """W in the given frames (n d × n d, (contact, component) order; d × d blocks, every
    diagonal block present) from the touches (contact, body slot, column, sign), grouped
    by slot as ContactProblem.touches gives."""
    n, d = frames.shape[0], frames.shape[1]
    if contact.size == 0:
        return sp.bsr_matrix((n * d, n * d), blocksize=(d, d))
    build = _row_builder(contact, slot, col, sign, W, w_off, k_size, frames)
    ptr, indices, data = build(np.arange(n, dtype=np.int64))
    return sp.bsr_matrix((data, indices, ptr), shape=(n * d, n * d))


@njit(cache=True, nogil=True)
def _block_product_by_columns(start, end, indices, data, shift, x, columns):
    """y = (W + shift I) x for a symmetric W by d × d block rows (row j: entries
    start[j] … end[j]) and an x that is zero outside the block ``columns``:
    y_c = Σ_j W_cj x_j = Σ_j W_jcᵀ x_j over those j, from their block rows alone."""
    n, d = start.size, data.shape[1]
    flat = data.reshape(data.shape[0] * d * d)
    y = np.zeros(n * d)
    for j in columns:
        xj = j * d
        if d == 2:
            x0, x1 = x[xj], x[xj + 1]
            for k in range(start[j], end[j]):
                at, yc = k * 4, indices[k] * 2
                y[yc] += flat[at] * x0 + flat[at + 2] * x1
                y[yc + 1] += flat[at + 1] * x0 + flat[at + 3] * x1
        else:
            x0, x1, x2 = x[xj], x[xj + 1], x[xj + 2]
            for k in range(start[j], end[j]):
                at, yc = k * 9, indices[k] * 3
                y[yc] += flat[at] * x0 + flat[at + 3] * x1 + flat[at + 6] * x2
                y[yc + 1] += flat[at + 1] * x0 + flat[at + 4] * x1 + flat[at + 7] * x2
                y[yc + 2] += flat[at + 2] * x0 + flat[at + 5] * x1 + flat[at + 8] * x2
        for p in range(d):
            y[xj + p] += shift * x[xj + p]
    return y


def as_block_rows(W: sp.bsr_matrix | BlockRows) -> BlockRows:
    """W's block rows (a BSR matrix: all of them, built)."""
    return W if isinstance(W, BlockRows) else BlockRows.from_bsr(W)


def product(W: sp.bsr_matrix | BlockRows, x: np.ndarray, shift: float = 0.0) -> np.ndarray:
    """(W + shift I) x for the block rows of :func:`block_rows` or :func:`assemble` (x
    flat, (contact, component) order), W symmetric (the bodies' compliances are:
    BodyStep.contact_response): only the block rows of the contacts whose x_j is not zero
    are read. Most impulses of a large problem are zero (the contacts in reach but open:
    50% in a dense 100-grain compaction, 84–96% in a 1000-grain compaction front), and
    reading them cost a fifth of a step there; at every density this kernel is as fast as
    SciPy's CSR product."""
    rows = as_block_rows(W)
    d = rows.d
    if d not in (2, 3):
        raise ValueError(f"the Delassus product is for 2D and 3D contacts, not {d}D")
    x = np.ascontiguousarray(x, float)
    columns = np.flatnonzero(nonzero_rows(x, d))
    rows.ensure(columns)
    return _block_product_by_columns(rows.start, rows.end, rows.indices, rows.data,
                                     float(shift), x, columns)


def nonzero_rows(x: np.ndarray, width: int) -> np.ndarray:
    """Whether each row of x, read as rows of ``width`` entries, has an entry ≠ 0: the
    same as np.any(x.reshape(-1, width) != 0, axis=1), whose reduction over a short axis
    took ~1 ms on 43 000 contacts (this kernel 0.2 ms), several times a Newton iteration."""
    return _rows_differ(np.ascontiguousarray(x, float).reshape(-1, width), None)


def differing_rows(x: np.ndarray, y: np.ndarray, width: int) -> np.ndarray:
    """Whether each row of x (rows of ``width`` entries) differs from y's in any entry."""
    return _rows_differ(np.ascontiguousarray(x, float).reshape(-1, width),
                        np.ascontiguousarray(y, float).reshape(-1, width))


@njit(cache=True)
def _rows_differ(a, b):
    """Row i: a[i, j] ≠ b[i, j] for some j (b None: ≠ 0; NaN differs from everything)."""
    m, k = a.shape
    out = np.zeros(m, np.bool_)
    for i in range(m):
        for j in range(k):
            other = 0.0 if b is None else b[i, j]
            if a[i, j] != other:
                out[i] = True
                break
    return out

"""Contact patches: a grain's point contacts against a wall grouped by the lattice node
nearest to their point, one multiplier per patch (issue #11).

Point contacts (surfaces.py) outnumber the velocity modes they sample: two points per h
against about one velocity mode per h along a line. Against a flat wall a flat row of lattice
points makes the Delassus matrix exactly singular (the impulses are not unique and every
solver stalls: the sliding test's block on its slab hung). A patch k gathers the point
contacts p of one pair (α, β) whose point is nearest to lattice node X_k, and constrains a
weighted mean of their gaps:

    Σ_p ŵ_p g_p + Δt n_k·w_k ≥ 0 at the end of the step,
    w_k = Σ_p ŵ_p R_kp (v^α_p − v^β_p),     n_k = Σ_p ŵ_p n_p / ‖Σ_p ŵ_p n_p‖,
    ŵ_p ∝ exp(−(g_p − min_{q∈k} g_q)/ℓ),  Σ_p ŵ_p = 1,  ℓ = 0.1 h,

R_kp the rotation taking p's normal onto the patch's (R_kp n_p = n_k), so that n_k·w_k =
Σ_p ŵ_p n_p·w_p is the weighted rate of the points' own gaps and the patch's tangential
velocity the weighted mean of theirs. The weights, fixed at the start of the step, make the
patch follow its closest points (a lattice staircase δ = h/2 higher weighs e⁻⁵; points on a
flat face weigh alike). The patch impulse P_k acts at each of its points as ŵ_p R_kpᵀ P_k on
α and its opposite on β: momentum is exchanged exactly, normal impulses act along each
point's own normal. A point may overlap by up to the spread of its patch's gaps within the
step; the least member gap at the start of the step is what is reported.

Between two grains each point stays a patch of its own: grouping them (both passes, or each
pass) let a disk sliding on a block sink 0.06–0.14 h and lose more speed than single points
(0.056 h; session 13, docs/dev-notes.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GAP_SCALE = 0.1  # ℓ/h of the patch weights ŵ_p ∝ exp(−(g_p − min_patch g)/ℓ)


@dataclass(frozen=True)
class Patches:
    """Point contacts grouped: each point's patch and weight, each patch's node, normal,
    mean gap and least member gap, and each point's rotation onto its patch's normal."""

    of_point: np.ndarray  # (n_points,) patch index
    weight: np.ndarray  # (n_points,) ŵ_p
    rotation: np.ndarray  # (n_points, d, d) R_kp
    node: np.ndarray  # (n_patches,) flat lattice index of the patch's node
    alpha: np.ndarray
    beta: np.ndarray
    site: np.ndarray  # −2 for a patch of several points, a lone point's code otherwise
    normal: np.ndarray  # (n_patches, d)
    position: np.ndarray  # (n_patches, d): the mean of its points
    gap: np.ndarray  # (n_patches,) Σ ŵ_p g_p
    least_gap: np.ndarray  # (n_patches,) min_p g_p (what is reported as overlap)

    def __len__(self) -> int:
        return self.node.size


def rotations(n_from: np.ndarray, n_to: np.ndarray) -> np.ndarray:
    """The rotation R (n, d, d) of least angle with R n_from = n_to, for unit vectors in 2D
    or 3D (Rodrigues: R = c I + [v]× + v vᵀ/(1 + c), v = n_from × n_to, c = n_from·n_to)."""
    n, d = n_from.shape
    c = np.einsum("pi,pi->p", n_from, n_to)
    if d == 2:
        s = n_from[:, 0] * n_to[:, 1] - n_from[:, 1] * n_to[:, 0]
        return np.stack([np.stack([c, -s], axis=1), np.stack([s, c], axis=1)], axis=1)
    v = np.cross(n_from, n_to)
    cross = np.zeros((n, 3, 3))
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    cross -= cross.transpose(0, 2, 1)
    return (c[:, None, None] * np.eye(3) + cross
            + np.einsum("pi,pj->pij", v, v) / np.maximum(1.0 + c, 1e-12)[:, None, None])


def group(alpha: np.ndarray, beta: np.ndarray, position: np.ndarray, normal: np.ndarray,
          gap: np.ndarray, origin: np.ndarray, h: float, n_nodes: np.ndarray,
          alone: np.ndarray) -> Patches:
    """Group point contacts (pair, point position, normal from β into α, gap) into patches
    by pair and nearest lattice node."""
    index = np.rint((position - origin) / h).astype(np.int64)
    index = np.clip(index, 0, np.asarray(n_nodes) - 1)
    strides = np.r_[1, np.cumprod(n_nodes[:-1])].astype(np.int64)
    node = index @ strides
    keys = np.stack([alpha, beta, node, alone], axis=1)
    unique, of_point = np.unique(keys, axis=0, return_inverse=True)
    of_point = of_point.ravel()
    n_patches = unique.shape[0]
    least = np.full(n_patches, np.inf)
    np.minimum.at(least, of_point, gap)
    weight = np.exp(-(gap - least[of_point]) / (GAP_SCALE * h))
    weight /= np.bincount(of_point, weight, minlength=n_patches)[of_point]

    def mean(x):
        out = np.zeros((n_patches,) + x.shape[1:])
        np.add.at(out, of_point, weight.reshape((-1,) + (1,) * (x.ndim - 1)) * x)
        return out

    summed = mean(normal)
    patch_normal = summed / np.linalg.norm(summed, axis=1)[:, None]
    return Patches(of_point, weight, rotations(normal, patch_normal[of_point]), unique[:, 2],
                   unique[:, 0], unique[:, 1], np.where(unique[:, 3] >= 0, unique[:, 3], -2),
                   patch_normal, mean(position), mean(gap), least)


def aggregate(patches: Patches, rows: np.ndarray, blocks: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """One side's patch stencils from its point stencils: v_k = Σ_p ŵ_p R_kp Σ_j B_pj
    v_{rows_pj} (rows −1: none), returned as the rows of each patch (n_patches, S; −1
    padded; distinct within a patch of several points) and their summed blocks
    (n_patches, S, d, d). A patch of one point (R = I, ŵ = 1) keeps its point's stencil."""
    d = blocks.shape[-1]
    n_patches = len(patches)
    count = np.bincount(patches.of_point, minlength=n_patches)
    alone = count[patches.of_point] == 1
    out_rows = -np.ones((n_patches, rows.shape[1]), np.int64)
    out_blocks = np.zeros((n_patches, rows.shape[1], d, d))
    out_rows[patches.of_point[alone]] = rows[alone]
    out_blocks[patches.of_point[alone]] = blocks[alone]
    p_idx, j_idx = np.nonzero((rows >= 0) & ~alone[:, None])
    if p_idx.size == 0:
        return out_rows, out_blocks
    patch = patches.of_point[p_idx]
    row = rows[p_idx, j_idx]
    scaled = patches.weight[p_idx, None, None] * np.einsum(
        "pij,pjk->pik", patches.rotation[p_idx], blocks[p_idx, j_idx])
    stride = int(row.max()) + 1
    unique, inverse = np.unique(patch * stride + row, return_inverse=True)
    summed = np.zeros((unique.size, d * d))
    for e in range(d * d):  # (np.add.at on blocks is ~10x slower)
        summed[:, e] = np.bincount(inverse, scaled.reshape(-1, d * d)[:, e],
                                   minlength=unique.size)
    u_patch, u_row = unique // stride, unique % stride
    per_patch = np.bincount(u_patch, minlength=n_patches)
    width = max(int(per_patch.max()), rows.shape[1])
    if width > out_rows.shape[1]:
        extra = width - out_rows.shape[1]
        out_rows = np.pad(out_rows, ((0, 0), (0, extra)), constant_values=-1)
        out_blocks = np.pad(out_blocks, ((0, 0), (0, extra), (0, 0), (0, 0)))
    slot = np.arange(unique.size) - np.r_[0, np.cumsum(per_patch)][u_patch]
    out_rows[u_patch, slot] = u_row
    out_blocks[u_patch, slot] = summed.reshape(-1, d, d)
    return out_rows, out_blocks

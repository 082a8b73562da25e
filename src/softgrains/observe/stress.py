"""Von Mises equivalent stress per point (ALGORITHM.md §9),

    σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(σxy² + σyz² + σzx²))
with σ_zz the plane-strain out-of-plane stress in 2D (stored in sigma[:, 2, 2]), and a point
field smoothed per grain for display (project_per_grain, issue #13).
"""

import numpy as np
from numba import njit


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """σ_vm of Cauchy stresses sigma (n, 3, 3)."""
    sxx, syy, szz = sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 2, 2]
    shear = sigma[:, 0, 1] ** 2 + sigma[:, 1, 2] ** 2 + sigma[:, 2, 0] ** 2
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * shear)


def project_per_grain(x: np.ndarray, vol: np.ndarray, values: np.ndarray, grain: np.ndarray,
                      spacing: float) -> np.ndarray:
    """A point field smoothed for display (a moving-least-squares recovery): a linear
    least-squares fit at each node of a grid of ``spacing``, the fits blended at the points
    with linear hats over the nodes where the fit is well posed, each grain on its own
    nodes (grains do not blur into each other), then shifted to keep each grain's
    volume-weighted mean:

        (a_I, b_I) = argmin Σ_p N_I(x_p) V_p (a + b·(x_p − x_I) − v_p)²,
        ṽ_p = Σ_{I fitted} N_I(x_p) (a_I + b_I·(x_p − x_I)) / Σ_{I fitted} N_I(x_p) + c_g,
        c_g such that Σ_{p∈g} V_p ṽ_p = Σ_{p∈g} V_p v_p.

    A node whose points cannot fix a gradient (too few, or nearly collinear: at a grain's
    edge) is left out; a point with no fitted node keeps its own value. A linear field
    comes back unchanged (c_g = 0); peaks narrower than about a spacing are lowered.
    ``values`` is (n, ...) (scalars, vectors or tensors, component by component); ``x`` is
    (n, d), any d."""
    x = np.asarray(x, float)
    n, d = x.shape
    vol = np.asarray(vol, float)
    grain = np.asarray(grain, np.int64)
    values = np.asarray(values, float)
    flat = np.ascontiguousarray(values.reshape(n, -1))
    point, node, hat, basis = _grain_stencils(x / spacing, grain)
    n_nodes = int(node.max()) + 1
    moments = np.zeros((n_nodes, d + 1, d + 1))
    rhs = np.zeros((n_nodes, d + 1, flat.shape[1]))
    _node_sums(node, hat * vol[point], basis, flat, point, moments, rhs)
    mass = moments[:, 0, 0]
    # the gradient fit where the second moments (about the points' centroid) are well posed
    spread = moments[:, 1:, 1:] - np.einsum("ni,nj->nij", moments[:, 0, 1:], moments[:, 0, 1:]) \
        / np.where(mass > 0.0, mass, 1.0)[:, None, None]
    smallest = np.linalg.eigvalsh(spread)[:, 0] / np.where(mass > 0.0, mass, 1.0)
    fit = smallest > 1e-3  # points spread over at least ~3% of a cell in every direction
    coefficients = np.zeros_like(rhs)  # (nodes, 1 + d, components): a_I, then b_I
    if np.any(fit):
        coefficients[fit] = np.linalg.solve(moments[fit], rhs[fit])
    # back to the points over the fitted nodes, each node's fit a_I + b_I·(x_p − x_I) taken
    # at the point (a point with no fitted node keeps its own value)
    smoothed = flat.copy()
    _blend(node, hat * fit[node], basis, coefficients, len(basis) // n, smoothed)
    volume = np.bincount(grain, vol)
    shift = np.stack([np.bincount(grain, vol * (flat[:, c] - smoothed[:, c]))
                      for c in range(flat.shape[1])], axis=1)
    smoothed += (shift / np.where(volume > 0.0, volume, 1.0)[:, None])[grain]
    return smoothed.reshape(values.shape)


def _grain_stencils(scaled: np.ndarray, grain: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per (point, node of its cell), points in order, 2^d nodes each: the point, the
    node's index among the (grain, node) pairs, the hat weight N_I(x_p) and the basis
    [1, (x_p − x_I)/h]; ``scaled`` = x / h."""
    n, d = scaled.shape
    base = np.floor(scaled).astype(np.int64)
    corners = np.array(np.meshgrid(*[[0, 1]] * d, indexing="ij")).reshape(d, -1).T  # (2^d, d)
    cells = (base[:, None, :] + corners[None, :, :]).reshape(-1, d)
    point = np.repeat(np.arange(n), len(corners))
    offset = scaled[point] - cells
    hat = np.prod(1.0 - np.abs(offset), axis=1)
    # one integer key per (grain, node): the node's index in the box of all cells
    low = cells.min(axis=0)
    extent = cells.max(axis=0) - low + 1
    key = grain[point]
    for k in range(d):
        key = key * extent[k] + (cells[:, k] - low[k])
    _, node = np.unique(key, return_inverse=True)
    basis = np.ascontiguousarray(np.concatenate([np.ones((len(point), 1)), offset], axis=1))
    return point, node.ravel(), hat, basis


@njit(cache=True)
def _node_sums(node, weight, basis, values, point, moments, rhs):
    """moments_I += w N-weighted basis ⊗ basis, rhs_I += w basis ⊗ v_p over the entries
    (point, node) of the stencils."""
    for e in range(node.shape[0]):
        I, p, w = node[e], point[e], weight[e]
        for i in range(basis.shape[1]):
            wi = w * basis[e, i]
            for j in range(basis.shape[1]):
                moments[I, i, j] += wi * basis[e, j]
            for c in range(values.shape[1]):
                rhs[I, i, c] += wi * values[p, c]


@njit(cache=True)
def _blend(node, use, basis, coefficients, per_point, out):
    """out_p = Σ_I use_I (a_I + b_I·r) / Σ_I use_I over each point's ``per_point`` entries
    (left as it is where Σ use = 0)."""
    for p in range(out.shape[0]):
        total = 0.0
        for k in range(per_point):
            total += use[p * per_point + k]
        if total <= 0.0:
            continue
        for c in range(out.shape[1]):
            acc = 0.0
            for k in range(per_point):
                e = p * per_point + k
                value = 0.0
                for i in range(basis.shape[1]):
                    value += basis[e, i] * coefficients[node[e], i, c]
                acc += use[e] * value
            out[p, c] = acc / total

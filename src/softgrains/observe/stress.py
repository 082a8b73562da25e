"""Von Mises equivalent stress per point (ALGORITHM.md §9).

    σ_vm = √(½[(σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²] + 3(σxy² + σyz² + σzx²))
with σ_zz the plane-strain out-of-plane stress in 2D (stored in sigma[:, 2, 2]).
"""

import numpy as np


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
    comes back unchanged (c_g = 0); peaks narrower than about two spacings are lowered.
    ``values`` is (n, ...) (scalars, vectors or tensors, component by component); ``x`` is
    (n, d), any d."""
    x = np.asarray(x, float)
    n, d = x.shape
    vol = np.asarray(vol, float)
    grain = np.asarray(grain, np.int64)
    values = np.asarray(values, float)
    flat = values.reshape(n, -1)
    scaled = x / spacing
    base = np.floor(scaled).astype(np.int64)
    corners = np.array(np.meshgrid(*[[0, 1]] * d, indexing="ij")).reshape(d, -1).T  # (2^d, d)
    cells = (base[:, None, :] + corners[None, :, :]).reshape(-1, d)
    point = np.repeat(np.arange(n), len(corners))
    # per (point, node): node key (grain, node index...), weight N V, offset (x_p − x_I)/h
    keys = np.concatenate([grain[point, None], cells], axis=1)
    offset = scaled[point] - cells
    hat = np.prod(1.0 - np.abs(offset), axis=1)
    _, node = np.unique(keys, axis=0, return_inverse=True)
    node = node.ravel()
    weight = hat * vol[point]
    basis = np.concatenate([np.ones((len(point), 1)), offset], axis=1)  # [1, r]
    moments = np.stack([np.bincount(node, weight * basis[:, i] * basis[:, j])
                        for i in range(d + 1) for j in range(d + 1)], axis=1)
    moments = moments.reshape(-1, d + 1, d + 1)
    rhs = np.stack([np.stack([np.bincount(node, weight * basis[:, i] * flat[point, c])
                              for c in range(flat.shape[1])], axis=1)
                    for i in range(d + 1)], axis=1)  # (nodes, d + 1, components)
    mass = moments[:, 0, 0]
    # the gradient fit where the second moments (about the points' centroid) are well posed
    spread = moments[:, 1:, 1:] - np.einsum("ni,nj->nij", moments[:, 0, 1:], moments[:, 0, 1:]) \
        / np.where(mass > 0.0, mass, 1.0)[:, None, None]
    smallest = np.linalg.eigvalsh(spread)[:, 0] / np.where(mass > 0.0, mass, 1.0)
    fit = smallest > 1e-3  # points spread over at least ~3% of a cell in every direction
    coefficients = np.zeros_like(rhs)  # (nodes, 1 + d, components): a_I, then b_I
    if np.any(fit):
        coefficients[fit] = np.linalg.solve(moments[fit], rhs[fit])
    # back to the points over the fitted nodes, each node's fit taken at the point
    # (a point with no fitted node keeps its own value)
    use = hat * fit[node]
    total = np.bincount(point, use, minlength=n)
    at_point = np.einsum("ki,kic->kc", basis, coefficients[node])  # a_I + b_I·(x_p − x_I)
    smoothed = np.stack([np.bincount(point, use * at_point[:, c], minlength=n)
                         for c in range(flat.shape[1])], axis=1)
    covered = total > 0.0
    smoothed[covered] /= total[covered, None]
    smoothed[~covered] = flat[~covered]
    volume = np.bincount(grain, vol)
    shift = np.stack([np.bincount(grain, vol * (flat[:, c] - smoothed[:, c]))
                      for c in range(flat.shape[1])], axis=1)
    smoothed += (shift / np.where(volume > 0.0, volume, 1.0)[:, None])[grain]
    return smoothed.reshape(values.shape)

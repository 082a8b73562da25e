"""Contact patches (contact/patches.py): a grain's point contacts against a wall grouped by
nearest lattice node, one multiplier per patch."""

import numpy as np
import pytest
from test_relations import _disk_sliding_on_block

from softgrains.contact import patches

H = 0.1


@pytest.mark.parametrize("d", [2, 3])
def test_rotations_turn_each_normal_onto_the_target_and_are_rotations(d):
    """R n_from = n_to, RᵀR = I and det R = 1 for random unit vectors (2D and 3D); R = I
    where the two are equal."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, d)), rng.normal(size=(50, d))
    a /= np.linalg.norm(a, axis=1)[:, None]
    b /= np.linalg.norm(b, axis=1)[:, None]
    R = patches.rotations(a, b)
    assert np.allclose(np.einsum("pij,pj->pi", R, a), b, atol=1e-12)
    assert np.allclose(np.einsum("pki,pkj->pij", R, R), np.eye(d), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    assert np.allclose(patches.rotations(a, a), np.eye(d), atol=1e-14)


def _row_of_points(gaps, tilt=0.0):
    """Lattice points δ = h/2 apart along x at y = 0.5 from x = 0.5 + ¾h, two nearest to
    each node (one pair: grain 0 against wall 1), their normals tilted by ``tilt`` radians
    alternately."""
    n = len(gaps)
    x = np.c_[0.5 + (0.75 + 0.5 * np.arange(n)) * H, np.full(n, 0.5)]
    angle = tilt * (-1.0) ** np.arange(n)
    normal = np.c_[np.sin(angle), np.cos(angle)]
    return x, normal, np.asarray(gaps, float)


def _group(x, normal, gap, alone=None):
    n = len(gap)
    return patches.group(np.zeros(n, np.int64), np.ones(n, np.int64), x, normal, gap,
                         np.zeros(2), H, np.array([21, 21]),
                         -np.ones(n, np.int64) if alone is None else alone)


def test_points_on_a_flat_face_share_their_patch_alike():
    """Six points h/2 apart on a flat face form three patches (one per node, two points
    each) with equal weights, the patch's gap the points' gap and its normal theirs; a
    point marked alone is a patch of its own with its code as site."""
    x, normal, gap = _row_of_points([0.01] * 6)
    found = _group(x, normal, gap)
    assert len(found) == 3
    assert np.allclose(found.weight, 0.5)
    assert np.allclose(found.gap, 0.01) and np.allclose(found.least_gap, 0.01)
    assert np.allclose(found.normal, [0.0, 1.0])
    assert np.all(found.site == -2)
    alone = _group(x, normal, gap, alone=np.arange(6) * 2)
    assert len(alone) == 6 and np.allclose(alone.weight, 1.0)
    assert sorted(alone.site) == list(range(0, 12, 2))


def test_a_patch_follows_its_closest_point():
    """A point δ = h/2 further from the wall than its patch partner (a lattice staircase)
    weighs e⁻⁵ of it: the patch's gap is within 0.004 h of the closer point's; the least
    member gap is reported."""
    x, normal, gap = _row_of_points([0.0, 0.5 * H])
    found = _group(x, normal, gap)
    assert len(found) == 1
    assert found.weight[1] / found.weight[0] == pytest.approx(np.exp(-5.0))
    assert 0.0 < found.gap[0] < 0.004 * H
    assert found.least_gap[0] == 0.0


def test_a_patch_velocity_is_its_points_velocities_turned_onto_its_normal():
    """aggregate: with point sites v_p = Σ_j B_pj v_{rows_pj}, the patch site gives
    Σ_p ŵ_p R_p v_p; its normal component is the weighted mean of each point's own normal
    velocity n_p·v_p, and each node row appears once in the patch's stencil."""
    rng = np.random.default_rng(3)
    x, normal, gap = _row_of_points([0.0, 0.01 * H, 0.0, 0.02 * H], tilt=0.2)
    found = _group(x, normal, gap)
    n_rows = 7
    rows = rng.integers(-1, n_rows, size=(4, 5))
    blocks = rng.normal(size=(4, 5, 2, 2))
    v = rng.normal(size=(n_rows, 2))
    point_v = np.einsum("pjab,pjb->pa", blocks, np.where(rows[..., None] >= 0, v[rows], 0.0))
    patch_rows, patch_blocks = patches.aggregate(found, rows, blocks)
    patch_v = np.einsum("kjab,kjb->ka", patch_blocks,
                        np.where(patch_rows[..., None] >= 0, v[patch_rows], 0.0))
    for k in range(len(found)):
        mine = found.of_point == k
        w, R = found.weight[mine], found.rotation[mine]
        assert np.allclose(patch_v[k], np.einsum("p,pab,pb->a", w, R, point_v[mine]))
        assert patch_v[k] @ found.normal[k] == pytest.approx(
            np.sum(w * np.einsum("pa,pa->p", normal[mine], point_v[mine])))
        # each row appears once per patch
        kept = patch_rows[k][patch_rows[k] >= 0]
        assert kept.size == np.unique(kept).size


def test_a_grain_on_a_wall_with_contacts_at_its_points_is_solved_every_step():
    """The sliding test's block on its kinematic slab (μ = 1) with ``wall_sites =
    "surface"``: the block's bottom row of lattice points lies on the slab's flat face, two
    points per h against one velocity mode per h, and the per-point Delassus matrix is
    exactly singular; from step 2 every contact solve failed (Newton, Gauss–Seidel,
    Tresca) and the loop hung at its 200-iteration limit (session 12). With the patches
    every step converges in ≤ 4 coupling iterations and the block stays on the slab within
    0.05 h (measured: 2 iterations a step, −0.010 h over 1 s)."""
    sim = _disk_sliding_on_block(wall_sites="surface")
    block = sim.model.bodies[1].points
    h, delta = sim.model.lattice.h, sim.model.lattice.h / 2
    for _ in range(20):
        diag = sim.step()
        assert diag.contact.converged and diag.contact.iterations <= 4
        bottom = sim.state.x[block, 1].min() - delta / 2
        assert bottom - 0.3 > -0.05 * h

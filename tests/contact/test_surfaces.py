"""Point-to-surface contact between grains (contact/surfaces.py, ``grain_sites =
"surface"``): the smoothed surface, its distance and its exact rate, on one body."""

import numpy as np
import pytest

from softgrains import Simulation, load_case
from softgrains.contact import surfaces
from softgrains.geometry import Rectangle
from softgrains.integrator.implicit import BodyStep

H = 0.1


def _body_steps(bodies: list[dict], h: float = H, size: float = 2.0,
                shape_function: str = "bspline2") -> dict[int, BodyStep]:
    """The steps of bodies at rest (material "gel") on a square grid, not yet solved."""
    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [size, size],
                 "shape_function": shape_function},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"material": "gel", **body} for body in bodies],
        "output": {"progress": False},
    }))
    solver = sim.solver
    return {i: BodyStep(solver.steppers[i], solver.body_points(sim.state, i), np.zeros(2),
                        1e-3, i) for i in range(len(bodies))}


def _body_step(shape_function: str, body: dict) -> BodyStep:
    """The step of a single body at rest (D/h = 10 for the disk), not yet solved."""
    return _body_steps([{"name": "body", **body}], shape_function=shape_function)[0]


DISK = {"shape": "disk", "center": [1.013, 1.0], "radius": 0.5}
BLOCK = {"shape": "rectangle", "lower": [0.5, 0.5], "upper": [1.5, 1.0]}


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
def test_surface_rate_is_the_time_derivative_of_the_smoothed_field(shape_function):
    """∂c/∂t = Σ_J a_J·v_J (surfaces._kernel_rate) against a finite difference: the body's
    points moved by ε Σ N v (and their volumes by ε ∇·v) for a random nodal velocity field
    change c at points just outside the disk by ε Σ a·v, to the difference's own error;
    and a rigid translation u gives Σ a·u = −∇c·u to round-off (momentum is exchanged
    exactly). (The grid-smoothed field Σ N_I(x) c_I of the first try was not
    translation-covariant: its rate under a rigid translation differed from −∇c·u by up
    to 20% at D/h 10.)"""
    step = _body_step(shape_function, DISK)
    surface = surfaces.KernelSurface(step)
    angle = np.linspace(0.0, 2.0 * np.pi, 13)[:-1]
    x = np.c_[1.013 + 0.52 * np.cos(angle), 1.0 + 0.52 * np.sin(angle)]
    c, grad = surface.field(x)
    rows, a = surface.rate(x)
    V = np.random.default_rng(0).normal(size=(step.active.size, 2))
    predicted = np.einsum("pkj,pkj->p", a, np.where(rows[:, :, None] >= 0, V[rows], 0.0))
    eps = 1e-6
    v_points = np.einsum("pk,pkj->pj", step.N, V[step.active_row[step.nodes]])
    div = np.einsum("pkj,pkj->p", step.dN, V[step.active_row[step.nodes]])
    step.pts.x[:] += eps * v_points
    step.pts.vol[:] *= 1.0 + eps * div
    moved, _ = surfaces.KernelSurface(step).field(x)
    difference = (moved - c) / eps
    assert np.max(np.abs(predicted - difference)) < 1e-4 * np.max(np.abs(difference))
    u = np.array([0.3, -0.7])
    rigid = np.einsum("pkj,pk->pj", a, (rows >= 0).astype(float)) @ u
    assert np.max(np.abs(rigid + grad @ u)) < 1e-12 * np.max(np.abs(grad @ u))


def test_field_sums_the_kernel_over_every_point_within_its_radius():
    """c(x) = Σ_q V_q W(‖x − x_q‖) and ∇c over the cell list (no neighbour lists written)
    equal the sums over every body point within the kernel radius, at points inside, across
    and outside the disk's surface, and where no point is within reach (c = 0)."""
    step = _body_step("bspline2", DISK)
    surface = surfaces.KernelSurface(step)
    rng = np.random.default_rng(3)
    x = np.r_[rng.uniform(0.3, 1.7, (200, 2)), [[1.9, 1.9]]]
    c, grad = surface.field(x)
    xq, vol, R = step.pts.x, step.pts.vol, surface.radius
    for p in range(len(x)):
        offset = x[p] - xq
        r = np.linalg.norm(offset, axis=1)
        inside = r <= R
        w = np.array([surfaces._wendland(ri, R, 2) for ri in r[inside]])
        expected_c = np.sum(vol[inside] * w[:, 0]) if inside.any() else 0.0
        expected_grad = (np.sum((vol[inside] * w[:, 1])[:, None] * offset[inside], axis=0)
                         if inside.any() else np.zeros(2))
        assert c[p] == pytest.approx(expected_c, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(grad[p], expected_grad, rtol=1e-12, atol=1e-12)
    assert c[-1] == 0.0 and np.all(grad[-1] == 0.0)
    assert np.count_nonzero(c > 0.0) > 100


def test_calibrated_distance_across_a_flat_boundary():
    """The distance to the ½ level of the kernel-smoothed volume fraction, read through the
    kernel's flat-boundary profile (surfaces.calibrated_distance), along a vertical line
    across the top of a lattice-seeded block at two lateral offsets. Measured (2026-12-02):
    0.0016 h at the surface, ≤ 0.034 h within ±0.5 h (the lattice sum of the kernel is not
    its integral); the first-order −(c − ½)/‖∇c‖ errs by 0.04 h at ±0.25 h and 0.40 h at
    ±0.5 h, which let an approaching body in by that much in one step."""
    surface = surfaces.KernelSurface(_body_step("bspline2", BLOCK))
    offset = np.linspace(-0.5, 0.5, 9) * H
    for x0 in (1.0, 1.013):
        x = np.c_[np.full(offset.size, x0), 1.0 + offset]
        c, grad = surface.field(x)
        distance, lam = surfaces.calibrated_distance(c, grad, surface.radius)
        error = np.abs(distance - offset) / H
        assert error[offset.size // 2] < 0.005
        assert error.max() < 0.04
        assert np.all(np.abs(lam - 1.0) < 0.1)  # ‖∇d‖ ≈ 1 across a flat boundary


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
def test_surface_side_velocity_is_exact_for_a_rigid_motion(shape_function):
    """The surface side's sampled velocity at a point of the other grain (friction's
    tangential velocity; the impulse acts on the surface body's nodes through the same
    weights) reproduces a rigid motion v = u + ω × (x − x0) exactly where some of the
    stencil's nodes are inactive (outside the body): the weights keep Σ w = 1 and Σ w X = x,
    so the friction impulse acts at x, with its moment. Renormalising over the active nodes
    alone samples the field at their centroid instead; measured (2026-12-02, D/h 10, 0.4 h
    outside the disk): a rotation's velocity off by up to 0.016 ω h with B-splines, and by
    0.27–0.53 ω h with linear hats where only a line of nodes is left (there the
    correction acts along the line only, and those points are left out below)."""
    step = _body_step(shape_function, DISK)
    surface = surfaces.KernelSurface(step)
    angle = np.linspace(0.0, 2.0 * np.pi, 13)[:-1]
    x = np.c_[1.013 + 0.54 * np.cos(angle), 1.0 + 0.54 * np.sin(angle)]
    rows, weights = surface.velocity_stencil(x)
    assert np.any(weights == 0.0)  # inactive nodes in the stencils
    lattice = step.stepper.lattice
    nodes = lattice.node_positions(step.box)[step.active]
    u, omega, x0 = np.array([0.3, -0.7]), 2.0, np.array([1.0, 1.0])
    V = u + omega * np.c_[-(nodes[:, 1] - x0[1]), nodes[:, 0] - x0[0]]
    sampled = np.einsum("pk,pkj->pj", weights, np.where(rows[:, :, None] >= 0, V[rows], 0.0))
    exact = u + omega * np.c_[-(x[:, 1] - x0[1]), x[:, 0] - x0[0]]
    # (linear hats: where the active nodes left lie on a line, a rotation's velocity can
    # be exact only along it; those points are left out)
    spanning = np.array([np.linalg.matrix_rank(nodes[r[r >= 0]] - nodes[r[r >= 0]][0]) == 2
                         for r in rows])
    assert spanning.sum() >= 6
    error = np.abs(sampled - exact)[spanning]
    assert np.max(error) < 1e-12 * np.max(np.abs(exact))
    assert np.allclose(weights.sum(axis=1), 1.0)


@pytest.mark.parametrize("shape_function", ["linear", "bspline2"])
@pytest.mark.parametrize("round_body", [False, True])
def test_own_side_velocity_is_the_rate_of_the_cell_edge(shape_function, round_body):
    """The own side of a point contact moves with the edge of the point's deformed cell,
    x_p + r_p (r_p: surfaces.cell_support), as the point and its cell are carried by the
    nodal velocities (ẋ_p = Σ N v, Ḟ_p = ∇v F_p): for a random nodal field and a random
    F_p, advancing x_p and F_p by ε moves the cell's material edge point by ε Σ_I w_I v_I
    and the edge along n (what the gap sees, ring cells too) by ε n·Σ_I w_I v_I, to the
    difference's error; Σ w = 1 (momentum) and Σ w X = x_p + r_p (the impulse acts at the edge: the
    lever arm of a wall's force in Σ V σ = Σ x ⊗ f: with the force at the point itself
    and walls at points, the small compaction's volume-averaged stress came out 7.9% below
    the wall's, session 13)."""
    step = _body_step(shape_function, DISK)
    rng = np.random.default_rng(4)
    points = np.arange(0, step.pts.x.shape[0], 7)
    F = np.eye(2) + 0.2 * rng.normal(size=(points.size, 2, 2))
    step.pts.F[points] = F
    n = rng.normal(size=(points.size, 2))
    n /= np.linalg.norm(n, axis=1)[:, None]
    spacing = 0.05
    r = surfaces.cell_support(F, n, spacing, round_body)
    assert np.allclose(-np.einsum("pi,pi->p", n, r),
                       0.5 * spacing * (np.linalg.norm(np.einsum("pji,pj->pi", F, n), axis=1)
                                        if round_body else
                                        np.abs(np.einsum("pji,pj->pi", F, n)).sum(axis=1)))
    rows, w = surfaces.edge_stencil(step, points, r)
    V = rng.normal(size=(step.active.size, 2))
    Vp = np.where(rows[:, :, None] >= 0, V[rows], 0.0)
    predicted = np.einsum("pk,pkj->pj", w, Vp)
    eps = 1e-7
    grad_v = np.einsum("pki,pkj->pij", Vp, step.dN[points])  # ∇v: (∂v_i/∂x_j)
    x_new = step.pts.x[points] + eps * np.einsum("pk,pkj->pj", step.N[points], Vp)
    F_new = F + eps * np.einsum("pij,pjk->pik", grad_v, F)
    # the material point of the cell's edge, F s with s fixed, moves with Σ w v ...
    r_material = np.einsum("pij,pjk,pk->pi", F_new, np.linalg.inv(F), r)
    moved = (x_new + r_material - step.pts.x[points] - r) / eps
    assert np.max(np.abs(moved - predicted)) < 1e-5 * np.max(np.abs(predicted))
    # ... and the edge along n (the gap's e = −n·r, recomputed) at the same rate
    r_new = surfaces.cell_support(F_new, n, spacing, round_body)
    along = np.einsum("pi,pi->p", n, x_new + r_new - step.pts.x[points] - r) / eps
    assert np.max(np.abs(along - np.einsum("pi,pi->p", n, predicted))) < 1e-5 * np.max(
        np.abs(predicted))
    assert np.allclose(w.sum(axis=1), 1.0)
    nodes = step.stepper.lattice.node_positions(step.box)[step.active]
    Xp = np.where(rows[:, :, None] >= 0, nodes[rows], 0.0)
    assert np.allclose(np.einsum("pk,pkj->pj", w, Xp), step.pts.x[points] + r, atol=1e-12)


def test_wall_contacts_take_every_point_within_reach_with_a_smooth_cell_extent():
    """Grain–wall point contacts (``wall_sites = "points"``): the block's lattice points
    above a kinematic slab whose face is the block's lower edge. (1) Every point within
    reach is a contact, the second row (1.5 point spacings inside the grain) too: with the
    grain pairs' outer-point threshold, compressed corner points read deeper than one
    spacing inside their grain, left the contact set and entered the walls unconstrained
    (session 15). (2) The gap's cell extent e = ½δ‖Fᵀn‖ is smooth where the cell's edge
    is parallel to the wall: a shear F = I + γ e_y⊗e_x changes the gap by ½δ(√(1 + γ²) − 1)
    (second order); the lattice square's corner support, ½δ Σ_j |(Fᵀn)_j|, changed it by
    ½δ|γ| (first order, its kink), and the edge stencil's linear rate then let the solve
    meet the constraint by shearing the point's cell (session 14)."""
    step = _body_step("linear", BLOCK)
    slab = Rectangle(lower=(0.0, 0.3), upper=(2.0, 0.5))
    spacing, reach = H / 2, H
    gaps = []
    for gamma in (0.0, 0.1):
        step.pts.F[:] = [[1.0, 0.0], [gamma, 1.0]]
        found = surfaces.wall_contacts([(0, 1)], {0: step}, {1: slab}, spacing, reach)
        gaps.append(found.gap)
    height = found.position[:, 1] - 0.5
    rows = np.unique(np.round(height / spacing, 9))
    assert rows[0] == 0.5 and rows[1] == 1.5 and np.all(found.gap < reach)
    assert np.allclose(found.gap, height - 0.5 * spacing * np.sqrt(1.0 + 0.1**2))
    assert np.abs(gaps[1] - gaps[0]).max() < 0.01 * spacing  # ½δ γ²/2 = 0.0025 δ


def _pair_steps(h: float, seeding: str, separation: float, angle: float, shift):
    """Two disks of radius 0.5 whose boundaries are ``separation`` apart along ``angle``
    (their centres shifted by ``shift`` against the grid), at rest, not yet solved."""
    radius, direction = 0.5, np.array([np.cos(angle), np.sin(angle)])
    first = np.array([1.8, 1.8]) + shift - 0.5 * (2 * radius + separation) * direction
    centres = (first, first + (2 * radius + separation) * direction)
    return _body_steps([{"name": f"disk{i}", "shape": "disk", "center": list(c),
                         "radius": radius, "seeding": seeding}
                        for i, c in enumerate(centres)], h=h, size=3.6)


def test_one_pass_takes_the_smaller_grains_points_only():
    """One pass (``grain_passes``): of two ring disks of radii 0.5 and 0.65 (D/h 10), 0.1 h
    apart or overlapping by 0.1 h, the contacts are the smaller disk's outer points
    against the larger one's surface, exactly those of the full two passes, whatever the
    pair's order; a ring-seeded body samples first against one of another seeding."""
    h = 0.1
    for separation in (0.1 * h, -0.1 * h):
        for order in ((0.5, 0.65), (0.65, 0.5)):
            first = np.array([1.6, 1.7])
            second = first + (sum(order) + separation) * np.array([0.8, 0.6])
            disks = zip((first, second), order, strict=True)
            steps = _body_steps([{"name": f"disk{i}", "shape": "disk", "center": list(c),
                                  "radius": r, "seeding": "rings"}
                                 for i, (c, r) in enumerate(disks)], h=h, size=3.6)
            small = int(np.argmin(order))
            assert surfaces.sampling_side(0, 1, steps) == (small, 1 - small)
            assert surfaces.sampling_side(0, 1, steps, frozenset({1 - small}))[0] == 1 - small
            both = surfaces.surface_contacts([(0, 1)], steps, h / 2, 2 * h)
            one = surfaces.surface_contacts([(0, 1)], steps, h / 2, 2 * h,
                                             one_pass=frozenset({(0, 1)}))
            mine = both.owner_is_alpha == (small == 0)
            assert mine.sum() > 5 and (~mine).sum() > 5
            assert np.all(one.owner_is_alpha == (small == 0))
            assert np.array_equal(one.point, both.point[mine])
            assert np.allclose(one.gap, both.gap[mine])
            assert np.allclose(one.normal, both.normal[mine])
            # what one pass leaves out: the least gap of the other disk's points, as the
            # second pass reads them
            left_out = surfaces.least_unsampled_gap(frozenset({(0, 1)}), steps, h / 2, 2 * h)
            assert left_out == pytest.approx(both.gap[~mine].min(), abs=1e-12)


def test_auto_passes_take_one_pass_on_frictional_pairs_only():
    """``grain_passes = "auto"`` (the default): one pass for a pair with friction, two for a
    frictionless one (frictionless one pass is slower and its overlaps deeper:
    docs/dev-notes.md, #11 next step 000); "one" and "two" hold for every pair."""
    from softgrains.contact.coupling import one_pass_rule

    mu = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.02], [0.0, 0.02, 0.0]])
    friction = lambda a, b: mu[a, b]  # noqa: E731
    pairs = [(0, 1), (0, 2), (1, 2)]
    assert [one_pass_rule("auto", friction)(*p) for p in pairs] == [True, False, True]
    assert all(one_pass_rule("one", friction)(*p) for p in pairs)
    assert not any(one_pass_rule("two", friction)(*p) for p in pairs)


@pytest.mark.parametrize("diameter_over_h", [10, 20])
def test_ring_seeded_disks_meet_at_their_boundaries(diameter_over_h):
    """The least gap of two ring-seeded disks' point-to-surface contacts is the distance
    between their boundaries, whatever their direction and their place on the grid: here
    0.1 h apart, 12 random directions and grid offsets. Measured (2026-12-04): the gap reads
    0.034–0.045 h too large at D/h 10 and 0.025–0.027 h at D/h 20 (the kernel surface sits
    0.017 h / 0.009 h inside a ring disk's boundary, the nearest ring point off the line of
    centres). Lattice-seeded disks (a staircase of point cells) read −0.16…+0.39 h at D/h 10
    and −0.22…+0.39 h at D/h 20: their corners make the grains rough at the cell's scale
    (the frictional main job's φ0: 0.681 at D/h 10, 0.696 at D/h 20, one sample) — why
    ``[sample] seeding`` is "rings" by default. (Round grains' φ0 under h halving, four
    seeds each: +0.7% ± 2.9% without friction, −1.9% ± 5.7% with μ = 0.5, 95% bands:
    within the samples' spread; docs/dev-notes.md.)"""
    h = 1.0 / diameter_over_h
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(12):
        steps = _pair_steps(h, "rings", 0.1 * h, rng.uniform(0.0, 2.0 * np.pi),
                            rng.uniform(0.0, h, 2))
        found = surfaces.surface_contacts([(0, 1)], steps, h / 2, 2 * h)
        for own in (True, False):  # each disk's points against the other's surface
            errors.append((found.gap[found.owner_is_alpha == own].min() - 0.1 * h) / h)
    errors = np.array(errors)
    assert np.all(np.abs(errors) < 0.05)
    assert errors.max() - errors.min() < 0.02  # smooth: no corners


def test_outer_candidates_are_the_outer_points_in_the_other_bodys_widened_box():
    """_outer_candidates (a kernel since session 53): the points of one body strictly
    inside the other's point bounds widened by the reach and its kernel radius whose own
    surface distance is above −spacing, in order: NumPy's selection."""
    h = 0.1
    steps = _body_steps([{"name": "a", "shape": "disk", "center": [1.0, 1.0], "radius": 0.5},
                         {"name": "b", "shape": "disk", "center": [1.95, 1.3],
                          "radius": 0.45}], h=h, size=3.0)
    found = surfaces._kernel_surfaces([(0, 1)], steps, None)
    for own, other in ((0, 1), (1, 0)):
        O, T = found[own], found[other]
        x, y = O.step.pts.x, T.step.pts.x
        margin = 2 * h + T.radius
        inside = np.all((x > y.min(axis=0) - margin) & (x < y.max(axis=0) + margin), axis=1)
        expected = np.flatnonzero(inside & (O.own_distance() > -h / 2))
        got = surfaces._outer_candidates(own, other, found, h / 2, 2 * h)
        assert 0 < got.size < x.shape[0]
        np.testing.assert_array_equal(got, expected)


def _gaps_by_numpy(c, grad, F, radius, spacing, round_body=True):
    """The calibrated distance, the normal, the cell support and the gap of surfaces.py's
    formulas, written with NumPy on whole arrays (the kernels' reference)."""
    xi, profile, slope = surfaces.PROFILES[grad.shape[1]]
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = np.interp(np.clip(c, profile[1], profile[-2]), profile, xi)
        length = np.linalg.norm(grad, axis=1)
        lam = radius * length / np.interp(inside, xi, slope)
        distance = np.where(c > 0.0, -radius * inside, np.inf)
        n = -grad / length[:, None]
        FTn = np.einsum("pji,pj->pi", F, np.nan_to_num(n))
        s = (FTn / np.maximum(np.linalg.norm(FTn, axis=1), 1e-300)[:, None] if round_body
             else np.sign(FTn))
        r = -0.5 * spacing * np.einsum("pij,pj->pi", F, s)
        gap = (distance + np.einsum("pi,pi->p", n, r)) / lam
    return distance, lam, length, n, r, gap


@pytest.mark.parametrize("d", [2, 3])
def test_surface_gaps_are_the_formulas_on_arrays(d):
    """surfaces.surface_gaps, calibrated_distance and cell_support (kernels over the points,
    sharing their per-point functions) give what the formulas give on arrays with NumPy,
    across the profile, beyond the kernel's reach (c = 0: +inf) and where ∇c vanishes
    (NaN): to the bit in 2D; in 3D to round-off (np.einsum sums three products in another
    order). The lattice cell's support (sign(Fᵀn)) too."""
    rng = np.random.default_rng(20 + d)
    n, radius, spacing = 400, 0.015, 0.005
    c = rng.uniform(-0.1, 1.1, n).clip(0.0, 1.0)
    c[:5] = 0.0
    grad = rng.standard_normal((n, d)) * 40.0
    grad[5:8] = 0.0
    F = np.eye(d) + 0.2 * rng.standard_normal((n, d, d))
    length, n_out, gap, support = surfaces.surface_gaps(c, grad, F, radius, spacing)
    distance, lam = surfaces.calibrated_distance(c, grad, radius)
    square = surfaces.cell_support(F, -grad, spacing, False)
    expected = _gaps_by_numpy(c, grad, F, radius, spacing)
    expected_square = _gaps_by_numpy(c, grad, F, radius, spacing, round_body=False)[4]
    tolerance = 0.0 if d == 2 else 1e-14
    for got, wanted in ((distance, expected[0]), (lam, expected[1]), (length, expected[2]),
                        (n_out, expected[3]), (support, expected[4]), (gap, expected[5]),
                        (square[8:], expected_square[8:])):
        finite = np.isfinite(wanted)
        scale = np.abs(wanted[finite]).max()
        np.testing.assert_allclose(got, wanted, rtol=tolerance, atol=tolerance * scale)
    assert np.isinf(gap[:5]).all() and np.isnan(gap[5:8]).all()
    assert np.isfinite(gap[8:]).sum() > n // 2

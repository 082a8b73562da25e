"""The coupled contact–bulk loop (ALGORITHM.md §6) on small cases (VALIDATION.md B5, B6).

Contacts act with the gap treatment of §4 unless a test says otherwise.
"""

import numpy as np
import pytest

from softgrains import Simulation, load_case


def _two_disks(enabled=True, gap=True, grain_sites="nodes"):
    """Sulsky et al. (1994): two elastic disks on the diagonal of a 1 m square, 20 x 20 cells."""
    disk = {"shape": "disk", "radius": 0.2, "material": "gel"}
    return load_case({
        "simulation": {"dt": 0.01, "end_time": 3.0, "theta": 0.5},
        "grid": {"cell_size": 0.05, "origin": [0.0, 0.0], "size": [1.0, 1.0]},
        "materials": {"gel": {"young": 1000.0, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{**disk, "center": [0.2, 0.2], "velocity": [0.1, 0.1]},
                   {**disk, "center": [0.8, 0.8], "velocity": [-0.1, -0.1]}],
        "contact": {"enabled": enabled, "gap": gap, "grain_sites": grain_sites},
    })


def _block_on_slab(h=0.1, young=1e5, dt=0.01, steps=60, gravity=(0.0, -10.0), contact=None,
                   slab_length=1.6):
    """An elastic 0.8 × 0.4 m block released 0.02 m above a kinematic slab (θ = 1)."""
    return Simulation(load_case({
        "simulation": {"dt": dt, "steps": steps, "theta": 1.0},
        "grid": {"cell_size": h, "origin": [0.0, 0.0], "size": [slab_length + 0.4, 2.0]},
        "materials": {"gel": {"young": young, "poisson": 0.3, "density": 1000.0}},
        "bodies": [
            {"name": "block", "shape": "rectangle", "lower": [0.6, 0.62],
             "upper": [1.4, 1.02], "material": "gel"},
            {"name": "slab", "shape": "rectangle", "lower": [0.2, 0.3],
             "upper": [0.2 + slab_length, 0.6], "material": "gel", "kind": "kinematic"}],
        "gravity": {"acceleration": list(gravity)},
        "contact": contact or {},
    }))


@pytest.mark.parametrize(("gap", "sites", "onset_range"),
                         [(True, "nodes", (1.4, 1.6)), (False, "nodes", (0.9, 1.05)),
                          (True, "surface", (1.5, 1.6))],
                         ids=["gap", "mass-overlap", "surface"])
def test_two_disks_collide_with_exact_momentum_and_no_energy_gain(gap, sites, onset_range):
    """VALIDATION.md B6. Measured (2026-11-23, session 3): the surfaces touch at 1.586 s; the
    impulse starts at 1.50 s with the gap treatment (1.14 s on mass overlap alone); the disks
    leave along the diagonal at 0.81 (0.93) of their speed; momentum stays within 2e-14 of zero;
    the energy never exceeds its start. Point-to-surface contacts (session 11): impulse from
    1.54 s, momentum within 3e-14 (the surface's rate vectors sum to its normal), energy never
    above its start, 0.81 of the speed. With quadratic B-splines (the default since session
    22) each body's nodes reach 1.5 h beyond its points instead of h, so the mass overlap
    starts h / |v_α − v_β| = 0.05 / 0.283 = 0.18 s earlier: 0.96 s (measured 2026-12-04)."""
    sim = Simulation(_two_disks(gap=gap, grain_sites=sites))
    m = sim.model.mass
    a = sim.model.bodies[0].points
    e0 = sim.series_row()["total_energy"]
    energies, momenta, onset = [], [], None
    for _ in range(sim.n_steps):
        diag = sim.step()
        if onset is None and diag.contact.active:
            onset = sim.state.time
        energies.append(sim.series_row()["total_energy"])
        momenta.append((m[:, None] * sim.state.v).sum(axis=0))
    assert np.abs(momenta).max() < 1e-12 * m.sum() * 0.1
    assert max(energies) <= e0 * (1 + 1e-9)
    assert onset is not None and onset_range[0] < onset < onset_range[1]
    va = sim.state.v[a].mean(axis=0)
    assert va[0] < -0.05 and va[1] < -0.05  # rebounded, back along the diagonal
    assert abs(va[0] - va[1]) < 1e-6 * abs(va[0]) + 1e-12


def test_without_contact_the_disks_pass_through_each_other():
    sim = Simulation(_two_disks(enabled=False))
    for _ in range(200):
        sim.step()
    assert np.allclose(sim.state.v[sim.model.bodies[0].points].mean(axis=0), [0.1, 0.1])


@pytest.mark.parametrize("wall_sites", ["nodes", "surface", "points"])
def test_block_resting_on_a_wall_reports_a_constant_force_mg(wall_sites):
    """An elastic block released just above a kinematic slab under gravity (θ = 1): once
    settled, the slab pushes it with m g within 1% at every step (no chatter between 2mg
    and 0). Measured: 0.994–1.003 mg over steps 50–60 (also with the opt-in point-to-face
    wall contacts, session 11)."""
    sim = _block_on_slab(contact={"wall_sites": wall_sites})
    weight = 10.0 * sim.model.mass[sim.model.bodies[0].points].sum()
    ratios = []
    for _ in range(sim.n_steps):
        diag = sim.step()
        force = diag.contact_forces(2, 2, sim.dt)
        ratios.append(force[0, 1] / weight)
        assert np.allclose(force[0] + force[1], 0.0, atol=1e-9 * weight)  # action = reaction
    assert np.abs(np.array(ratios[-10:]) - 1.0).max() < 0.01


@pytest.mark.parametrize("relation", ["delassus", "lumped"])
@pytest.mark.parametrize(("mu", "expected"), [(0.2, 3.206), (0.5, 0.657), (0.7, 0.0)])
def test_block_on_an_incline_slides_with_the_coulomb_acceleration(mu, expected, relation):
    """VALIDATION.md B7: a block (0.8 × 0.4 m, E = 1 MPa, h = 0.1) on a fixed slab, gravity
    tilted by 30°: a = g(sin θ − μ cos θ) from a quadratic fit of the centre-of-mass
    displacement after 0.15 s (the block lands at ~0.07 s); at μ = 0.7 the block sticks:
    B7's bar is the slip along the interface, < 10⁻³ h, measured on the block's bottom
    row of points after 0.15 s. Measured (2026-11-23): 3.2059 (μ = 0.2), 0.6577 (μ = 0.5),
    −0.002 m/s² (μ = 0.7: sticks), the same with either local relation (the Delassus one
    in 2 coupling iterations a step, the lumped one in 10–24 when sticking); the sticking
    block's slip 1.4e-4 h with either (2026-12-06). The exact face normal of the wall is
    what makes this right: mass-gradient normals gave 2.28 m/s² at μ = 0.2 and stuck at
    μ = 0.5."""
    g, tilt, h = 9.81, np.radians(30.0), 0.1
    sim = _block_on_slab(h=h, young=1e6, dt=0.005, steps=80, slab_length=3.6,
                         gravity=(g * np.sin(tilt), -g * np.cos(tilt)),
                         contact={"friction": mu, "local_relation": relation})
    block = sim.model.bodies[0].points
    m = sim.model.mass[block]
    y0 = sim.state.x[block, 1]
    bottom = block.start + np.flatnonzero(y0 < y0.min() + 1e-9 * h)  # the row on the slab
    t, x, x_bottom = [], [], []
    for _ in range(sim.n_steps):
        sim.step()
        t.append(sim.state.time)
        x.append(np.sum(m * sim.state.x[block, 0]) / m.sum())
        x_bottom.append(sim.state.x[bottom, 0].mean())
    t, x = np.array(t), np.array(x)
    late = t > 0.15
    a = 2.0 * np.polyfit(t[late], x[late], 2)[0]
    if expected > 0:
        assert a == pytest.approx(expected, rel=0.03)
    else:
        assert abs(a) < 0.01 * g
        slip = np.array(x_bottom)[late] - x_bottom[int(np.argmax(late))]
        assert np.abs(slip).max() < 1e-3 * h  # B7: the sticking block's slip


@pytest.mark.parametrize("gap, wall_sites", [(True, "nodes"), (False, "nodes"),
                                             (True, "surface"), (True, "points")],
                         ids=["gap", "mass-overlap", "surface", "points"])
def test_resting_block_boundary_gap(gap, wall_sites):
    """ALGORITHM.md §4: a block released 0.4 h above a slab (h = 0.05) comes to rest with its
    boundary (lowest points − δ/2) within 0.05 h of the slab with the gap treatment; on mass
    overlap alone it stops about half a cell above. Measured (2026-11-23): −0.010 h with the
    gap, +0.45 h without."""
    h = 0.05
    sim = _block_on_slab(h=h, contact={"gap": gap, "wall_sites": wall_sites})
    for _ in range(sim.n_steps):
        sim.step()
    bottom = sim.state.x[sim.model.bodies[0].points, 1].min() - 0.25 * h
    residual = (bottom - 0.6) / h
    if gap:
        assert abs(residual) < 0.05
    else:
        assert residual > 0.3


class _Body:
    """A body step stand-in whose compliance at its contact rows is ``exact`` with the
    exact tangent and the identity with the projected one."""

    def __init__(self, exact):
        self.exact, self.projected = np.asarray(exact, float), False

    def contact_response(self, rows, delassus, sites=None):
        return None, np.eye(2) if self.projected else self.exact

    def rigid_modes(self, rows, sites=None):
        return np.zeros((self.exact.shape[0] // 2, 2, 3))  # held: no rigid mode

    def use_projected_tangent(self):
        switched, self.projected = not self.projected, True
        return switched

    def mirror_negative_modes(self):
        return False  # as for a body above MIRROR_LIMIT unknowns


def test_a_body_with_an_indefinite_compliance_switches_to_the_projected_tangent():
    """tangent = "auto": a body whose W at its contact rows has a negative eigenvalue (an
    exact tangent under compression; the contact problem is not monotone there and its
    solves stalled at 450-690 iterations in a dense compaction) is flagged, and when the
    solve stalls it takes the mirrored negative modes, or the projected tangent where the
    mirror does not apply (its W redone); a semidefinite W, singular ones included
    (redundant sites), keeps the exact tangent. With tangent = "exact" the indefinite W
    stays."""
    from types import SimpleNamespace

    from softgrains.contact.coupling import (
        _semidefinite,
        _switch_indefinite,
        _update_compliances,
    )

    indefinite, singular = _Body([[1.0, 2.0], [2.0, 1.0]]), _Body([[1.0, 1.0], [1.0, 1.0]])
    steps = {3: indefinite, 5: singular}
    slots = SimpleNamespace(bodies=[3, 5], W=[None, None], response=[None, None],
                            rigid=[None, None], rows=[None, None], semidefinite=[False, False],
                            impulse_basis=[None, None], H=[None, None],
                            compliance=lambda slot, W: W)
    fresh = {3, 5}
    assert not _update_compliances(steps, slots, fresh, delassus=True)
    assert slots.semidefinite == [False, True]
    assert _switch_indefinite(steps, slots) == [3]
    assert indefinite.projected and not singular.projected and slots.W[0] is None
    assert _update_compliances(steps, slots, set(), delassus=True)  # every W_s now PSD
    np.testing.assert_array_equal(slots.W[0], np.eye(2))
    np.testing.assert_array_equal(slots.W[1], singular.exact)
    stuck = _Body([[1.0, 2.0], [2.0, 1.0]])
    stuck.use_projected_tangent = lambda: False  # tangent = "exact"
    slots.W, slots.semidefinite = [None, None], [False, False]
    assert not _update_compliances({3: stuck, 5: singular}, slots, fresh, delassus=True)
    assert _switch_indefinite({3: stuck, 5: singular}, slots) == []
    assert not stuck.projected
    # a body the mirror applies to takes it first (after a failed solve), not the projection
    mirrored = _Body([[1.0, 2.0], [2.0, 1.0]])
    mirrored.mirror_negative_modes = lambda: True
    slots.W, slots.semidefinite = [None, None], [False, False]
    assert not _update_compliances({3: mirrored, 5: singular}, slots, fresh, delassus=True)
    assert _switch_indefinite({3: mirrored, 5: singular}, slots) == [3]
    assert not mirrored.projected and slots.W[0] is None
    # round-off below a PSD matrix's zero eigenvalue is not indefiniteness
    rotation = np.array([[0.6, 0.8], [-0.8, 0.6]])
    assert _semidefinite(rotation @ np.diag([1.0, -1e-13]) @ rotation.T)
    assert not _semidefinite(rotation @ np.diag([1.0, -1e-6]) @ rotation.T)


def test_a_frictionless_contact_s_tangential_compliance_is_no_part_of_the_check():
    """The definiteness check sees W_s on the impulses the body's contacts can carry
    (coupling._impulse_basis): every component at a column with a frictional contact, the
    normal alone at a frictionless one. A W_s negative only along a frictionless contact's
    tangent is semidefinite there; the same W_s with friction on that contact is not."""
    from types import SimpleNamespace

    from softgrains.contact.coupling import _impulse_basis, _semidefinite

    def touching(slots):  # the body's contacts as first body, as second
        return np.flatnonzero(slots.a_slot == 0), np.flatnonzero(slots.b_slot == 0)

    slots = SimpleNamespace(d=2, k_size=np.array([2]), a_slot=np.array([0, -1]),
                            a_col=np.array([0, 0]), b_slot=np.array([-1, 0]),
                            b_col=np.array([0, 1]))
    normal = np.array([[1.0, 0.0], [0.6, 0.8]])
    tangent = np.array([0.0, 0.0, -0.8, 0.6])  # column 1's tangent
    W = np.eye(4) - 2.0 * np.outer(tangent, tangent)
    basis = _impulse_basis(slots, 0, touching(slots), normal, np.array([0.5, 0.0]))
    np.testing.assert_array_equal(basis, [[1, 0, 0], [0, 1, 0], [0, 0, 0.6], [0, 0, 0.8]])
    assert _semidefinite(W, basis) and not _semidefinite(W)
    assert _impulse_basis(slots, 0, touching(slots), normal,
                          np.array([0.5, 0.5])) is None
    # column 1 shared by two contacts: both frictionless, their two normals; one of them
    # frictional, every component
    shared = SimpleNamespace(d=2, k_size=np.array([2]), a_slot=np.array([0, -1, 0]),
                             a_col=np.array([0, 0, 1]), b_slot=np.array([-1, 0, -1]),
                             b_col=np.array([0, 1, 0]))
    normals = np.array([[1.0, 0.0], [0.6, 0.8], [0.0, 1.0]])
    basis = _impulse_basis(shared, 0, touching(shared), normals,
                           np.array([0.5, 0.0, 0.0]))
    np.testing.assert_array_equal(basis, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0.6],
                                          [0, 0, 1, 0.8]])
    assert _impulse_basis(shared, 0, touching(shared), normals,
                          np.array([0.5, 0.0, 0.5])) is None


def test_the_mirrored_matrix_of_the_iterate_is_made_once(monkeypatch):
    """BodyStep.mirror_negative_modes tests the Newton matrix for a negative mode with an
    eigensolve; the next direction at the same iterate takes that A⁺ instead of making it
    again (2–3 ms a body: 52 → 36 eigensolves in 8 dense compaction steps); after a step
    of the iterate A⁺ is made anew. The direction is the same either way. (The consistent
    form's: the momentum form's loaded grains have no negative mode to mirror.)"""
    import softgrains.integrator.implicit as implicit

    def step_of_a_disk():
        sim = Simulation(load_case({
            "simulation": {"dt": 1e-3, "steps": 1, "stress_form": "consistent"},
            "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
            "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
            "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0],
                        "radius": 0.5, "material": "gel", "velocity": [0.3, -0.2]}],
            "output": {"progress": False},
        }))
        return implicit.BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                                 np.array([0.0, -10.0]), 1e-3, 0)

    calls = []

    def shifted(A, m):  # as if A had a negative mode: A + a multiple of M
        calls.append(1)
        return implicit.dense(A) + 1e-3 * np.diag(m)

    monkeypatch.setattr(implicit, "mirrored_negative_modes", shifted)
    step = step_of_a_disk()
    assert step.mirror_negative_modes() and len(calls) == 1
    du = step.newton_direction(direct=True)
    assert len(calls) == 1  # A⁺ of this iterate reused
    step.take_step(du)
    step.newton_direction(direct=True)
    assert len(calls) == 2  # a new iterate: a new A⁺
    fresh = step_of_a_disk()
    fresh._mirrored = True  # mirrored without the kept A⁺: made for the direction
    np.testing.assert_array_equal(fresh.newton_direction(direct=True), du)
    assert len(calls) == 3


def _disk_step():
    """The first step of one free disk (D/h 10, no contact), its Newton not started."""
    from softgrains.integrator.implicit import BodyStep

    sim = Simulation(load_case({
        "simulation": {"dt": 1e-3, "steps": 1},
        "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
        "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0], "radius": 0.5,
                    "material": "gel"}],
        "output": {"progress": False},
    }))
    return BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                    np.zeros(2), 1e-3, 0)


def test_the_compliance_at_sites_is_the_rows_compliance_mapped():
    """BodyStep.contact_response with a site map H (sites d × rows d): W_sites = H W_rows Hᵀ
    and X_sites = X_rows Hᵀ (the impulse response at the sites), to round-off, where the
    sites' columns are solved for directly (fewer than the rows' in a dense packing)."""
    import scipy.sparse as sp

    step = _disk_step()
    rng = np.random.default_rng(7)
    rows = np.sort(rng.choice(step.u.shape[0], 12, replace=False))
    H = sp.csr_matrix(rng.standard_normal((10, 24)) * (rng.random((10, 24)) < 0.3))
    response_rows, W_rows = step.contact_response(rows, True)
    response_sites, W_sites = step.contact_response(rows, True, H)
    X_rows, X_sites = response_rows.matrix(), response_sites.matrix()
    scale = np.abs(W_rows).max()
    np.testing.assert_allclose(W_sites, H @ (H @ W_rows.T).T, atol=1e-12 * scale)
    np.testing.assert_allclose(X_sites, (H @ X_rows.T).T, atol=1e-12 * np.abs(X_rows).max())
    q = rng.standard_normal(X_sites.shape[1])
    np.testing.assert_allclose(response_sites.move(q), X_sites @ q,
                               atol=1e-12 * np.abs(X_sites @ q).max())


@pytest.mark.parametrize("form", ["consistent", "momentum"])
def test_the_rigid_modes_carry_a_free_disks_compliance_at_a_quasi_static_step(form):
    """BodyStep.rigid_modes G: a free disk's translations, and with the momentum form its
    rigid rotation, are modes of inertia alone, so their share G Gᵀ of its compliance W is
    a rigid body's: I/m + r⊥ r⊥ᵀ/I (m and I the active nodes' mass and inertia about their
    mass centre; the consistent form's rotation is left in W). What is left, W − G Gᵀ, is
    the deformation's: positive semidefinite, and at Δt c/h ~2400 a small part of W. At
    sites H the modes are H G. A held disk has no rigid mode (G = 0)."""
    from softgrains.integrator.implicit import BodyStep
    from softgrains.integrator.rotations import mass_centred

    case = {
        "simulation": {"dt": 20.0, "steps": 1, "stress_form": form},  # Δt c/h ≈ 2400
        "grid": {"cell_size": 0.1, "origin": [0.0, 0.0], "size": [2.0, 2.0]},
        "materials": {"gel": {"law": "neo-hookean", "young": 1e5, "poisson": 0.3,
                              "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [1.0, 1.0], "radius": 0.5,
                    "material": "gel"}],
        "output": {"progress": False},
    }
    sim = Simulation(load_case(case))
    step = BodyStep(sim.solver.steppers[0], sim.solver.body_points(sim.state, 0),
                    np.zeros(2), 20.0, 0)
    assert step.momentum_form == (form == "momentum")
    rows = np.arange(0, step.u.shape[0], 7)
    _, W = step.contact_response(rows, True)
    G = step.rigid_modes(rows).reshape(rows.size * 2, -1)
    m = step.m[:, 0]
    expected = np.kron(np.ones((rows.size, rows.size)), np.eye(2)) / m.sum()
    if form == "momentum":
        r = mass_centred(step.stepper.lattice.node_positions(step.box)[step.active], m)
        inertia = float(np.sum(m * np.einsum("ij,ij->i", r, r)))
        perp = np.stack([-r[rows, 1], r[rows, 0]], axis=1).ravel()
        expected += np.outer(perp, perp) / inertia
    np.testing.assert_allclose(G @ G.T, expected, rtol=1e-10, atol=1e-12 * expected.max())
    deformation = np.linalg.eigvalsh(W - G @ G.T)
    assert deformation.min() > -1e-9 * np.abs(W).max()
    if form == "momentum":  # the deformation's share is small: measured 6e-3 of W's trace
        assert np.trace(W - G @ G.T) < 1e-2 * np.trace(W)
    # at sites v_s = H v_rows (a patch of points whose blocks are not the identity) the
    # modes are the rows' mapped: H G, for the translations as for the rotation
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    H = sp.csr_matrix(rng.random((6, rows.size * 2)) * (rng.random((6, rows.size * 2)) < 0.4))
    np.testing.assert_allclose(step.rigid_modes(rows, H).reshape(6, -1), H @ G,
                               atol=1e-14 * np.abs(G).max())
    held = _disk_step()
    held.fixed[0] = True
    assert not held.rigid_modes(np.arange(5)).any()


@pytest.mark.parametrize("band", [False, True])
def test_the_compliance_by_cholesky_is_the_one_by_lu(band, monkeypatch):
    """Where the Newton matrix A is positive definite it is factorised by Cholesky (of A
    dense, or of Ā's band with a rank-2k update: integrator/banded.py, the default for a
    grain) and the compliance formed as W = κ w (L⁻¹G)ᵀ(L⁻¹G) (less the update's term),
    X applied by solves: the same W and X q as the LU's W = κ w Gᵀ A⁻¹ G, X = w A⁻¹ G (to
    round-off), W symmetric to the bit and positive semidefinite; fixed dofs take no
    impulse."""
    import scipy.sparse as sp

    import softgrains.integrator.implicit as implicit
    from softgrains.integrator import linear_solvers
    from softgrains.integrator.banded import BandedDecoupled
    from softgrains.integrator.rotations import decoupled_dense

    if not band:
        monkeypatch.setattr(implicit, "band_pays", lambda *args: False)
    step = _disk_step()
    step.fixed[3] = True  # a fixed (Dirichlet) row among the contact rows
    rng = np.random.default_rng(11)
    rows = np.sort(np.r_[3, rng.choice(np.arange(4, step.u.shape[0]), 11, replace=False)])
    H = sp.csr_matrix(rng.standard_normal((10, 24)) * (rng.random((10, 24)) < 0.3))
    cholesky, W = step.contact_response(rows, True, H)
    assert cholesky.positive_definite and cholesky.formed is None
    assert isinstance(cholesky.factorization,
                      BandedDecoupled if band else linear_solvers.DenseCholesky)
    np.testing.assert_array_equal(W, W.T)
    assert np.linalg.eigvalsh(W).min() >= -1e-12 * np.abs(W).max()
    # the same A (its decoupled symmetric form, rotations.py) by LU
    step._lu = linear_solvers.DenseLU(decoupled_dense(step._exact, step._rigid_rotations(),
                                                      step._rotation_block))
    lu, W_lu = step.contact_response(rows, True, H)
    assert lu.formed is not None
    np.testing.assert_allclose(W, W_lu, atol=1e-12 * np.abs(W_lu).max())
    q = rng.standard_normal(W.shape[0])
    np.testing.assert_allclose(cholesky.move(q), lu.move(q),
                               atol=1e-12 * np.abs(lu.move(q)).max())
    fixed_dofs = step.fixed.ravel()
    assert fixed_dofs.any() and not cholesky.move(q)[fixed_dofs].any()


def _thrown_disk(max_step_motion: float, speed: float = 15.0, gravity: float = 0.0,
                 grid: dict | None = None, contact: dict | None = None) -> Simulation:
    """A stiff disk (c = 100 m/s) thrown at ``speed`` (15 m/s: 3 cells a step) towards a
    kinematic slab 2 cells away, gravity along x: its contact is found at a step's start
    only within about a cell."""
    return Simulation(load_case({
        "simulation": {"dt": 0.01, "steps": 6, "theta": 1.0,
                       "max_step_motion": max_step_motion},
        "grid": {"cell_size": 0.05, "origin": [0.0, 0.0], "size": [1.0, 1.0], **(grid or {})},
        "contact": contact or {},
        "materials": {"gel": {"young": 1e7, "poisson": 0.3, "density": 1000.0}},
        "bodies": [{"name": "disk", "shape": "disk", "center": [0.4, 0.5], "radius": 0.2,
                    "material": "gel", "velocity": [speed, 0.0]},
                   {"name": "slab", "shape": "rectangle", "lower": [0.7, 0.1],
                    "upper": [0.9, 0.9], "material": "gel", "kind": "kinematic"}],
        "gravity": {"acceleration": [gravity, 0.0]}}))


def test_a_step_that_would_cross_a_contact_unseen_is_shortened():
    """The step-size controller's motion limit (session 20): a grain whose velocity would
    carry a point farther than max_step_motion h in a step gets a Δt halved as often as that
    takes. Measured: with the default (1 h), Δt/4, the disk's front points stop 0.04 h before
    the slab's face and it rebounds at −3.0 m/s; without the limit (10 h), on linear hats with
    nodal wall contacts (the defaults until session 22), the first step carries them 0.75 h
    into the slab, unseen by the contact found at the step's start. (With B-splines and the
    wall's contacts at the points, whose reach is longer, this throw is caught without the
    limit: the front stops 0.23 h short of the face, 2026-12-04; faster grains are not.)"""
    face, h = 0.7, 0.05
    fronts = {}
    for limit in (1.0, 10.0):
        legacy = limit > 1.0
        sim = _thrown_disk(limit, grid={"shape_function": "linear"} if legacy else None,
                           contact={"wall_sites": "nodes"} if legacy else None)
        disk = sim.model.bodies[0].points
        front = []
        for _ in range(sim.n_steps):
            sim.step()
            front.append(sim.state.x[disk, 0].max())
        fronts[limit] = (max(front), sim.smallest_dt_factor)
    front, smallest = fronts[1.0]
    assert front < face and smallest == 0.25
    front, smallest = fronts[10.0]
    assert front > face + 0.5 * h and smallest == 1.0


def test_a_step_that_moved_a_point_too_far_is_retried_shorter_at_once():
    """A disk released from rest, gravity 1250 m/s² away from the slab: its first step
    moves it g Δt² = 2.5 cells (θ = 1), which its velocity did not foretell. The step is
    undone and redone with Δt/4 at once (⌈log₂ 2.5⌉ = 2 halvings in one retry)."""
    sim = _thrown_disk(1.0, speed=0.0, gravity=-1250.0)
    x0 = sim.state.x.copy()
    sim.step()
    assert sim.retried_steps == 1 and sim.dt_factor == 0.25
    moved = np.linalg.norm(sim.state.x - x0, axis=1).max() / 0.05
    assert 0.1 < moved < 1.0  # g (Δt/4)² = 2.5/16 of a cell


def test_the_coupling_loop_gives_up_on_a_cycle_but_not_on_slow_progress():
    """Progress (coupling.py): a loop whose measure repeats a cycle (session 21's dense
    frictional step: contacts switching stick/slip in turn, period 3, the loop ran to its
    200 iterations) stalls STALL_ITERATIONS iterations after its last 10% improvement; one
    that converges linearly, however slowly within reason, by bounded oscillations whose
    envelope falls, or comes steadily back down from an excursion (the quasi-static
    squeeze's step 11: 7.8 up to 66 in 30 iterations, then −15% an iteration), does not."""
    from softgrains.contact.coupling import STALL_ITERATIONS, Progress

    cycle = Progress()
    measures = [500.0, 80.0, 30.0] + [192.0, 220.0, 680.0] * 100
    stalled_at = next(k for k, m in enumerate(measures) if cycle.stalled(m))
    assert stalled_at == 2 + STALL_ITERATIONS

    for rate in (0.5, 0.9, 0.99):
        linear = Progress()
        assert not any(linear.stalled(1e3 * rate ** k) for k in range(200))
    zigzag = Progress()  # a period-2 oscillation over a falling envelope
    assert not any(zigzag.stalled(1e3 * 0.97 ** k * (4.0 if k % 2 else 1.0))
                   for k in range(200))
    excursion = Progress()
    measures = [7.8 * 1.075 ** k for k in range(30)] + [66.0 * 0.85 ** k for k in range(30)]
    assert not any(excursion.stalled(m) for m in measures)
    restarted = Progress()
    for m in [1.0] + [5.0] * (STALL_ITERATIONS - 1):
        assert not restarted.stalled(m)
    restarted.restart()  # a new tangent: the best is forgotten
    assert not restarted.stalled(5.0)


def test_the_coupling_loop_gives_up_at_once_on_an_iterate_that_repeats():
    """Progress (coupling.py): residuals (the contacts' and each body's over their
    tolerances) that repeat unchanged STUCK_REPEATS times mean an iteration at a fixed
    point that is no solution (session 27: a contact solve stopped at 1.09 × the loop's
    tolerance with every fallback spent and the bodies converged, the same iterate 42
    times before the 40-iteration stall test gave up); residuals that still move, however
    little beyond round-off, do not stall it, nor repeats interrupted by a restart."""
    from softgrains.contact.coupling import STUCK_REPEATS, Progress

    stuck = Progress()
    residuals = [[40.0, 3.0], [5.0, 2.0]] + [[1.09, 0.2]] * 10
    stalled_at = next(k for k, r in enumerate(residuals) if stuck.stalled(max(r), r))
    assert stalled_at == 2 + STUCK_REPEATS - 1 and stuck.stuck
    moving = Progress()  # the contacts' residual the same, a body's still converging
    assert not any(moving.stalled(1.09, [1.09, 0.2 * 0.999 ** k]) for k in range(30))
    restarted = Progress()
    for r in [[1.09, 0.2]] * (STUCK_REPEATS - 1):
        assert not restarted.stalled(max(r), r)
    restarted.restart()  # corrected gaps, a new tangent: the repeats are forgotten
    assert not restarted.stalled(1.09, [1.09, 0.2])


def test_the_coupling_loop_gives_up_on_contact_solves_that_keep_failing():
    """Progress (coupling.py): FAILED_SOLVES_IN_A_ROW contact solves in a row that fail
    (every fallback spent) with neither their residuals nor the loop's measure 10% below
    the first one's stall the loop (session 28: a dense frictional step whose solves
    stopped at 1.6-2.0e-4 against 1e-4 twelve times, 5.9 s, while its measure bounced),
    over a sliding window (a large first failure does not hide the later ones); failed
    solves that still gain, a measure that still falls, a success between them, or a
    restart do not."""
    from softgrains.contact.coupling import FAILED_SOLVES_IN_A_ROW, Progress

    def first_stall(progress, measures, solves):
        return next((k for k, (m, r) in enumerate(zip(measures, solves, strict=True))
                     if progress.stalled(m, None, r)), None)

    assert FAILED_SOLVES_IN_A_ROW == 3
    traced = Progress()  # the traced step: the measure fell once, then bounced
    measures = [171.0, 8.0, 4.3, 2.4, 2.9, 2.6, 2.6]
    solves = [None, None, 1.7e-4, 1.6e-4, 2.0e-4, 1.9e-4, 1.9e-4]
    assert first_stall(traced, measures, solves) == 5 and traced.unsolved
    large_first = Progress()  # the first failure the largest: the window moves past it
    assert first_stall(large_first, [2.0] * 6, [2.0e-4, 1.6e-4, 1.7e-4, 1.65e-4, 1.7e-4,
                                                1.8e-4]) == 3
    gaining = Progress()  # each failed solve 15% below the one before
    assert first_stall(gaining, [2.0] * 10, [1e-3 * 0.85 ** k for k in range(10)]) is None
    converging = Progress()  # the solves stuck, the bodies (the measure) still converging
    assert first_stall(converging, [50.0 * 0.8 ** k for k in range(10)], [1.7e-4] * 10) is None
    interrupted = Progress()  # a converged solve between the failed ones
    assert first_stall(interrupted, [2.0] * 12,
                       [None if k % 3 == 2 else 1.7e-4 for k in range(12)]) is None
    restarted = Progress()
    for _ in range(FAILED_SOLVES_IN_A_ROW - 1):
        assert not restarted.stalled(2.0, None, 1.7e-4)
    restarted.restart()  # a new tangent: the failures are forgotten
    assert not restarted.stalled(2.0, None, 1.7e-4)


def _kicked_disk(adaptive: bool) -> tuple[Simulation, np.ndarray, float]:
    """``_thrown_disk`` at rest, its front point 0.9 h from the slab's face (the edge of
    its cell, h/4 ahead, 0.65 h), for one step (its points then move 0: the next step's
    contacts are searched only 0.5 h out), then kicked to 0.95 h a step towards the slab:
    the front's cell reaches the face within the step."""
    sim = _thrown_disk(1.0, speed=0.0, contact={"adaptive_reach": adaptive})
    disk = np.arange(sim.model.n_points)[sim.model.bodies[0].points]
    h, face = 0.05, 0.7
    sim.state.x[disk, 0] += face - 0.9 * h - sim.state.x[disk, 0].max()
    sim.step()
    sim.state.v[disk] = [0.95 * h / 0.01, 0.0]
    return sim, disk, face


def test_a_step_whose_points_outran_its_contact_search_is_redone_with_the_full_reach(
        monkeypatch):
    """contact.adaptive_reach (session 26): a step's point contacts are searched only to a
    gap of 2 × the relative motion the last step predicts (at least 0.5 h), not the
    kernel's full reach (~2.1 h): a dense compaction step then carries 1400 contacts
    instead of 2640, 480 of them loaded either way. A step whose points moved farther
    than its search allowed is redone with the full reach, and is then the step a full
    reach gives (measured: the front point stops 0.247 h before the face, its cell's edge
    at the face); without that check the kicked disk's front point ends 0.05 h inside the
    slab, found by no contact."""
    results = {}
    for adaptive in (True, False):
        sim, disk, face = _kicked_disk(adaptive)
        sim.step()
        results[adaptive] = (sim.state.x.copy(), sim.reach_retries)
    (x_adaptive, redone), (x_full, never) = results[True], results[False]
    assert redone == 1 and never == 0
    assert np.array_equal(x_adaptive, x_full)
    h = 0.05
    assert x_adaptive[disk, 0].max() < face - 0.2 * h  # its cell's edge stops at the face
    monkeypatch.setattr(Simulation, "_check_reach", lambda *args: None)
    sim, disk, face = _kicked_disk(True)
    sim.step()
    assert sim.reach_retries == 0 and sim.state.x[disk, 0].max() > face - 0.1 * h


def _landing_block(monkeypatch, working_set_gap: float) -> tuple[Simulation, int]:
    """``_block_on_slab`` (0.2 h above the slab) for 25 steps with the working set's gap
    ``working_set_gap`` (contact/coupling.py); the final state and the working set's
    growths."""
    import softgrains.contact.coupling as coupling

    monkeypatch.setattr(coupling, "WORKING_SET_GAP", working_set_gap)
    sim = _block_on_slab(steps=25)
    growths = 0
    for _ in range(sim.n_steps):
        sim.step()
        growths += sim.last_diagnostics.contact.working_set_growths
    return sim, growths


def test_contacts_left_out_of_the_working_set_join_it_when_they_close(monkeypatch):
    """The working set (session 29): a step's contact problem is posed on the contacts that
    carried an impulse and those the first Newton directions bring within WORKING_SET_GAP
    h of closing; a contact left out that closes joins it and the loop goes on. With the
    gap −1 (no contact is predicted to close that far: each step starts from the contacts
    loaded at the last and the one closest to closing), the landing block's other contacts
    join as they close, and the block lands as with every contact in the problem (gap inf):
    positions within 1e-5 h (measured 8.9e-7 h: the loop's tolerance, 1e-4 of the
    impulses, with 11 loaded contacts at the end instead of 16 of the same statically
    indeterminate support). Without the growth the contacts left out would let the block
    into the slab."""
    h = 0.1
    tight, grown = _landing_block(monkeypatch, -1.0)
    full, never = _landing_block(monkeypatch, np.inf)
    assert grown > 0 and never == 0
    assert np.abs(tight.state.x - full.state.x).max() < 1e-5 * h
    block = tight.model.bodies[0].points
    assert tight.state.x[block, 1].min() > 0.6 - 0.05 * h  # on the slab's face, not in it
    last = tight.last_diagnostics.contact
    assert last.working_set < last.n_contacts  # the problem did not hold every contact


def test_a_solve_that_fails_on_the_working_set_is_redone_on_every_contact(monkeypatch):
    """Session 29: a contact solve that fails on the working set (seen twice in 60 dense
    compaction steps: a Tresca fixed point stalled at 6-8e-4 where the problem on every
    contact converged) is redone on every contact, and the step goes on with them. Here
    every solve on fewer than all of a step's contacts is made to fail (the resting
    block's working set holds half of them): the steps redo their solves on every contact
    and end converged, none retried, as a run on every contact (positions within 1e-5 h).
    Without the redo the failed solves would stall the loop and the steps be retried."""
    from dataclasses import replace

    import softgrains.contact.coupling as coupling

    default_gap = coupling.WORKING_SET_GAP
    full, _ = _landing_block(monkeypatch, np.inf)
    real_solve, real_slots = coupling.solve, coupling._working_slots
    seen = {"contacts": 0, "failed": 0, "redone": 0}

    def working_slots(everywhere, normal, member, mu):
        seen["contacts"] = member.size  # the step's contacts
        return real_slots(everywhere, normal, member, mu)

    def failing_on_fewer(problem, P0=None, options=None):
        result = real_solve(problem, P0, options)
        if problem.n_contacts < seen["contacts"]:
            seen["failed"] += 1
            return replace(result, residual=1.0, converged=False)
        seen["redone"] += seen["failed"] > 0
        return result

    monkeypatch.setattr(coupling, "_working_slots", working_slots)
    monkeypatch.setattr(coupling, "solve", failing_on_fewer)
    sim, _ = _landing_block(monkeypatch, default_gap)
    contact = sim.last_diagnostics.contact
    assert seen["failed"] > 0 and seen["redone"] > 0
    assert contact.converged and contact.working_set == contact.n_contacts
    assert sim.unconverged_contact_steps == 0 and sim.retried_steps == 0
    assert np.abs(sim.state.x - full.state.x).max() < 1e-5 * 0.1


def test_fallbacks_that_gained_nothing_are_skipped_until_the_iteration_changes(monkeypatch):
    """Session 37 (coupling.FUTILE_FALLBACK_GAIN): a failed solve whose fallbacks lowered
    the stalled Newton's residual by less than 10% makes the loop's next solves skip them
    until the iteration changes (seed 3's frictional step 270 spent 8 solves of ~0.35 s
    each on fallbacks that never moved the residual; the step converged only at Δt/2).
    Here the landing block's first solve warm-started with impulses is made to report such
    a failure (and return half its impulses, so that the loop goes on): the next solves of
    that step are asked without fallbacks, every other solve with them, and the block
    lands as without the fault (positions within 1e-5 h). (Without the end-gap check,
    whose re-solves change the iteration and so restore the fallbacks.)"""
    from dataclasses import replace

    import softgrains.contact.coupling as coupling

    monkeypatch.setattr(coupling, "WORKING_SET_GAP", np.inf)
    real_solve = coupling.solve
    seen = {"step": 0, "faulted": None, "asked": []}  # asked: (step, fallbacks) per solve

    def futile_once(problem, P0=None, options=None):
        seen["asked"].append((seen["step"], options.fallbacks))
        result = real_solve(problem, P0, options)
        if seen["faulted"] is None and np.any(P0):
            seen["faulted"] = len(seen["asked"])  # the solves up to this one
            return replace(result, impulse=0.5 * result.impulse, residual=1.0,
                           converged=False, fallback_gain=1.0)
        return result

    def landed(solve):
        monkeypatch.setattr(coupling, "solve", solve)
        sim = _block_on_slab(steps=25, contact={"end_gap_check": False})
        for step in range(sim.n_steps):
            seen["step"] = step
            sim.step()
        return sim

    full = landed(real_solve)
    seen["asked"] = []
    sim = landed(futile_once)
    at = seen["faulted"]
    assert at is not None
    k = seen["asked"][at - 1][0]  # the faulted solve's step
    later = [fallbacks for step, fallbacks in seen["asked"][at:] if step == k]
    assert later and not any(later)
    assert all(fallbacks for step, fallbacks in seen["asked"][:at])
    assert all(fallbacks for step, fallbacks in seen["asked"][at:] if step != k)
    assert sim.unconverged_contact_steps == 0
    assert np.abs(sim.state.x - full.state.x).max() < 1e-5 * 0.1


def test_the_largest_step_within_the_motion_limit():
    """α = max{α ∈ [0, 1] : |a_p + α b_p| ≤ L for every p}: the root of a quadratic per row,
    the least over the rows that would leave; 1 where none does."""
    from softgrains.contact.coupling import largest_step_within

    L = 2.0
    assert largest_step_within(np.zeros((1, 2)), np.array([[4.0, 0.0]]), L) == 0.5
    # a row moving back inwards does not bind; a sideways one: 1.2² + (α 2)² = 2²
    a = np.array([[1.0, 0.0], [1.2, 0.0]])
    b = np.array([[-2.0, 0.0], [0.0, 2.0]])
    assert largest_step_within(a, b, L) == pytest.approx(0.8)
    assert largest_step_within(a[:1], b[:1], L) == 1.0
    assert largest_step_within(np.array([[2.0, 0.0]]), np.array([[1.0, 0.0]]), L) == 0.0


def _interpolated(step, u):
    """The points' displacements Σ_k N_k(x_p) u_{I_k} over each point's stencil, in
    stencil order (the reference of coupling._points_motion)."""
    u_box = np.zeros((step.box.size, u.shape[1]))
    u_box[step.active] = u
    out = np.zeros((step.nodes.shape[0], u.shape[1]))
    for k in range(step.nodes.shape[1]):
        out += step.N[:, k, None] * u_box[step.nodes[:, k]]
    return out


def test_a_uniform_nodal_displacement_moves_every_point_by_it():
    """coupling._points_motion interpolates the nodal displacements to the points: a
    uniform one moves every point by it (Σ_I N_I = 1 at every point)."""
    from softgrains.contact.coupling import _points_motion

    step = _disk_step()
    c = np.array([0.03, -0.02])
    u = np.tile(c, (step.u.shape[0], 1))
    most_a, alpha, most_reach = _points_motion(step.nodes, step.N, step.active_row, u,
                                               np.zeros_like(u), 1.0)
    assert abs(np.sqrt(most_a) - np.linalg.norm(c)) <= 1e-14
    assert most_reach == most_a and alpha == 1.0
    np.testing.assert_allclose(_interpolated(step, u), np.tile(c, (step.pts.x.shape[0], 1)),
                               atol=1e-14)


def test_the_points_motion_kernel_is_the_interpolated_displacements_bound():
    """coupling._points_motion (one pass over the points) gives what the interpolated
    displacements and largest_step_within give on random nodal fields: max |a_p|², the
    largest α and max |a_p + b_p|², to the bit."""
    from softgrains.contact.coupling import _points_motion, largest_step_within

    step = _disk_step()
    rng = np.random.default_rng(11)
    alphas = []
    for scale in (0.01, 0.05, 0.2):
        u = scale * rng.standard_normal(step.u.shape)
        du = scale * rng.standard_normal(step.u.shape)
        a, b = _interpolated(step, u), _interpolated(step, du)
        limit = 0.1
        most_a, alpha, most_reach = _points_motion(step.nodes, step.N, step.active_row, u,
                                                   du, limit)
        assert most_a == (a * a).sum(axis=1).max()
        assert most_reach == ((a + b) ** 2).sum(axis=1).max()
        assert alpha == largest_step_within(a, b, limit)
        # the quadratic's root per leaving row, in NumPy
        aa, ab, bb = (a * a).sum(axis=1), (a * b).sum(axis=1), (b * b).sum(axis=1)
        leaving = (aa + 2.0 * ab + bb > limit * limit) & (bb > 0.0)
        roots = (-ab + np.sqrt(np.maximum(ab * ab - bb * (aa - limit * limit), 0.0))) / bb
        assert alpha == (np.clip(roots[leaving].min(), 0.0, 1.0) if leaving.any() else 1.0)
        alphas.append(alpha)
    assert min(alphas) < 1.0 and max(alphas) == 1.0


def test_a_body_s_iterate_is_kept_within_the_step_s_motion_limit():
    """coupling.motion_bounded_step: a step that would carry a point past the limit is
    shortened to reach it; from the limit, a step leading out stops the step with the
    motion error (kind "motion", its destination's ratio to the limit, which the
    step-size controller turns into halvings of Δt); an iterate beyond the limit or no
    limit leaves the step as it is."""
    from softgrains.contact.coupling import motion_bounded_step
    from softgrains.errors import SimulationError

    step = _disk_step()
    h = 0.1
    shift = np.tile([1.0, 0.0], (step.u.shape[0], 1))
    step.u = 0.0 * shift
    bounded = motion_bounded_step(step, 3.0 * h * shift, h, 0)
    np.testing.assert_allclose(bounded, h * shift, rtol=1e-12)
    np.testing.assert_array_equal(motion_bounded_step(step, 0.5 * h * shift, h, 0),
                                  0.5 * h * shift)
    np.testing.assert_array_equal(motion_bounded_step(step, 3.0 * h * shift, 0.0, 0),
                                  3.0 * h * shift)
    step.u = bounded  # on the limit (to round-off either way)
    with pytest.raises(SimulationError) as failure:
        motion_bounded_step(step, 1.5 * h * shift, h, 7)
    assert failure.value.diagnosis["kind"] == "motion"
    assert failure.value.diagnosis["motion"] == pytest.approx(2.5)
    back = motion_bounded_step(step, -0.5 * h * shift, h, 7)
    np.testing.assert_array_equal(back, -0.5 * h * shift)
    step.u = 2.0 * h * shift
    np.testing.assert_array_equal(motion_bounded_step(step, h * shift, h, 7), h * shift)


def test_contacts_at_inactive_nodes_are_found_as_the_loop_over_contacts_found_them():
    """coupling.inactive_nodes (one lookup in the bodies' active rows laid end to end)
    marks what the per-contact loop it replaced marked: a contact whose node carries no
    unknown of its body's step; never one whose body has no step (a wall, body 5)."""
    from types import SimpleNamespace

    from softgrains.contact.coupling import inactive_nodes

    rng = np.random.default_rng(8)
    steps = {b: SimpleNamespace(active_row=np.where(rng.random(size) < 0.3, -1,
                                                    np.arange(size)))
             for b, size in ((0, 40), (2, 25), (3, 60))}
    bodies = rng.choice([0, 2, 3, 5], 300)
    local = np.array([rng.integers(0, steps[b].active_row.size) if b in steps
                      else rng.integers(0, 1000) for b in bodies])
    expected = np.array([b in steps and steps[b].active_row[i] < 0
                         for b, i in zip(bodies, local, strict=True)])
    got = inactive_nodes(bodies, local, steps)
    np.testing.assert_array_equal(got, expected)
    assert got.any() and not got[bodies == 5].any()
    assert inactive_nodes(bodies[:0], local[:0], steps).size == 0


def test_stiffened_rotations_stay_only_while_the_loop_makes_progress_with_them():
    """_StiffeningTrial (coupling.py): the measures of the quasi-static squeeze's slow steps
    after the switch (883 → 33.5 → 3.3, session 55's trace) keep the stiffened rotations;
    the 100-grain deposit's (3.21e3 at the switch, then +1.8% an iteration) undo them
    after STIFFENING_TRIAL measures; help that stops (a fall to 1.17, then +1.7% an
    iteration) undoes them STIFFENING_TRIAL measures after the last 10% improvement; and
    a restart (the problem changed: corrected gaps, a larger working set) starts the
    trial again from the next measure."""
    from softgrains.contact.coupling import STIFFENING_TRIAL, _StiffeningTrial

    squeeze = _StiffeningTrial(883.0, [0])
    assert not squeeze.failed(33.5) and not squeeze.failed(3.31)
    deposit = _StiffeningTrial(3.21e3, [0])
    rising = [3.21e3 * 1.018 ** j for j in range(1, 10)]
    undone = next(j for j, m in enumerate(rising, start=1) if deposit.failed(m))
    assert undone == STIFFENING_TRIAL
    helped = _StiffeningTrial(1.58e3, [0])
    measures = [26.1, 2.93, 1.17] + [1.17 * 1.017 ** j for j in range(1, 10)]
    undone = next(j for j, m in enumerate(measures, start=1) if helped.failed(m))
    assert undone == 3 + STIFFENING_TRIAL
    restarted = _StiffeningTrial(1.0, [0])
    for _ in range(STIFFENING_TRIAL - 1):
        assert not restarted.failed(5.0)
    restarted.restart()
    assert not restarted.failed(50.0)  # the new problem's first measure is its best


def test_a_deposit_step_is_not_held_back_by_stiffened_rotations_that_do_not_help(
        monkeypatch):
    """#14 item 6 (the pre-compaction ends in bounded steps): the first steps of the
    100-grain deposit (examples/compaction_1000.toml at 100 grains, 4e-4 s a step).
    Until session 55 a loop still slow at its 10th iteration stiffened every grain's
    rotation (BodyStep.stiffen_rotation) and kept them so: at steps 8 and 18 the loop,
    about to converge, crawled on at line-search steps of 2^-8, its measure rising, until
    the stall test gave up 40 iterations later and the step was retried at Δt/2 (seven
    retries to t = 0.03 s, 72 s; 48 s and none since, this 2-core machine beside another
    run). Now the stiffened rotations are undone where they do not help
    (coupling.STIFFENING_TRIAL): no step of the first 20 is retried, and at least one
    undid them."""
    from pathlib import Path

    from softgrains.contact import coupling

    case = Path(__file__).resolve().parents[2] / "examples" / "compaction_1000.toml"

    def run():
        sim = Simulation(load_case(case, ["sample.count=100", "sample.box_width=0.09"]))
        undone = sum(sim.step().contact.stiffenings_undone for _ in range(20))
        return sim.retried_steps, undone

    retried, undone = run()
    assert retried == 0 and undone > 0
    monkeypatch.setattr(coupling, "STIFFENING_TRIAL", 10**9)  # never undone
    assert run()[0] > 0  # what undoing them changes

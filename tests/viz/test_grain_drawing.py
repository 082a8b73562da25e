"""Grains drawn as filled bodies, the smoothed stress field and the force chains (issue #13,
items 1–3): checks that would catch a blank or wrong figure."""

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from softgrains.geometry import Disk, seed_disk_rings, seed_points
from softgrains.observe.chains import (
    body_centres,
    chain_segments,
    force_distribution,
    pair_forces,
)
from softgrains.observe.stress import project_per_grain, von_mises
from softgrains.viz.chains import ChainPanel, chain_widths, chains_figure, draw_chains
from softgrains.viz.grains import (
    GrainPoints,
    draw_grains,
    grain_mesh,
    grain_outlines,
    wall_rectangles,
)


def _frame(grains, wall=None):
    """GrainPoints of a list of (positions, volumes, F) grains and an optional wall block."""
    xs, vols, Fs, bodies = [], [], [], []
    for index, (x, vol, F) in enumerate(grains):
        xs.append(x)
        vols.append(vol)
        Fs.append(np.tile(F, (len(x), 1, 1)))
        bodies.append(np.full(len(x), index))
    walls = frozenset()
    if wall is not None:
        x, vol = wall
        xs.append(x)
        vols.append(vol)
        Fs.append(np.tile(np.eye(2), (len(x), 1, 1)))
        bodies.append(np.full(len(x), len(grains)))
        walls = frozenset({len(grains)})
    F = np.concatenate(Fs)
    vol = np.concatenate(vols)
    side = np.sqrt(vol / np.linalg.det(F))
    return GrainPoints(np.concatenate(xs), F, side, np.concatenate(bodies), walls), vol


def test_a_drawn_grain_fills_its_area_without_holes():
    """The filled triangles of a lattice disk, a ring-seeded disk and a sheared ellipse
    cover their points' area Σ V_p within 2% (issue #13, item 6), and every point lies in
    the filled region (no hole)."""
    h = 0.1
    lattice_x, v0 = seed_points(Disk(np.array([1.0, 1.0]), 0.5), np.zeros(2), h, 2)
    lattice_vol = np.full(len(lattice_x), v0)
    rings_x, rings_vol = seed_disk_rings(Disk(np.array([2.5, 1.0]), 0.5), h / 2)
    F = np.array([[1.4, 0.3], [0.0, 1.0 / 1.4]])  # area-preserving shear and stretch
    centre = np.array([4.0, 1.0])
    sheared_x = centre + (lattice_x - 1.0) @ F.T
    points, vol = _frame([(lattice_x, lattice_vol, np.eye(2)), (rings_x, rings_vol, np.eye(2)),
                          (sheared_x, lattice_vol, F)])
    mesh = grain_mesh(points)
    assert mesh.grains == [0, 1, 2]
    for index in range(3):
        area = vol[points.body == index].sum()
        assert mesh.filled_area(index) == pytest.approx(area, rel=0.02)
    from matplotlib.tri import Triangulation

    triangulation = Triangulation(mesh.vertices[:, 0], mesh.vertices[:, 1], mesh.triangles)
    finder = triangulation.get_trifinder()
    assert np.all(finder(points.positions[:, 0], points.positions[:, 1]) >= 0)


def test_the_shading_interpolates_the_point_values():
    """At the points the drawn field is the point value; the outline vertices take values
    from their nearest points (within the points' range)."""
    x, v0 = seed_points(Disk(np.array([0.0, 0.0]), 0.5), np.zeros(2), 0.1, 2)
    points, _ = _frame([(x, np.full(len(x), v0), np.eye(2))])
    mesh = grain_mesh(points)
    field = 3.0 + x[:, 0]
    values = mesh.values(field)
    assert values[: len(x)] == pytest.approx(field)
    assert values.min() >= field.min() - 1e-12 and values.max() <= field.max() + 1e-12
    figure = Figure()
    ax = figure.add_subplot()
    filled = draw_grains(ax, mesh, field, Normalize(field.min(), field.max()))
    assert filled.get_array().shape == (len(mesh.vertices),)
    outlines = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(outlines) == 1 and len(outlines[0].get_segments()) == 1


def test_walls_are_drawn_where_their_points_are():
    x = np.stack(np.meshgrid(np.arange(10) * 0.1 + 0.05, [-0.05, -0.15]), -1).reshape(-1, 2)
    disk, v0 = seed_points(Disk(np.array([0.5, 0.5]), 0.3), np.zeros(2), 0.1, 2)
    points, _ = _frame([(disk, np.full(len(disk), v0), np.eye(2))],
                       wall=(x, np.full(len(x), 0.01)))
    ((lower, upper),) = wall_rectangles(points)
    assert lower == pytest.approx([0.0, -0.2]) and upper == pytest.approx([1.0, 0.0])
    assert grain_mesh(points).grains == [0]  # the wall is not a grain


def test_the_smoothed_stress_keeps_each_grain_mean_and_a_linear_field():
    """The least-squares projection keeps Σ V_p σ_p per grain to round-off, returns a
    linear field unchanged, and reduces point-to-point noise."""
    rng = np.random.default_rng(1)
    x = rng.random((3000, 2))
    grain = (x[:, 0] > 0.5).astype(int)
    vol = 0.5 + rng.random(3000)
    noise = rng.standard_normal((3000, 3, 3))
    smoothed = project_per_grain(x, vol, noise, grain, 0.1)
    for g in (0, 1):
        mine = grain == g
        assert np.einsum("p,pij->ij", vol[mine], smoothed[mine]) == pytest.approx(
            np.einsum("p,pij->ij", vol[mine], noise[mine]), abs=1e-9)
    assert smoothed.std() < 0.3 * noise.std()
    linear = 2.0 + 3.0 * x[:, 0] - x[:, 1]
    assert project_per_grain(x, vol, linear, grain, 0.1) == pytest.approx(linear, abs=1e-12)
    # also on seeded grains, whose edge nodes see too few points to fit a gradient
    for disk_x, disk_v in (seed_points(Disk(np.array([0.3, 0.2]), 0.1), np.zeros(2), 0.01, 2),
                           seed_disk_rings(Disk(np.array([0.3, 0.2]), 0.1), 0.005)):
        disk_vol = np.broadcast_to(disk_v, (len(disk_x),)).astype(float)
        field = 3.0 + 10.0 * disk_x[:, 0] + 5.0 * disk_x[:, 1]
        one = np.zeros(len(disk_x), int)
        assert project_per_grain(disk_x, disk_vol, field, one, 0.005) == pytest.approx(
            field, abs=1e-12)
    # grains are not blurred into each other: a jump between grains is kept
    step = np.where(grain == 1, 10.0, 0.0)
    assert project_per_grain(x, vol, step, grain, 0.1) == pytest.approx(step, abs=1e-12)
    assert von_mises(smoothed).shape == (3000,)


def _two_disks_and_a_wall():
    """Disk 0 resting on a wall (body 2) and disk 1 resting on disk 0; the wall carries
    both disks' weight, so the wall pair is the stronger."""
    a, v0 = seed_points(Disk(np.array([0.5, 0.5]), 0.4), np.zeros(2), 0.1, 2)
    b = a + [0.0, 0.8]
    wall = np.stack(np.meshgrid(np.arange(10) * 0.1 + 0.05, [-0.05]), -1).reshape(-1, 2)
    points, vol = _frame([(a, np.full(len(a), v0), np.eye(2)), (b, np.full(len(b), v0),
                                                               np.eye(2))],
                         wall=(wall, np.full(len(wall), 0.01)))
    # contact nodes: three between the disks (at y = 0.9), two under disk 0 (at y = 0)
    position = np.array([[0.45, 0.9], [0.5, 0.9], [0.55, 0.9], [0.45, 0.0], [0.55, 0.0]])
    alpha = np.array([1, 0, 1, 0, 2])  # either order names one pair
    beta = np.array([0, 1, 0, 2, 0])
    fn = np.array([1.0, 2.0, 1.0, 4.0, 4.0])
    status = np.array([1, 2, 2, 1, 1])  # stick, slip, slip, stick, stick
    ft = 0.5 * fn  # with friction: the slipping nodes carry f_t = μ f_n
    return points, vol, pair_forces(alpha, beta, fn, status, position, ft)


def test_a_two_disk_stack_gives_one_chain_segment_per_pair():
    points, vol, pairs = _two_disks_and_a_wall()
    assert sorted(zip(pairs.alpha, pairs.beta, strict=True)) == [(0, 1), (0, 2)]
    order = np.argsort(pairs.beta)
    assert pairs.force[order] == pytest.approx([4.0, 8.0])
    assert pairs.slip_share[order] == pytest.approx([0.75, 0.0])
    assert pairs.point[order][0] == pytest.approx([0.5, 0.9])
    centres = body_centres(points.positions, vol, points.body)
    segments = chain_segments(pairs, centres, set(points.wall_bodies))[order]
    # grain–grain: centre to centre; grain–wall: centre to the contact point
    assert segments[0] == pytest.approx(np.array([centres[0], centres[1]]))
    assert segments[1] == pytest.approx(np.array([centres[0], [0.5, 0.0]]))
    widths = chain_widths(pairs.force[order], float(pairs.force.max()))
    assert widths[1] == pytest.approx(2.0 * widths[0])
    # drawn: one line per pair, the wall pair twice as wide, one slipping pair marked
    panel = ChainPanel(points, grain_outlines(points), pairs, centres, "stack")
    figure = chains_figure([panel], (np.array([-0.1, -0.3]), np.array([1.1, 1.8])))
    lines = next(c for c in figure.axes[0].collections if isinstance(c, LineCollection))
    assert len(lines.get_segments()) == 2
    assert sorted(lines.get_linewidths()) == pytest.approx(sorted(widths))
    marked = [line for line in figure.axes[0].get_lines() if line.get_marker() == "o"]
    assert len(marked) == 1 and len(marked[0].get_xdata()) == 1
    # without friction (f_t = 0) nothing is marked as slipping: every contact "slips"
    frictionless = pair_forces(np.array([1, 0]), np.array([0, 2]), np.array([1.0, 4.0]),
                               np.array([2, 2]), np.array([[0.5, 0.9], [0.5, 0.0]]),
                               np.zeros(2))
    assert np.all(frictionless.slip_share == 0.0)
    ax = Figure().add_subplot()
    draw_chains(ax, ChainPanel(points, grain_outlines(points), frictionless, centres, ""),
                Normalize(0.0, 8.0))
    assert not [line for line in ax.get_lines() if line.get_marker() == "o"]


def test_the_force_distribution_is_normalised_by_the_mean():
    forces = np.array([1.0, 1.0, 2.0, 4.0])  # mean 2: f/<f> = 0.5, 0.5, 1, 2
    centres, density = force_distribution(forces, np.array([0.0, 1.0, 2.0, 3.0]))
    assert centres == pytest.approx([0.5, 1.5, 2.5])
    assert density == pytest.approx([0.5, 0.25, 0.25])  # f/<f> = 2 falls in [2, 3)
    assert np.sum(density) == pytest.approx(1.0)

"""Seeding of material points (ALGORITHM.md §1): lattice and concentric rings."""

import numpy as np
import pytest

from softgrains import load_case
from softgrains.errors import CaseError
from softgrains.geometry import Disk, seed_disk_rings, seed_points
from softgrains.model import build


@pytest.mark.parametrize("radius, spacing", [(0.5, 0.005), (0.005, 0.00025), (0.3, 0.07)])
def test_rings_fill_the_disk_exactly_with_nearly_square_cells(radius, spacing):
    disk = Disk(np.array([0.2, -0.1]), radius)
    x, vol = seed_disk_rings(disk, spacing)
    assert vol.sum() == pytest.approx(np.pi * radius**2, rel=1e-12)
    r = np.linalg.norm(x - disk.center, axis=1)
    rings = max(1, round(radius / spacing))
    dr = radius / rings
    # the outermost points lie half a ring width inside the circle, all around
    assert r.max() == pytest.approx(radius - 0.5 * dr, rel=1e-12)
    outer = np.isclose(r, radius - 0.5 * dr)
    angles = np.sort(np.arctan2(*(x[outer] - disk.center).T[::-1]))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
    assert np.ptp(gaps) < 1e-9  # equally spaced
    # cells of side ~δ: volumes within 25% of δ² (the three innermost points excepted)
    assert np.all(np.abs(vol[3:] / spacing**2 - 1.0) < 0.25)


def test_rings_follow_the_circle_where_the_lattice_is_a_staircase():
    """Lowest boundary (point − δ/2) below the disk's apex, over the lateral band |x| ≤ 0.1 R:
    the lattice's bottom row is flat there (it deviates from the circle by up to δ), the
    rings follow the circle to a small fraction of δ."""
    radius, delta = 0.5, 0.005
    disk = Disk(np.array([0.7, 0.7]), radius)

    def worst_deviation(x):
        rel = x - disk.center
        deviations = []
        for xc in np.linspace(-0.1 * radius, 0.1 * radius, 21):
            column = np.abs(rel[:, 0] - xc) <= 0.5 * delta
            lowest = rel[column, 1].min() - 0.5 * delta
            deviations.append(abs(lowest + np.sqrt(radius**2 - xc**2)))
        return max(deviations) / delta

    lattice, _ = seed_points(disk, np.zeros(2), 2 * delta, 2)
    rings, _ = seed_disk_rings(disk, delta)
    assert worst_deviation(lattice) > 0.5
    assert worst_deviation(rings) < 0.2


def _case(shape, seeding):
    body = {"disk": {"shape": "disk", "center": [0.5, 0.5], "radius": 0.2},
            "rectangle": {"shape": "rectangle", "lower": [0.3, 0.3], "upper": [0.7, 0.7]}}
    return {"simulation": {"dt": 1e-3, "steps": 1},
            "grid": {"cell_size": 0.05, "size": [1.0, 1.0]},
            "materials": {"gel": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
            "bodies": [{**body[shape], "material": "gel", "seeding": seeding}]}


def test_ring_seeded_body_carries_its_mass_and_volume():
    model, state = build(load_case(_case("disk", "rings")))
    assert model.vol0.sum() == pytest.approx(np.pi * 0.04, rel=1e-12)
    assert model.mass.sum() == pytest.approx(1000.0 * np.pi * 0.04, rel=1e-12)
    assert np.allclose(state.vol, model.vol0)


def test_rings_only_for_disks():
    with pytest.raises(CaseError, match="seeding"):
        load_case(_case("rectangle", "rings"))


def test_ring_seeded_disk_smaller_than_a_point_spacing_is_a_case_error():
    case = _case("disk", "rings")
    case["bodies"][0]["radius"] = 0.01  # spacing 0.025
    with pytest.raises(CaseError, match="radius 0.01 is below one point spacing"):
        build(load_case(case))


@pytest.mark.parametrize("outer", [2, 3])
def test_a_denser_outer_ring_keeps_the_disk_and_divides_its_outer_cells(outer):
    """outer_ring_density: the outermost ring holds `outer` times its points, each of
    1/outer the volume; the other rings and the disk's volume are unchanged, and the ring
    sectors still tile it (the cells' areas are the points' volumes)."""
    from softgrains.geometry import disk_ring_cells

    disk, spacing = Disk(np.array([0.2, -0.1]), 0.05), 0.0025
    x1, vol1 = seed_disk_rings(disk, spacing)
    x2, vol2 = seed_disk_rings(disk, spacing, outer)
    r1, r2 = (np.linalg.norm(x - disk.center, axis=1) for x in (x1, x2))
    rim1, rim2 = np.isclose(r1, r1.max()), np.isclose(r2, r2.max())
    assert r2.max() == pytest.approx(r1.max(), rel=1e-12)
    assert rim2.sum() == outer * rim1.sum()
    assert np.allclose(vol2[rim2], vol1[rim1][0] / outer)
    assert np.array_equal(x2[~rim2], x1[~rim1]) and np.array_equal(vol2[~rim2], vol1[~rim1])
    assert vol2.sum() == pytest.approx(np.pi * disk.radius**2, rel=1e-12)
    assert np.allclose(disk_ring_cells(disk, spacing, outer).area(), vol2)


def test_outer_ring_density_is_for_ring_seeding_only():
    case = _case("disk", "lattice")
    case["bodies"][0]["outer_ring_density"] = 2
    with pytest.raises(CaseError, match="outer_ring_density"):
        load_case(case)
    case["bodies"][0]["seeding"] = "rings"
    model, _ = build(load_case(case))
    assert model.bodies[0].outer_ring_density == 2
    assert model.vol0.sum() == pytest.approx(np.pi * 0.04, rel=1e-12)

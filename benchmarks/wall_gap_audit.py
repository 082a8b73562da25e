"""Audit of per-point wall contacts: does a wall contact's next gap follow the constraint?

    python benchmarks/wall_gap_audit.py RUN_DIR AUDIT_DIR [edge|noedge] [STEPS]

Copies RUN_DIR (the output folder of a run with a checkpoint, e.g. a compaction example run
with wall_sites = "surface"), resumes it with one contact site per boundary point at walls
(patches of one point; with "noedge" the force at the point instead of its cell edge) and,
for STEPS steps, compares every grain–wall point contact's gap at step k + 1 with step k:

- "deepened": a contact of step k whose gap fell by more than 0.02 h to below −0.05 h,
  printed with the contact solve's predicted end-of-step gap, the point's normal
  displacement n·Δx, the change of its cell support n·Δr and its linear prediction
  n·(ΔF F⁻¹ r) (what the edge stencil's rate assumes);
- "new": a point already 0.02 h into the wall that was not a contact at step k, with its
  gap and its own-surface distance at step k (points deeper than one point spacing
  inside their own grain's kernel surface are not taken as contacts).

Session 14 (2026-12-03) found with it the two ways points got 0.5 h into the walls of the
README main job; docs/dev-notes.md, "Contact, session 14".
"""

import shutil
import sys
from pathlib import Path

import numpy as np

import softgrains.contact.coupling as coupling
import softgrains.contact.sites as sites
import softgrains.contact.surfaces as surfaces

_group = sites.group
sites.group = lambda *a, alone=None, **k: _group(*a, alone=np.arange(alone.size) * 2, **k)
if len(sys.argv) > 3 and sys.argv[3] == "noedge":
    surfaces.edge_stencil = lambda step, points, r: (step.active_row[step.nodes[points]],
                                                     step.N[points])
_wall_contacts, _solve = surfaces.wall_contacts, coupling.solve
log = {}


def traced_wall_contacts(pairs, steps, shapes, spacing, reach, round_bodies=frozenset()):
    sc = _wall_contacts(pairs, steps, shapes, spacing, reach, round_bodies)
    candidates = {}  # every point within reach: (gap, own-surface distance)
    for grain, wall in pairs:
        own = surfaces.KernelSurface(steps[grain])
        x = own.step.pts.x
        distance, n_out = surfaces.shape_distance(shapes[wall], x)
        near = np.flatnonzero(distance < reach + spacing)
        value, grad, _ = own.field(x[near])
        inside, _ = surfaces.calibrated_distance(value, grad, own.radius)
        support = surfaces.cell_support(own.step.pts.F[near], n_out[near], spacing,
                                        grain in round_bodies)
        gap = distance[near] + np.einsum("pi,pi->p", n_out[near], support)
        pairs_of = zip(gap.tolist(), inside.tolist(), strict=True)
        candidates[(grain, wall)] = dict(zip(near.tolist(), pairs_of, strict=True))
    log["contacts"], log["candidates"] = sc, candidates
    return sc


def traced_solve(problem, P, options):
    result = _solve(problem, P, options)
    log["problem"] = (problem, result)
    return result


surfaces.wall_contacts = sites.wall_contacts = traced_wall_contacts
coupling.solve = traced_solve
from softgrains import Simulation, load_case  # noqa: E402  (after the patches)


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    n_steps = int(sys.argv[4]) if len(sys.argv) > 4 else 10
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(src, out)
    sim = Simulation(load_case(out / "case.toml"), out=out)
    sim.resume(out / "checkpoint.h5")
    h = sim.case.grid.cell_size
    spacing = h / sim.model.points_per_cell
    round_bodies = {b.index for b in sim.model.bodies if b.seeding == "rings"}
    previous = None
    for _ in range(n_steps):
        before = {b.index: (sim.state.x[b.points].copy(), sim.state.F[b.points].copy())
                  for b in sim.model.bodies if b.deformable}
        diag = sim.step()
        sc, candidates = log["contacts"], log["candidates"]
        problem, result = log["problem"]
        dt = sim.case.simulation.dt * sim.dt_factor
        w_n = np.einsum("ci,ci->c", problem.velocities(result.impulse), problem.normal)
        cs = sim.state.contacts
        index = {(int(a), int(b), tuple(np.round(x, 12))): c for c, (a, b, x) in enumerate(
            zip(cs.nodes.alpha, cs.nodes.beta, cs.nodes.position, strict=True))}
        now, predicted, normal = {}, {}, {}
        for a, b, p, x, g, n in zip(sc.alpha, sc.beta, sc.point, sc.position, sc.gap,
                                    sc.normal, strict=True):
            key = (int(a), int(b), int(p))
            now[key], normal[key] = g, n
            c = index.get((key[0], key[1], tuple(np.round(x, 12))))
            if c is not None:
                predicted[key] = g + dt * w_n[c]  # the gap the solve's velocities give
        print(f"step {sim.state.step}: coupling its {diag.contact.iterations}, residual "
              f"{diag.contact.residual:.1e}; wall contacts {len(now)}, least gap "
              f"{min(now.values()) / h:.3f} h", flush=True)
        if previous is not None:
            gaps, predicted_before, normals, candidates_before, states = previous
            for key, g in now.items():
                if key in gaps and g < -0.05 * h and g < gaps[key] - 0.02 * h:
                    a, _, p = key
                    (X0, G0), (X1, G1) = states[a]
                    x0, F0, x1, F1 = X0[p], G0[p], X1[p], G1[p]
                    n = normals[key]
                    r0, r1 = (surfaces.cell_support(F[None], n[None], spacing,
                                                    a in round_bodies)[0] for F in (F0, F1))
                    linear = (F1 - F0) @ np.linalg.solve(F0, r0)
                    print(f"   deepened {key}: {gaps[key] / h:.3f} -> {g / h:.3f} h (solve "
                          f"predicted {predicted_before.get(key, np.nan) / h:.3f}); "
                          f"n.dx {n @ (x1 - x0) / h:.3f}, n.dr {n @ (r1 - r0) / h:.3f}, "
                          f"linear n.dr {n @ linear / h:.3f} h; max|dF| "
                          f"{np.abs(F1 - F0).max():.2f}")
                elif key not in gaps and g < -0.02 * h:
                    gap0, inside0 = candidates_before.get(key[:2], {}).get(key[2],
                                                                          (np.nan, np.nan))
                    print(f"   new {key}: {g / h:.3f} h; at step k gap {gap0 / h:.3f} h, "
                          f"own-surface distance {inside0 / h:.3f} h")
        states_pair = {a: (before[a], (sim.state.x[sim.model.bodies[a].points].copy(),
                                       sim.state.F[sim.model.bodies[a].points].copy()))
                       for a in before}
        previous = (now, predicted, normal, candidates, states_pair)


if __name__ == "__main__":
    main()

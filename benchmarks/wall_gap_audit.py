"""Audit of per-point wall contacts: does a wall contact's next gap follow the constraint?

    python benchmarks/wall_gap_audit.py RUN_DIR AUDIT_DIR [VARIANT] [STEPS]

Copies RUN_DIR (the output folder of a run with a checkpoint, e.g. a compaction example run),
resumes it with ``contact.wall_sites = "points"`` (one contact site per grain point within
reach of a wall) and, for STEPS steps, compares every grain–wall point contact's gap at step
k + 1 with step k:

- "deepened": a contact of step k whose gap fell by more than 0.02 h to below −0.05 h,
  printed with the contact solve's predicted end-of-step gap, the point's normal
  displacement n·Δx, the change of its cell support n·Δr and its linear prediction
  n·(ΔF F⁻¹ r) (what the edge stencil's rate assumes);
- "new": a point already 0.02 h into the wall that was not a contact at step k, with its
  gap and its own-surface distance at step k.

VARIANT (joined by "+"): "noedge" puts the force at the point instead of its cell edge;
"square" takes the lattice square's corner as the cell support at walls (session 14's);
"nodalwalls" keeps the case's wall sites (the default: nodes) and audits only the grain
pairs' point contacts: per step, how many deepened (same rule) and the worst three;
"check" turns ``contact.end_gap_check`` on.

Session 14 (2026-12-03) found with it the two ways points got 0.5 h into the walls of the
README main job (the square support's kink, and corner points beyond the outer-point
threshold); session 15 checked the mends; docs/dev-notes.md, "Contact, session 14/15".
"""

import shutil
import sys
from pathlib import Path

import numpy as np

import softgrains.contact.coupling as coupling
import softgrains.contact.sites as sites
import softgrains.contact.surfaces as surfaces

VARIANT = set(sys.argv[3].split("+")) if len(sys.argv) > 3 else set()
if "noedge" in VARIANT:
    surfaces.edge_stencil = lambda step, points, r: (step.active_row[step.nodes[points]],
                                                     step.N[points])
if "square" in VARIANT:  # session 14's support: the lattice square's corner at walls
    _support = surfaces.cell_support
    surfaces.cell_support = lambda F, n, spacing, round_body: _support(F, n, spacing, False)
_wall_contacts, _grain_contacts = surfaces.wall_contacts, surfaces.surface_contacts
_solve = coupling.solve
log = {}


def traced_grain_contacts(*args, **kwargs):
    log["grain_contacts"] = sc = _grain_contacts(*args, **kwargs)
    return sc


def traced_wall_contacts(pairs, steps, shapes, spacing, reach):
    sc = _wall_contacts(pairs, steps, shapes, spacing, reach)
    candidates = {}  # every point within reach: (gap, own-surface distance)
    for grain, wall in pairs:
        own = surfaces.KernelSurface(steps[grain])
        x = own.step.pts.x
        distance, n_out = surfaces.shape_distance(shapes[wall], x)
        near = np.flatnonzero(distance < reach + spacing)
        value, grad = own.field(x[near])
        inside, _ = surfaces.calibrated_distance(value, grad, own.radius)
        gap, _ = surfaces.edge_gap(distance[near], n_out[near], own.step.pts.F[near],
                                   spacing, "square" not in VARIANT)
        pairs_of = zip(gap.tolist(), inside.tolist(), strict=True)
        candidates[(grain, wall)] = dict(zip(near.tolist(), pairs_of, strict=True))
    log["contacts"], log["candidates"] = sc, candidates
    return sc


def traced_solve(problem, P, options):
    result = _solve(problem, P, options)
    log["problem"] = (problem, result)
    return result


surfaces.wall_contacts = sites.wall_contacts = traced_wall_contacts
surfaces.surface_contacts = sites.surface_contacts = traced_grain_contacts
coupling.solve = traced_solve
from softgrains import Simulation, load_case  # noqa: E402  (after the patches)


def _gaps(sc, index, moved):
    """Per contact key: its gap, normal and the end-of-step gap the solve's velocities gave."""
    now, predicted, normal = {}, {}, {}
    for a, b, own_a, p, x, g, n in zip(sc.alpha, sc.beta, sc.owner_is_alpha, sc.point,
                                       sc.position, sc.gap, sc.normal, strict=True):
        key = (int(a), int(b), int(p), bool(own_a))
        now[key], normal[key] = g, n
        c = index.get((key[0], key[1], tuple(np.round(x, 12))))
        if c is not None:
            predicted[key] = g + moved[c]
    return now, predicted, normal


def _report_walls(now, before, states, spacing, h):
    gaps, predicted, normals, candidates = before
    for key, g in now.items():
        if key in gaps and g < -0.05 * h and g < gaps[key] - 0.02 * h:
            a, _, p, _ = key
            (X0, G0), (X1, G1) = states[a]
            x0, F0, x1, F1 = X0[p], G0[p], X1[p], G1[p]
            n = normals[key]
            r0, r1 = (surfaces.cell_support(F[None], n[None], spacing, "square" not in VARIANT)
                      [0] for F in (F0, F1))
            linear = (F1 - F0) @ np.linalg.solve(F0, r0)
            print(f"   deepened {key[:3]}: {gaps[key] / h:.3f} -> {g / h:.3f} h (solve "
                  f"predicted {predicted.get(key, np.nan) / h:.3f}); "
                  f"n.dx {n @ (x1 - x0) / h:.3f}, n.dr {n @ (r1 - r0) / h:.3f}, "
                  f"linear n.dr {n @ linear / h:.3f} h; max|dF| {np.abs(F1 - F0).max():.2f}")
        elif key not in gaps and g < -0.02 * h:
            gap0, inside0 = candidates.get(key[:2], {}).get(key[2], (np.nan, np.nan))
            print(f"   new {key[:3]}: {g / h:.3f} h; at step k gap {gap0 / h:.3f} h, "
                  f"own-surface distance {inside0 / h:.3f} h")


def _report_grains(now, before, states, spacing, h):
    """Grain pairs' point contacts that deepened: the gap change, the solve's prediction,
    the own point's motion along the surface normal n·Δx and the change of its cell's
    extent e along n with the lattice square's support and with the round one."""
    gaps, predicted, normals, _ = before
    deepened = sorted((g - gaps[key], key, gaps[key], g) for key, g in now.items()
                      if key in gaps and g < -0.05 * h and g < gaps[key] - 0.02 * h)
    new = [g for key, g in now.items() if key not in gaps and g < -0.02 * h]
    print(f"   grain contacts {len(now)}, least gap {min(now.values(), default=0) / h:.3f} h;"
          f" deepened {len(deepened)}, new below -0.02 h {len(new)}"
          + (f" (deepest new {min(new) / h:.3f} h)" if new else ""))
    for _, key, g0, g in deepened[:3]:
        a, b, p, own_alpha = key
        (X0, G0), (X1, G1) = states[a if own_alpha else b]
        n = normals[key] if own_alpha else -normals[key]  # out of the surface's body
        extent = {round_: [-n @ surfaces.cell_support(F[None], n[None], spacing, round_)[0]
                           for F in (G0[p], G1[p])] for round_ in (False, True)}
        print(f"   deepened {key}: {g0 / h:.3f} -> {g / h:.3f} h (solve predicted "
              f"{predicted.get(key, np.nan) / h:.3f}); own n.dx {n @ (X1[p] - X0[p]) / h:.3f}"
              f", de square {np.diff(extent[False])[0] / h:.3f}, round "
              f"{np.diff(extent[True])[0] / h:.3f} h")


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    n_steps = int(sys.argv[4]) if len(sys.argv) > 4 else 10
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(src, out)
    overrides = [] if "nodalwalls" in VARIANT else ["contact.wall_sites=points"]
    if "check" in VARIANT:
        overrides.append("contact.end_gap_check=true")
    sim = Simulation(load_case(out / "case.toml", overrides), out=out)
    sim.resume(out / "checkpoint.h5")
    h = sim.case.grid.cell_size
    spacing = h / sim.model.points_per_cell
    previous = {}
    for _ in range(n_steps):
        before = {b.index: (sim.state.x[b.points].copy(), sim.state.F[b.points].copy())
                  for b in sim.model.bodies if b.deformable}
        log.clear()
        diag = sim.step()
        problem, result = log["problem"]
        dt = sim.case.simulation.dt * sim.dt_factor
        moved = dt * np.einsum("ci,ci->c", problem.velocities(result.impulse), problem.normal)
        cs = sim.state.contacts
        index = {(int(a), int(b), tuple(np.round(x, 12))): c for c, (a, b, x) in enumerate(
            zip(cs.nodes.alpha, cs.nodes.beta, cs.nodes.position, strict=True))}
        print(f"step {sim.state.step}: coupling its {diag.contact.iterations}, residual "
              f"{diag.contact.residual:.1e}", flush=True)
        states = {a: (before[a], (sim.state.x[sim.model.bodies[a].points].copy(),
                                  sim.state.F[sim.model.bodies[a].points].copy()))
                  for a in before}
        current = {"states": states}
        if "contacts" in log:
            current["walls"] = (*_gaps(log["contacts"], index, moved), log["candidates"])
            now = current["walls"][0]
            print(f"   wall contacts {len(now)}, least gap {min(now.values()) / h:.3f} h")
            if "walls" in previous:  # the motion of the previous step
                _report_walls(now, previous["walls"], previous["states"], spacing, h)
        if "grain_contacts" in log:
            current["grains"] = (*_gaps(log["grain_contacts"], index, moved), None)
            if "grains" in previous:
                _report_grains(current["grains"][0], previous["grains"], previous["states"],
                               spacing, h)
        previous = current
        sys.stdout.flush()


if __name__ == "__main__":
    main()

"""What a checkpoint holds for a Simulation, and how a run resumes from it (issue #5).

Everything that is carried from one step to the next is saved, so that a resumed run
repeats the uninterrupted one bit for bit (same thread count): the State arrays, the last
step's contacts and impulses (the warm start of the next contact loop), time and step, the
last Δt, the protocol's phase and controller memory, each body's linear-solver choice (CG
or, after a CG failure, direct), the counters of the summary and its last series row. The
case's random seed is stored; no random number is drawn while stepping (the [sample] deposit
is drawn from the seed when the case is loaded), so there is no generator state to keep.
"""

from __future__ import annotations

import copy
import math
import tomllib

import numba
import numpy as np

from softgrains.case import case_to_toml
from softgrains.contact.coupling import ContactState
from softgrains.contact.detection import ContactNodes
from softgrains.errors import CaseError
from softgrains.io import software_versions

STATE_ARRAYS = ("x", "v", "a", "F", "sigma", "vol", "body_velocity", "body_offset")
CONTACT_NODE_ARRAYS = ("node", "alpha", "beta", "normal", "local_alpha", "local_beta")
CONTACT_SITE_ARRAYS = ("site", "position")  # surface contacts only
CONTACT_ARRAYS = ("impulse", "status", "gap")


def structure(case, model) -> dict[str, object]:
    """What a resumed case must share with the checkpoint's: dimension, bodies and their
    point counts, grid, integrator and mass matrix, protocol (the rest, e.g. dt or the
    tolerances, may change: that is how a failed run is continued)."""
    grid = case.grid
    return {
        "dimension": model.dim,
        "bodies": [[b.name, b.kind, b.points.stop - b.points.start] for b in model.bodies],
        "grid": {"cell_size": grid.cell_size, "origin": list(grid.origin),
                 "size": list(grid.size), "shape_function": grid.shape_function,
                 "points_per_cell": grid.points_per_cell},
        "integrator": case.simulation.integrator,
        "mass_matrix": case.simulation.mass_matrix,
        "protocol": case.protocol.kind if case.protocol is not None else None,
    }


def snapshot(sim) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """(arrays, meta): copies of what a Simulation carries between two steps (in memory:
    the retry of a failed step with a smaller Δt restores it)."""
    s = sim.state
    arrays = {f"state/{name}": getattr(s, name).copy() for name in STATE_ARRAYS}
    if s.contacts is not None:
        for name in CONTACT_NODE_ARRAYS:
            arrays[f"contacts/{name}"] = getattr(s.contacts.nodes, name).copy()
        for name in CONTACT_SITE_ARRAYS:
            if getattr(s.contacts.nodes, name) is not None:
                arrays[f"contacts/{name}"] = getattr(s.contacts.nodes, name).copy()
        for name in CONTACT_ARRAYS:
            arrays[f"contacts/{name}"] = getattr(s.contacts, name).copy()
    meta = {
        "time": s.time, "step": s.step, "last_dt": sim.last_dt,
        "unconverged_contact_steps": sim.unconverged_contact_steps,
        "retried_steps": sim.retried_steps,
        "wall_work": sim.wall_work, "contact_dissipation": sim.contact_dissipation,
        "gap_correction_work": sim.gap_correction_work,
        "integrator_dissipation": sim.integrator_dissipation,
        "transfer_dissipation": sim.transfer_dissipation,
        "largest_penetration": sim.largest_penetration,
        "largest_unsampled_penetration": sim.largest_unsampled_penetration,
        "dt_factor": sim.dt_factor, "steps_at_factor": sim.steps_at_factor,
        "grow_after": sim.grow_after, "just_grown": sim.just_grown,
        "smallest_dt_factor": sim.smallest_dt_factor,
        "grain_speed": sim.grain_speed, "reach_retries": sim.reach_retries,
        "last_row": sim._rows[-1] if sim._rows else None,
        "protocol": copy.deepcopy(sim.protocol.state_dict())
        if sim.protocol is not None else None,
        "protocol_row": dict(sim._protocol_row),
        "linear_solvers": {st.name: st.solver.use_direct
                           for st in sim.solver.steppers.values()},
    }
    return arrays, meta


def capture(sim, wall_time: float) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """(arrays, meta) of a Simulation between two steps, for a checkpoint file."""
    arrays, meta = snapshot(sim)
    meta.update({
        "seed": sim.case.simulation.seed, "threads": numba.get_num_threads(),
        "wall_time_s": wall_time, "structure": structure(sim.case, sim.model),
        "case": case_to_toml(sim.case), "software": software_versions(),
    })
    return arrays, meta


def check_compatible(sim, meta: dict[str, object], path) -> list[str]:
    """Raise CaseError when the case differs from the checkpoint's in a way that matters;
    return the other differences (``key: old → new``) for the log."""
    saved, now = meta["structure"], _plain_json(structure(sim.case, sim.model))
    wrong = [key for key in now if saved.get(key) != now[key]]
    if wrong:
        lines = [f"  {key}: checkpoint {_short(saved.get(key))}, case {_short(now[key])}"
                 for key in wrong]
        raise CaseError(f"the case does not match the checkpoint '{path}' (it was written "
                        "by another case):\n" + "\n".join(lines) + "\nrun without --resume "
                        "into another --out folder, or resume with the original case")
    old = _flatten(tomllib.loads(str(meta["case"])))
    new = _flatten(tomllib.loads(case_to_toml(sim.case)))
    return [f"{k}: {_short(old.get(k))} → {_short(new.get(k))}"
            for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]


def restore(sim, arrays: dict[str, np.ndarray], meta: dict[str, object]) -> None:
    """Put the checkpoint's state into a freshly built Simulation of the same case."""
    s = sim.state
    for name in STATE_ARRAYS:
        target, value = getattr(s, name), arrays[f"state/{name}"]
        if target.shape != value.shape:
            raise CaseError(f"checkpoint array state/{name} has shape {value.shape}, the "
                            f"case needs {target.shape}")
        target[...] = value
    s.time, s.step = float(meta["time"]), int(meta["step"])
    if "contacts/impulse" in arrays:  # copies: a retried step must not change the snapshot
        nodes = ContactNodes(*(arrays[f"contacts/{name}"].copy()
                               for name in CONTACT_NODE_ARRAYS),
                             *(arrays[f"contacts/{name}"].copy()
                               if f"contacts/{name}" in arrays else None
                               for name in CONTACT_SITE_ARRAYS))
        s.contacts = ContactState(nodes, *(arrays[f"contacts/{name}"].copy()
                                           for name in CONTACT_ARRAYS))
    else:  # no warm start from a failed attempt's contacts
        s.contacts = None
    sim.last_dt = float(meta["last_dt"])
    sim.unconverged_contact_steps = int(meta["unconverged_contact_steps"])
    sim.retried_steps = int(meta.get("retried_steps", 0))
    sim.wall_work = float(meta.get("wall_work", 0.0))
    sim.contact_dissipation = float(meta.get("contact_dissipation", 0.0))
    sim.gap_correction_work = float(meta.get("gap_correction_work", 0.0))
    sim.integrator_dissipation = float(meta.get("integrator_dissipation", 0.0))
    sim.transfer_dissipation = float(meta.get("transfer_dissipation", 0.0))
    sim.largest_penetration = float(meta.get("largest_penetration", 0.0))
    sim.largest_unsampled_penetration = float(meta.get("largest_unsampled_penetration",
                                                       math.nan))
    sim.dt_factor = float(meta.get("dt_factor", 1.0))
    sim.steps_at_factor = int(meta.get("steps_at_factor", 0))
    sim.grow_after = int(meta.get("grow_after", sim.grow_after))
    sim.just_grown = bool(meta.get("just_grown", sim.just_grown))
    sim.smallest_dt_factor = float(meta.get("smallest_dt_factor", 1.0))
    speed = meta.get("grain_speed")  # (none before session 26: the full reach first)
    sim.grain_speed = None if speed is None else float(speed)
    sim.reach_retries = int(meta.get("reach_retries", 0))
    sim._rows = [meta["last_row"]] if meta["last_row"] is not None else []
    sim._protocol_row = dict(meta["protocol_row"] or {})
    if sim.protocol is not None:
        sim.protocol.load_state_dict(meta["protocol"])
    by_name = {st.name: st for st in sim.solver.steppers.values()}
    for name, direct in dict(meta["linear_solvers"]).items():
        if name in by_name:
            solver = by_name[name].solver
            solver.use_direct = solver.kind == "direct" or (solver.kind == "auto" and direct)


def _plain_json(value: object) -> object:
    """``value`` as it reads back from JSON (tuples → lists)."""
    import json

    return json.loads(json.dumps(value))


def _flatten(table: object, prefix: str = "") -> dict[str, object]:
    if isinstance(table, dict):
        out: dict[str, object] = {}
        for key, item in table.items():
            out.update(_flatten(item, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: table}


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."

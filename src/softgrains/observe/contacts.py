"""Per-contact records (INTERFACE.md ``contacts/``): one row per contact node that carries an
impulse, with the force f = P/Δt split along the normal n (from β into α) and the tangent:
    f_n = f·n,   f_t = f·t (2D, t = (−n_y, n_x)) or ‖f − f_n n‖ (3D)."""

from __future__ import annotations

import numpy as np

from softgrains.contact.detection import node_position
from softgrains.contact.local_law import SLIP, STICK

CONTACT_COLUMNS = ["step", "time", "alpha", "beta", "x", "y", "nx", "ny", "fn", "ft", "status",
                   "gap"]
STATUS_NAMES = {STICK: "stick", SLIP: "slip"}


def contact_records(model, contacts, dt: float) -> dict[str, np.ndarray]:
    """Arrays over the contacts with P ≠ 0: position, normal, force, f_n, f_t, status code,
    α and β body indices, and the boundary gap at the start of the step (gap.py; < 0: an
    estimated overlap; 0 without the gap treatment)."""
    d = model.dim
    if contacts is None or len(contacts.nodes) == 0:
        empty = np.zeros(0)
        return {"position": np.zeros((0, d)), "normal": np.zeros((0, d)),
                "force": np.zeros((0, d)), "fn": empty, "ft": empty,
                "status": np.zeros(0, np.int32), "alpha": np.zeros(0, np.int32),
                "beta": np.zeros(0, np.int32), "gap": empty}
    keep = np.any(contacts.impulse != 0.0, axis=1)
    nodes = contacts.nodes
    normal = nodes.normal[keep]
    force = contacts.impulse[keep] / dt
    fn = np.einsum("ij,ij->i", force, normal)
    if d == 2:
        ft = force[:, 1] * normal[:, 0] - force[:, 0] * normal[:, 1]
    else:
        ft = np.linalg.norm(force - fn[:, None] * normal, axis=1)
    position = (node_position(model.lattice, nodes.node[keep]) if nodes.position is None
                else nodes.position[keep])
    return {"position": position, "normal": normal,
            "force": force, "fn": fn, "ft": ft,
            "status": contacts.status[keep].astype(np.int32),
            "alpha": nodes.alpha[keep].astype(np.int32),
            "beta": nodes.beta[keep].astype(np.int32), "gap": contacts.gap[keep]}


def contact_rows(model, state, records: dict[str, np.ndarray]) -> list[dict[str, object]]:
    """Rows of contacts/contacts_<step>.csv (body names, status as stick/slip)."""
    names = [b.name for b in model.bodies]
    rows = []
    for k in range(records["fn"].size):
        x, n = records["position"][k], records["normal"][k]
        rows.append({"step": state.step, "time": state.time,
                     "alpha": names[records["alpha"][k]], "beta": names[records["beta"][k]],
                     "x": x[0], "y": x[1], "nx": n[0], "ny": n[1], "fn": records["fn"][k],
                     "ft": records["ft"][k],
                     "status": STATUS_NAMES.get(int(records["status"][k]), "open"),
                     "gap": records["gap"][k]})
    return rows


def contact_patch(records: dict[str, np.ndarray], body: int) -> tuple[float, np.ndarray, float]:
    """Load, centre and half-width of the contact patch of ``body`` (one patch assumed):

        F = Σ f_n,I,   x_c = Σ f_n,I x_I / F,   a = 2 √(Σ f_n,I ‖x_I − x_c‖² / F)

    over its contacts (f_n ≥ 0 from the records). a is the half-width of a Hertz (elliptic)
    pressure distribution with the same second moment (VALIDATION.md B8)."""
    on = (records["alpha"] == body) | (records["beta"] == body)
    f = np.maximum(records["fn"][on], 0.0)
    load = float(f.sum())
    d = records["position"].shape[1]
    if load <= 0.0:
        return 0.0, np.full(d, np.nan), 0.0
    x = records["position"][on]
    centre = f @ x / load
    spread = float(f @ np.sum((x - centre) ** 2, axis=1)) / load
    return load, centre, 2.0 * np.sqrt(spread)

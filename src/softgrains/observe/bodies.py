"""Per-body records for bodies.csv: centre of mass, its velocity, contact force, energies.

    x_cm = Σ m_p x_p / Σ m_p,   v_cm = Σ m_p v_p / Σ m_p,
    E_k = ½ Σ m_p |v_p|²,       E_s = Σ V⁰_p W(F_p)
f is the total contact force the body received during the last step (Σ ±P/Δt).
"""

from __future__ import annotations

from softgrains.observe.energies import kinetic_energy, strain_energy

AXES = "xyz"


def body_records(model, state, forces=None) -> list[dict[str, object]]:
    """One row per body for the current state; ``forces`` (B, d): contact force received."""
    rows = []
    for b in model.bodies:
        sl = b.points
        m = model.mass[sl]
        mtot = float(m.sum())
        xc = (m[:, None] * state.x[sl]).sum(axis=0) / mtot
        vc = (m[:, None] * state.v[sl]).sum(axis=0) / mtot
        row: dict[str, object] = {"step": state.step, "time": state.time, "body": b.name,
                                  "kind": b.kind, "mass": mtot}
        for j in range(model.dim):
            row[AXES[j]] = xc[j]
        for j in range(model.dim):
            row["v" + AXES[j]] = vc[j]
        for j in range(model.dim):
            row["f" + AXES[j]] = 0.0 if forces is None else float(forces[b.index, j])
        row["kinetic_energy"] = kinetic_energy(m, state.v[sl])
        row["strain_energy"] = (strain_energy(model.law[sl], state.F[sl], model.lam[sl],
                                              model.mu[sl], model.vol0[sl])
                                if b.deformable else 0.0)
        rows.append(row)
    return rows


def body_columns(dim: int) -> list[str]:
    return (["step", "time", "body", "kind", "mass"] + [AXES[j] for j in range(dim)]
            + ["v" + AXES[j] for j in range(dim)] + ["f" + AXES[j] for j in range(dim)]
            + ["kinetic_energy", "strain_energy"])

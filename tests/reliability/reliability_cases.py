"""Small cases for the reliability tests."""

from __future__ import annotations

import copy
from pathlib import Path

from softgrains import load_case
from softgrains.case import case_to_toml

COMPACTION = {
    # 6 disks pre-compacted (large steps) then compacted: protocol phases, contacts and
    # their warm start, a servo with memory: everything a resume must carry over
    "simulation": {"dt": 1e-4, "steps": 60, "theta": 1.0, "seed": 3},
    "grid": {"cell_size": 2e-3},
    "materials": {"gel": {"young": 1e7, "poisson": 0.4, "density": 100.0}},
    # clearance: one point spacing, the default until session 40 (this deposit runs all
    # 60 steps below stop_stress_ratio, which the resume tests need)
    "sample": {"count": 6, "mean_diameter": 0.01, "polydispersity": 0.2,
               "box_width": 0.02, "material": "gel", "clearance": 1e-3},
    "protocol": {"kind": "uniaxial-compaction", "sigma0": 5e3, "wall_speed": 5.0,
                 "precompaction_dt": 5e-4, "precompaction_speed": 0.5,
                 "precompaction_max_steps": 40, "stop_stress_ratio": 30.0},
    "output": {"interval": 3, "snapshot_interval": 0, "progress": False,
               "checkpoint_interval": 10},
}

FREE_DISK = {
    "simulation": {"dt": 1e-3, "steps": 4},
    "grid": {"cell_size": 0.1, "size": [2.0, 2.0]},
    "materials": {"rubber": {"young": 1e5, "poisson": 0.3, "density": 1000.0}},
    "bodies": [{"shape": "disk", "center": [1.0, 1.0], "radius": 0.3, "material": "rubber",
                "velocity": [0.5, 0.0]}],
    "output": {"interval": 1, "snapshot_interval": 0, "progress": False},
}


def case_dict(base: dict, **sections) -> dict:
    """A deep copy of ``base`` with ``sections`` merged in (``simulation={"dt": 1e-3}``)."""
    data = copy.deepcopy(base)
    for name, values in sections.items():
        data.setdefault(name, {}).update(values)
    return data


def write_case(path: Path, data: dict) -> Path:
    """The case written as a resolved TOML file (what `softgrains run` reads)."""
    path.write_text(case_to_toml(load_case(data)))
    return path

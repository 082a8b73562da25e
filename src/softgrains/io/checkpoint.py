"""Checkpoints: the complete state of a run in one HDF5 file, replaced atomically.

Layout: arrays as datasets (``state/x``, ``contacts/impulse``...), everything else (time,
step, protocol phase, counters, the resolved case TOML) as JSON string attributes, with a
format name and version. The file is written to ``checkpoint.h5.tmp``, flushed to disk and
renamed over ``checkpoint.h5``: a kill at any moment leaves the last good checkpoint.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import h5py
import numpy as np

from softgrains.errors import CaseError
from softgrains.io.summary import to_json, write_bytes_atomic

FORMAT = "softgrains-checkpoint"
VERSION = 1
CHECKPOINT_NAME = "checkpoint.h5"


def write_checkpoint(path: str | Path, arrays: dict[str, np.ndarray],
                     meta: dict[str, object]) -> None:
    """Write ``arrays`` (name → array; '/' makes groups) and ``meta`` (JSON-able) to
    ``path`` atomically: the HDF5 file is built in memory, then written to a temporary file,
    fsynced and renamed over ``path`` (``write_bytes_atomic``)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        f.attrs["meta"] = json.dumps(meta, default=to_json)
        for name, array in arrays.items():
            f.create_dataset(name, data=np.asarray(array))
    write_bytes_atomic(path, buffer.getvalue())


def read_checkpoint(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """(arrays, meta) of a checkpoint; a missing, unreadable or foreign file is a CaseError."""
    path = Path(path)
    if not path.is_file():
        raise CaseError(f"no checkpoint to resume from: '{path}' does not exist (run without "
                        "--resume to start afresh)")
    arrays: dict[str, np.ndarray] = {}
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise CaseError(f"'{path}' is not a softgrains checkpoint")
            version = int(f.attrs.get("version", -1))
            if version != VERSION:
                raise CaseError(f"'{path}' has checkpoint format version {version}; this "
                                f"softgrains reads version {VERSION}")
            meta = json.loads(f.attrs["meta"])

            def visit(name: str, item: object) -> None:
                if isinstance(item, h5py.Dataset):
                    arrays[name] = item[()]

            f.visititems(visit)
    except (OSError, KeyError, ValueError) as error:
        if isinstance(error, CaseError):
            raise
        raise CaseError(f"cannot read checkpoint '{path}': {error}") from None
    return arrays, meta

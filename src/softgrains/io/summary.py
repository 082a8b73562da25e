"""Files replaced atomically (``summary.json``, the ``.pvd`` index) and software versions."""

from __future__ import annotations

import json
import os
import platform
import tempfile
from importlib import metadata
from pathlib import Path

import numpy as np


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``.

    A reader sees either the old file or the complete new one, never a partial write.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as file:
            file.write(data)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    try:  # make the rename itself durable
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass


def to_json(obj: object) -> object:
    """``json.dumps`` fallback for NumPy scalars and arrays and paths."""
    if isinstance(obj, np.ndarray | np.generic):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write a value of type {type(obj).__name__} to JSON")


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Write ``obj`` as indented JSON, atomically; NumPy scalars/arrays become plain values."""
    text = json.dumps(obj, indent=2, default=to_json) + "\n"
    write_bytes_atomic(path, text.encode("utf-8"))


def _distribution_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "unknown"


def software_versions() -> dict[str, str]:
    """Versions of softgrains, Python and the numerical libraries, for provenance."""
    versions = {"softgrains": _distribution_version("softgrains")}
    versions["python"] = platform.python_version()
    for name in ("numpy", "scipy", "numba"):
        versions[name] = _distribution_version(name)
    return versions


def peak_memory_mib() -> float | None:
    """Peak resident memory of this process so far [MiB] (None where the platform does not
    say: no ``resource`` module)."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if platform.system() == "Darwin" else peak / 2**10  # bytes / KiB

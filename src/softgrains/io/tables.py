"""CSV tables written one row at a time (``series.csv``, ``bodies.csv``).

Each row is flushed as soon as it is appended, so a run that is killed keeps every row it
recorded. Floats are written with the shortest representation that reads back to the same
double, so a table round-trips exactly.
"""

from __future__ import annotations

import csv
import io
import numbers
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Self

import numpy as np


def _format_value(value: object) -> str:
    """One cell: ints as ints, floats exact (shortest round-trip repr), strings as they are."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, bool | np.bool_):
        return "1" if value else "0"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str):
        return value
    raise TypeError(f"cannot write a value of type {type(value).__name__} to a CSV table")


class CsvTable:
    """A CSV file with a fixed header; :meth:`append` writes and flushes one row."""

    def __init__(self, path: str | Path, columns: Sequence[str], append: bool = False) -> None:
        """Create (or truncate) ``path`` and write the header ``columns``; with ``append``,
        add rows to an existing table with that header (see :func:`truncate_after_step`)."""
        self.columns = list(columns)
        if not self.columns:
            raise ValueError("a CSV table needs at least one column")
        duplicates = sorted({c for c in self.columns if self.columns.count(c) > 1})
        if duplicates:
            raise ValueError(f"duplicate column names: {', '.join(duplicates)}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("a" if append else "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file, lineterminator="\n")
        if not append:
            self._write(self.columns)

    def append(self, row: Mapping[str, object] | Sequence[object]) -> None:
        """Write one row (a mapping keyed by column, or values in column order) and flush."""
        if isinstance(row, Mapping):
            missing = [c for c in self.columns if c not in row]
            if missing:
                raise ValueError(f"{self.path.name}: row lacks columns: {', '.join(missing)}")
            unknown = [str(k) for k in row if k not in self.columns]
            if unknown:
                raise ValueError(f"{self.path.name}: row has unknown columns: {', '.join(unknown)}")
            values = [row[c] for c in self.columns]
        else:
            values = list(row)
            if len(values) != len(self.columns):
                raise ValueError(
                    f"{self.path.name}: row has {len(values)} values, "
                    f"the table has {len(self.columns)} columns"
                )
        self._write([_format_value(v) for v in values])

    def _write(self, cells: list[str]) -> None:
        self._writer.writerow(cells)
        self._file.flush()

    def close(self) -> None:
        """Close the file (idempotent)."""
        self._file.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def truncate_after_step(path: str | Path, columns: Sequence[str], step: int) -> int:
    """Keep the header and the rows of ``path`` up to ``step`` (column "step"), dropping later
    rows and an unfinished last line (a run killed while writing): a resumed run appends from
    there without duplicates. The file is replaced atomically. Returns the rows kept.

    A table written by an older version, whose header is ``columns`` less some that were
    added since, gains them, empty ("nan") in its rows. Raises ValueError when the header is
    otherwise not ``columns`` (another case wrote the table).
    """
    from softgrains.io.summary import write_bytes_atomic

    path = Path(path)
    text = path.read_text(encoding="utf-8")
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    lines = text.splitlines(keepends=True)
    header = next(csv.reader(lines[:1]), [])
    missing = [c for c in columns if c not in header]
    extra = [c for c in header if c not in columns]
    if missing and not extra and [c for c in columns if c in header] == header:
        lines = _with_columns(lines, header, list(columns))
        header = list(columns)
    if header != list(columns):
        raise ValueError(
            f"{path}: its columns are not those of this case"
            + (f" (missing: {', '.join(missing)})" if missing else "")
            + (f" (not written any more: {', '.join(extra)})" if extra else "")
            + ": it was written by another case or by another version of softgrains; run "
            "without --resume into another --out folder")
    where = header.index("step")
    kept = [lines[0]]
    for line in lines[1:]:
        cells = next(csv.reader([line]), [])
        if len(cells) == len(header) and float(cells[where]) <= step:
            kept.append(line)
    write_bytes_atomic(path, "".join(kept).encode("utf-8"))
    return len(kept) - 1


def _with_columns(lines: list[str], header: list[str], columns: list[str]) -> list[str]:
    """The table's lines with ``columns`` for header: the cells of ``header``'s columns where
    they were, "nan" in the others (rows of another length are kept as they are)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(columns)
    for line in lines[1:]:
        cells = next(csv.reader([line]), [])
        if len(cells) == len(header):
            value = dict(zip(header, cells, strict=True))
            writer.writerow([value.get(c, "nan") for c in columns])
        else:
            out.write(line)
    return out.getvalue().splitlines(keepends=True)


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Read a CSV table into ``{column: array}``.

    Numeric columns become float arrays; a column holding any non-numeric cell (e.g. a body
    ``kind``) stays an array of strings. An unfinished last line (a file read while it is
    being written) is ignored.
    """
    text = Path(path).read_text(encoding="utf-8")
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise ValueError(f"{path}: no header line")
    header, body = rows[0], [r for r in rows[1:] if r]
    for number, row in enumerate(body, start=1):
        if len(row) != len(header):
            raise ValueError(
                f"{path}: data row {number} has {len(row)} cells, expected {len(header)}"
            )
    columns = list(zip(*body, strict=True)) if body else [() for _ in header]
    table: dict[str, np.ndarray] = {}
    for name, cells in zip(header, columns, strict=True):
        try:
            table[name] = np.array(cells, dtype=float)
        except ValueError:
            table[name] = np.array(cells, dtype=str)
    return table

"""Which figures a run folder gets: the series figures of every run (series.py) and, for
compaction runs, the compaction figures (compaction.py), overlaid when there are several."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from softgrains.io.tables import read_table
from softgrains.viz.compaction import (
    DEFAULT_FIELD,
    AnimationQueue,
    FieldChoice,
    plot_compaction,
)
from softgrains.viz.series import plot_run


def is_compaction_run(run_dir: Path) -> bool:
    """True when the run's summary.json records a compaction protocol and its series.csv
    has compaction rows (a run stopped during the pre-compaction has no curve to draw)."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        series = read_table(run_dir / "series.csv")
    except (OSError, ValueError):
        return False
    return (isinstance(summary.get("protocol"), dict) and "phase" in series
            and bool(np.any(series["phase"] == "compaction")))


def draw_figures(run_dirs: Sequence[str | Path], out_dir: str | Path | None = None,
                 field: FieldChoice = DEFAULT_FIELD,
                 animations: AnimationQueue | None = None) -> list[Path]:
    """Draw every figure: RUN/figures/ per run; the compaction figures into ``out_dir``
    (default: RUN/figures for one run), their grains shaded by ``field``, the animations
    by ``animations`` where given (see :func:`plot_compaction`). Returns the files
    written."""
    runs = [Path(r) for r in run_dirs]
    written: list[Path] = []
    for run in runs:
        written += plot_run(run)
    compaction = [r for r in runs if is_compaction_run(r)]
    if compaction:
        target = Path(out_dir) if out_dir is not None else compaction[0] / "figures"
        written += plot_compaction(compaction, target, field, animations)
    return written

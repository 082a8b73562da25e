"""Figures of uniaxial-compaction runs: compaction curves, snapshots and animations.

A run folder holds ``series.csv`` (with ``phase``, ``phi``, ``stress_yy``, ``coordination``,
``wall_gap``...), ``summary.json`` (with a ``protocol`` block: ``sigma0``, ``phi0``, ``h0``,
``label``) and, optionally, ``snapshots/points.pvd`` with its ``.vtu`` files.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import Colormap, Normalize
from matplotlib.figure import Figure

from softgrains.errors import CaseError
from softgrains.io import read_table
from softgrains.io.vtk import read_points_vtu, read_pvd
from softgrains.viz.series import read_run_series

_REQUIRED_COLUMNS = ("time", "phase", "phi", "stress_yy", "coordination", "wall_gap")
_REQUIRED_PROTOCOL = ("sigma0", "phi0", "h0")
_COMPACTION = "compaction"
_DPI = 150
_CMAP = "viridis"
_WALL_COLOR = "0.6"
_STRESS_LABEL = "von Mises stress [Pa]"
_SNAPSHOT_FRACTIONS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
_GIF_SIZE, _GIF_DPI, _GIF_FPS, _GIF_MAX_FRAMES = (4.0, 4.0), 80, 8, 60
_CLIP_PERCENTILE = 99.0
_PHI_LABEL = r"$\phi/\phi_0$ [–]"
_SIGMA_LABEL = r"$\sigma_{yy}/\sigma_0$ [–]"
_SIGMA_AVG_LABEL = r"$\langle\sigma_{yy}\rangle/\sigma_0$ (sample average) [–]"


@dataclass(frozen=True)
class _Run:
    """One compaction run: its series (all rows, by time), protocol and snapshot files."""

    folder: Path
    label: str
    sigma0: float
    phi0: float
    h0: float
    series: dict[str, np.ndarray]
    compaction: np.ndarray  # boolean mask of the compaction rows of ``series``
    snapshots: list[tuple[float, Path]]

    def at(self, column: str, time: float) -> float:
        """``column`` linearly interpolated at ``time``."""
        return float(np.interp(time, self.series["time"], self.series[column]))

    def strain(self) -> np.ndarray:
        """Wall displacement ratio (h0 - wall_gap) / h0 for every row."""
        return (self.h0 - self.series["wall_gap"]) / self.h0

    def compaction_times(self) -> tuple[float, float]:
        """First and last time of the compaction phase."""
        times = self.series["time"][self.compaction]
        return float(times[0]), float(times[-1])


@dataclass(frozen=True)
class _Frame:
    """One snapshot: point centres, square sides, von Mises stress and the wall mask."""

    time: float
    positions: np.ndarray
    side: np.ndarray
    von_mises: np.ndarray
    wall: np.ndarray


def _read_protocol(folder: Path) -> dict[str, object]:
    """The ``protocol`` block of ``folder/summary.json``, checked for the needed keys."""
    path = folder / "summary.json"
    if not path.is_file():
        raise CaseError(f"{folder}: no summary.json (needed for the compaction protocol)")
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise CaseError(f"{path}: not valid JSON ({error})") from error
    protocol = summary.get("protocol") if isinstance(summary, dict) else None
    if not isinstance(protocol, dict):
        raise CaseError(f"{path}: no 'protocol' block (is this a compaction run?)")
    missing = [key for key in _REQUIRED_PROTOCOL if key not in protocol]
    if missing:
        raise CaseError(f"{path}: protocol lacks {', '.join(missing)}")
    for key in _REQUIRED_PROTOCOL:
        value = protocol[key]
        if not isinstance(value, int | float) or isinstance(value, bool) or not value > 0:
            raise CaseError(f"{path}: protocol {key} = {value!r}, expected a positive number")
    return protocol


def _read_series(folder: Path) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """``series.csv`` sorted by time, and the mask of its compaction rows."""
    path = folder / "series.csv"
    series = read_run_series(folder, _REQUIRED_COLUMNS, "compaction ")
    order = np.argsort(series["time"], kind="stable")
    series = {name: values[order] for name, values in series.items()}
    compaction = np.char.strip(series["phase"].astype(str)) == _COMPACTION
    if not compaction.any():
        raise CaseError(f"{path}: no rows with phase '{_COMPACTION}'")
    return series, compaction


def _snapshot_files(folder: Path) -> list[tuple[float, Path]]:
    """``(time, path)`` of the snapshots listed in ``snapshots/points.pvd`` (none if absent)."""
    pvd = folder / "snapshots" / "points.pvd"
    if not pvd.is_file():
        return []
    return [(time, pvd.parent / name) for time, name in read_pvd(pvd)]


def _load_run(folder: str | Path) -> _Run:
    """Read and check one run folder; raises :class:`CaseError` when it is unusable."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CaseError(f"{folder}: not a folder")
    series, compaction = _read_series(folder)
    protocol = _read_protocol(folder)
    label = str(protocol.get("label") or "").strip() or folder.name
    if "contact_converged" in series:  # on_failure = "warn": said in every legend/title
        unconverged = int(np.sum(series["contact_converged"] == 0))
        if unconverged:
            label += f" ({unconverged} unconverged steps)"
    return _Run(
        folder=folder,
        label=label,
        sigma0=float(protocol["sigma0"]),
        phi0=float(protocol["phi0"]),
        h0=float(protocol["h0"]),
        series=series,
        compaction=compaction,
        snapshots=_snapshot_files(folder),
    )


def _read_frame(time: float, path: Path) -> _Frame:
    """Read one snapshot file."""
    if not path.is_file():
        raise CaseError(f"{path}: snapshot listed in points.pvd is missing")
    positions, data = read_points_vtu(path, dim=2)
    missing = [name for name in ("volume", "von_mises") if name not in data]
    if missing:
        raise CaseError(f"{path}: snapshot lacks point data {', '.join(missing)}")
    kinematic = data.get("kinematic", np.zeros(len(positions)))
    return _Frame(
        time=time,
        positions=positions,
        side=np.sqrt(np.clip(data["volume"], 0.0, None)),
        von_mises=data["von_mises"],
        wall=kinematic.astype(int) == 1,
    )


def _nearest_snapshot(run: _Run, time: float) -> tuple[float, Path]:
    """The snapshot of ``run`` nearest in time to ``time``."""
    times = np.array([t for t, _ in run.snapshots])
    return run.snapshots[int(np.argmin(np.abs(times - time)))]


def _slugs(runs: Sequence[_Run]) -> list[str]:
    """File-name-safe, distinct slugs of the run labels."""
    slugs: list[str] = []
    for run in runs:
        base = re.sub(r"[^a-z0-9]+", "-", run.label.lower()).strip("-") or "run"
        slug, count = base, 1
        while slug in slugs:
            count += 1
            slug = f"{base}-{count}"
        slugs.append(slug)
    return slugs


def _stress_norm(frames: Sequence[_Frame]) -> Normalize:
    """A colour scale from 0 to the 99th percentile of the grains' von Mises stress."""
    values = np.concatenate([frame.von_mises[~frame.wall] for frame in frames])
    top = float(np.percentile(values, _CLIP_PERCENTILE)) if values.size else 0.0
    return Normalize(vmin=0.0, vmax=top if top > 0.0 else 1.0)


def _squares(positions: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Corners ``(n, 4, 2)`` of squares of ``side`` centred on ``positions``."""
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    return positions[:, None, :] + side[:, None, None] * corners[None, :, :]


def _draw_points(
    ax: Axes, frame: _Frame, norm: Normalize, cmap: str | Colormap = _CMAP
) -> tuple[PolyCollection, PolyCollection]:
    """Draw the points of ``frame`` as squares: grains by von Mises stress, walls in grey."""
    grains = PolyCollection(
        _squares(frame.positions[~frame.wall], frame.side[~frame.wall]),
        array=frame.von_mises[~frame.wall],
        norm=norm,
        cmap=cmap,
        edgecolors="none",
    )
    walls = PolyCollection(
        _squares(frame.positions[frame.wall], frame.side[frame.wall]),
        facecolors=_WALL_COLOR,
        edgecolors="none",
    )
    ax.add_collection(grains, autolim=False)
    ax.add_collection(walls, autolim=False)
    return grains, walls


def _update_points(collections: tuple[PolyCollection, PolyCollection], frame: _Frame) -> None:
    """Move the squares drawn by :func:`_draw_points` to ``frame``."""
    grains, walls = collections
    grains.set_verts(_squares(frame.positions[~frame.wall], frame.side[~frame.wall]))
    grains.set_array(frame.von_mises[~frame.wall])
    walls.set_verts(_squares(frame.positions[frame.wall], frame.side[frame.wall]))


def _frame_axes(ax: Axes, frames: Sequence[_Frame]) -> None:
    """Equal-aspect axes in metres that hold every square of ``frames``."""
    low = np.min([np.min(f.positions - f.side[:, None] / 2, axis=0) for f in frames], axis=0)
    high = np.max([np.max(f.positions + f.side[:, None] / 2, axis=0) for f in frames], axis=0)
    pad = 0.02 * np.max(high - low)
    ax.set_xlim(low[0] - pad, high[0] + pad)
    ax.set_ylim(low[1] - pad, high[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _state_title(run: _Run, time: float) -> str:
    """φ/φ0 and σ_yy/σ0 of ``run`` at ``time``."""
    phi = run.at("phi", time) / run.phi0
    sigma = run.at("stress_yy", time) / run.sigma0
    return rf"$\phi/\phi_0$ = {phi:.3f}, $\sigma_{{yy}}/\sigma_0$ = {sigma:.3g}"


def _phi_sigma_figure(runs: Sequence[_Run], stress: str = "stress_yy") -> Figure:
    """φ/φ0 against σ/σ0 (log) for the compaction rows, with the φ = 1 limit dashed;
    where series.csv has ``phi_covered`` (the area covered, an overlap counted once), it is
    drawn dotted in the run's colour: the distance between the two is the overlap.
    ``stress``: the top wall's σ_yy, or ``stress_yy_avg`` (the sample's volume average,
    which differs from the top wall's when the side walls carry load by friction)."""
    figure = Figure(figsize=(5.0, 3.8), layout="constrained")
    ax = figure.add_subplot()
    colors = []
    covered_labelled = False
    for run in runs:
        rows = run.compaction & (run.series[stress] > 0.0)
        sigma = run.series[stress][rows] / run.sigma0
        (line,) = ax.plot(sigma, run.series["phi"][rows] / run.phi0, label=run.label)
        colors.append(line.get_color())
        if "phi_covered" in run.series:
            ax.plot(sigma, run.series["phi_covered"][rows] / run.phi0, color=line.get_color(),
                    linestyle=":", linewidth=1.2,
                    label=None if covered_labelled else "area covered (overlap once)")
            covered_labelled = True
    limits = [1.0 / run.phi0 for run in runs]
    several = not np.allclose(limits, limits[0], rtol=1e-6)
    for index, (limit, color) in enumerate(zip(limits, colors, strict=True)):
        if index == 0 or several:
            ax.axhline(
                limit,
                color=color if several else "black",
                linestyle="--",
                linewidth=1.0,
                label=r"$\phi = 1$" if index == 0 else None,
            )
    ax.set_xscale("log")
    ax.set_xlabel(_SIGMA_LABEL if stress == "stress_yy" else _SIGMA_AVG_LABEL)
    ax.set_ylabel(_PHI_LABEL)
    ax.grid(True, which="both", linewidth=0.5, alpha=0.3)
    ax.legend(frameon=False)
    return figure


def _coordination_figure(runs: Sequence[_Run]) -> Figure:
    """Coordination number Z against packing fraction φ over the compaction."""
    figure = Figure(figsize=(5.0, 3.8), layout="constrained")
    ax = figure.add_subplot()
    for run in runs:
        rows = run.compaction
        ax.plot(run.series["phi"][rows], run.series["coordination"][rows], label=run.label)
    ax.set_xlabel(r"packing fraction $\phi$ [–]")
    ax.set_ylabel("coordination number $Z$ [–]")
    ax.grid(True, linewidth=0.5, alpha=0.3)
    ax.legend(frameon=False)
    return figure


def _grain_shapes(run: _Run) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(φ, mean asphericity, its standard deviation over the grains) at each snapshot of
    the compaction that has a grains/grains_<step>.csv (issue #13)."""
    phi, mean, spread = [], [], []
    steps = run.series["step"]
    for path in sorted((run.folder / "grains").glob("grains_*.csv")):
        table = read_table(path)
        if table["step"].size == 0:
            continue
        at = np.flatnonzero(steps == table["step"][0])
        if at.size == 0 or not run.compaction[at[0]]:
            continue
        phi.append(run.series["phi"][at[0]])
        mean.append(float(np.mean(table["asphericity"])))
        spread.append(float(np.std(table["asphericity"])))
    return np.array(phi), np.array(mean), np.array(spread)


def _asphericity_figure(runs: Sequence[_Run]) -> Figure | None:
    """Mean grain asphericity P²/(4πA) against φ over the compaction, with its spread over
    the grains; None when no run has grain shape tables."""
    data = [(run, *_grain_shapes(run)) for run in runs]
    if not any(phi.size for _, phi, _, _ in data):
        return None
    figure = Figure(figsize=(5.0, 3.8), layout="constrained")
    ax = figure.add_subplot()
    for run, phi, mean, spread in data:
        if phi.size:
            line, = ax.plot(phi, mean, marker="o", markersize=3, label=run.label)
            ax.fill_between(phi, mean - spread, mean + spread, alpha=0.2,
                            color=line.get_color(), linewidth=0)
    ax.set_xlabel(r"packing fraction $\phi$ [–]")
    ax.set_ylabel(r"mean asphericity $P^2/(4\pi A)$ [–]")
    ax.set_title("shaded: ± one standard deviation over the grains", fontsize=8)
    ax.grid(True, linewidth=0.5, alpha=0.3)
    ax.legend(frameon=False)
    return figure


def _snapshots_figure(run: _Run) -> Figure:
    """Four snapshots spread over the compaction, on one von Mises colour scale."""
    start, end = run.compaction_times()
    picks = [_nearest_snapshot(run, start + f * (end - start)) for f in _SNAPSHOT_FRACTIONS]
    frames = [_read_frame(time, path) for time, path in picks]
    norm = _stress_norm(frames)
    figure = Figure(figsize=(3.0 * len(frames) + 1.2, 3.8), layout="constrained")
    axes = figure.subplots(1, len(frames), sharex=True, sharey=True, squeeze=False)[0]
    for ax, frame in zip(axes, frames, strict=True):
        grains, _ = _draw_points(ax, frame, norm)
        _frame_axes(ax, frames)
        ax.set_title(f"t = {frame.time:.3g} s\n{_state_title(run, frame.time)}", fontsize=9)
    for ax in axes[1:]:
        ax.set_ylabel("")
    figure.colorbar(grains, ax=list(axes), label=_STRESS_LABEL, extend="max", shrink=0.85)
    figure.suptitle(run.label)
    return figure


def _side_by_side_figure(first: _Run, second: _Run) -> Figure:
    """Two runs at the largest wall strain both reached, on one shared colour scale."""
    target = min(float(np.max(run.strain()[run.compaction])) for run in (first, second))
    frames, titles = [], []
    for run in (first, second):
        rows = np.flatnonzero(run.compaction)
        row = rows[np.argmin(np.abs(run.strain()[rows] - target))]
        frame = _read_frame(*_nearest_snapshot(run, float(run.series["time"][row])))
        strain = (run.h0 - run.at("wall_gap", frame.time)) / run.h0
        phi = run.at("phi", frame.time)
        frames.append(frame)
        titles.append(f"{run.label}\n" + rf"$\varepsilon$ = {strain:.3f}, $\phi$ = {phi:.3f}")
    norm = _stress_norm(frames)
    figure = Figure(figsize=(8.0, 4.2), layout="constrained")
    axes = figure.subplots(1, 2)
    for ax, frame, title in zip(axes, frames, titles, strict=True):
        grains, _ = _draw_points(ax, frame, norm)
        _frame_axes(ax, [frame])
        ax.set_title(title, fontsize=9)
    figure.colorbar(grains, ax=list(axes), label=_STRESS_LABEL, extend="max", shrink=0.85)
    return figure


def _subsample(count: int, limit: int = _GIF_MAX_FRAMES) -> np.ndarray:
    """At most ``limit`` indices spread evenly over ``range(count)``, first and last included."""
    return np.unique(np.linspace(0, count - 1, min(count, limit)).round().astype(int))


def _write_animation(run: _Run, path: Path) -> None:
    """A GIF of the snapshots (at most ~60 frames) on a fixed von Mises colour scale."""
    frames = [_read_frame(*run.snapshots[i]) for i in _subsample(len(run.snapshots))]
    norm = _stress_norm(frames)
    figure = Figure(figsize=_GIF_SIZE, layout="constrained")
    ax = figure.add_subplot()
    collections = _draw_points(ax, frames[0], norm)
    _frame_axes(ax, frames)
    figure.colorbar(collections[0], ax=ax, label=_STRESS_LABEL, extend="max", shrink=0.8)

    def show(index: int) -> tuple[PolyCollection, PolyCollection]:
        frame = frames[index]
        _update_points(collections, frame)
        title = f"{run.label}, t = {frame.time:.3g} s\n{_state_title(run, frame.time)}"
        ax.set_title(title, fontsize=8)
        return collections

    show(0)
    figure.draw_without_rendering()  # lay out once; the frames then keep that layout
    figure.set_layout_engine("none")

    animation = FuncAnimation(figure, show, frames=len(frames), blit=False, repeat=False)
    animation.save(path, writer=PillowWriter(fps=_GIF_FPS), dpi=_GIF_DPI)


def _save(figure: Figure, path: Path, written: list[Path]) -> None:
    """Save ``figure`` to ``path`` and record it."""
    figure.savefig(path, dpi=_DPI)
    written.append(path)


def plot_compaction(run_dirs: Sequence[str | Path], out_dir: str | Path) -> list[Path]:
    """Draw the figures of one or more compaction runs into ``out_dir``.

    Writes ``phi_sigma.png`` (against the top wall's σ_yy), ``phi_sigma_average.png`` (against
    the volume-averaged σ_yy, when series.csv has it) and ``coordination.png`` (all runs
    overlaid), ``asphericity_phi.png`` when the runs wrote grain shapes; for each run with
    snapshots, ``snapshots.png`` and ``animation.gif`` (``snapshots_<slug>.png`` and
    ``animation_<slug>.gif`` when several runs are given); and ``side_by_side.png`` for the
    first two runs with snapshots. Every run is checked before anything is written (an
    unusable folder raises :class:`CaseError`). Returns the paths written.
    """
    if not run_dirs:
        raise CaseError("plot_compaction: no run folders given")
    runs = [_load_run(folder) for folder in run_dirs]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    _save(_phi_sigma_figure(runs), out_dir / "phi_sigma.png", written)
    if all("stress_yy_avg" in run.series for run in runs):
        _save(_phi_sigma_figure(runs, "stress_yy_avg"), out_dir / "phi_sigma_average.png",
              written)
    _save(_coordination_figure(runs), out_dir / "coordination.png", written)
    shapes = _asphericity_figure(runs)
    if shapes is not None:
        _save(shapes, out_dir / "asphericity_phi.png", written)

    several = len(runs) > 1
    with_snapshots = [
        (run, slug) for run, slug in zip(runs, _slugs(runs), strict=True) if run.snapshots
    ]
    for run, slug in with_snapshots:
        name = f"snapshots_{slug}.png" if several else "snapshots.png"
        _save(_snapshots_figure(run), out_dir / name, written)
    if len(with_snapshots) >= 2:
        first, second = (run for run, _ in with_snapshots[:2])
        _save(_side_by_side_figure(first, second), out_dir / "side_by_side.png", written)
    for run, slug in with_snapshots:
        path = out_dir / (f"animation_{slug}.gif" if several else "animation.gif")
        _write_animation(run, path)
        written.append(path)
    return written

"""Figures of uniaxial-compaction runs: compaction curves, snapshots and animations.

A run folder holds ``series.csv`` (with ``phase``, ``phi``, ``stress_yy``, ``coordination``,
``wall_gap``...), ``summary.json`` (with a ``protocol`` block: ``sigma0``, ``phi0``, ``h0``,
``label``) and, optionally, ``snapshots/points.pvd`` with its ``.vtu`` files.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import signal
from collections.abc import Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.colors import Colormap, Normalize
from matplotlib.figure import Figure

from softgrains.errors import CaseError
from softgrains.io import read_table
from softgrains.io.vtk import read_points_vtu, read_pvd
from softgrains.observe.chains import PairForces, body_centres, pair_forces
from softgrains.observe.stress import project_per_grain, von_mises
from softgrains.viz.chains import ChainPanel, chains_figure, distribution_figure
from softgrains.viz.grains import (
    GrainPoints,
    draw_grains,
    draw_walls,
    grain_mesh,
    grain_outlines,
)
from softgrains.viz.series import read_run_series

_REQUIRED_COLUMNS = ("time", "phase", "phi", "stress_yy", "coordination", "wall_gap")
_REQUIRED_PROTOCOL = ("sigma0", "phi0", "h0")
_COMPACTION = "compaction"
_DPI = 150
_CMAP = "viridis"
_SNAPSHOT_FRACTIONS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
_GIF_SIZE, _GIF_DPI, _GIF_FPS, _GIF_MAX_FRAMES = (4.0, 4.0), 100, 8, 60
_MP4_DPI, _MP4_KBPS = 150, 1500  # 60 frames at 8 fps: ~1.4 MB
_CLIP_PERCENTILE = 99.0
SMOOTHING_SPACINGS = 2.0  # smoothing grid in point spacings δ: h for 2 points per cell
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


_FIELD_NAMES = {"von_mises": "von Mises stress [Pa]", "pressure": "pressure [Pa]",
                "J": "J = det F [–]"}


@dataclass(frozen=True)
class FieldChoice:
    """What the grains are shaded with: ``name`` is ``von_mises`` (of the stress tensor),
    ``pressure`` (−tr σ / 3), ``J`` or any scalar point field of the snapshots; ``smoothed``
    draws its least-squares projection per grain (observe/stress.project_per_grain, each
    grain's mean kept) instead of the raw point values."""

    name: str = "von_mises"
    smoothed: bool = True

    def label(self) -> str:
        """The colour bar's label."""
        how = "smoothed per grain" if self.smoothed else "at the points"
        return f"{_FIELD_NAMES.get(self.name, self.name)}, {how}"

    def caption(self) -> str:
        """One sentence on what the shading shows."""
        name = _FIELD_NAMES.get(self.name, self.name).split(" [")[0]
        what = "of the stress tensor" if self.name in ("von_mises", "pressure") else ""
        if self.smoothed:
            return (f"{name}: least-squares fits {what} per grain on a grid of one cell "
                    "(each grain's mean kept; peaks under a cell lowered)").replace("  ", " ")
        return f"{name} at the material points, interpolated linearly between them"


DEFAULT_FIELD = FieldChoice()


@dataclass(frozen=True)
class _Frame:
    """One snapshot: its points grouped into grains, their volumes and the shaded field at
    the points."""

    time: float
    points: GrainPoints
    volume: np.ndarray
    field: np.ndarray

    @property
    def grain(self) -> np.ndarray:
        return ~np.isin(self.points.body, list(self.points.wall_bodies))


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


def _read_points(path: Path) -> tuple[GrainPoints, np.ndarray, dict[str, np.ndarray]]:
    """The points of one snapshot file grouped into grains and walls, their volumes, and
    all their point data."""
    if not path.is_file():
        raise CaseError(f"{path}: snapshot listed in points.pvd is missing")
    positions, data = read_points_vtu(path)
    missing = [name for name in ("volume", "body", "stress", "J") if name not in data]
    if missing:
        raise CaseError(f"{path}: snapshot lacks point data {', '.join(missing)}")
    J = np.clip(data["J"], 1e-12, None)
    volume = np.clip(data["volume"], 0.0, None)
    if "F" in data:
        F = data["F"][:, :2, :2]
    else:  # snapshots written before the deformation gradient was: isotropic cells
        F = np.sqrt(J)[:, None, None] * np.eye(2)[None, :, :]
    body = data["body"].astype(np.int64)
    kinematic = data.get("kinematic", np.zeros(len(positions))).astype(int) == 1
    points = GrainPoints(positions[:, :2], F, np.sqrt(volume / J), body,
                         frozenset(np.unique(body[kinematic]).tolist()))
    return points, volume, data


def _read_frame(time: float, path: Path, field: FieldChoice = DEFAULT_FIELD) -> _Frame:
    """Read one snapshot file and compute the field the grains are shaded with."""
    points, volume, data = _read_points(path)
    if field.name in ("von_mises", "pressure"):
        values = data["stress"]  # (n, 3, 3): σ_zz is the plane-strain stress
    elif field.name in data and data[field.name].ndim == 1:
        values = data[field.name]
    else:
        scalars = sorted(k for k, v in data.items() if v.ndim == 1)
        raise CaseError(f"{path}: no scalar point field {field.name!r}; choose von_mises, "
                        f"pressure or one of {', '.join(scalars)}")
    if field.smoothed and field.name in ("von_mises", "pressure") and "stress_smoothed" in data:
        values = data["stress_smoothed"]  # smoothed by the run on its grid (spacing h)
    elif field.smoothed:
        values = project_per_grain(points.positions, volume, values, points.body,
                                   SMOOTHING_SPACINGS * float(np.median(points.side)))
    if field.name == "von_mises":
        values = von_mises(values)
    elif field.name == "pressure":
        values = -np.trace(values, axis1=1, axis2=2) / 3.0
    return _Frame(time=time, points=points, volume=volume, field=values)


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


def _field_norm(frames: Sequence[_Frame], field: FieldChoice) -> tuple[Normalize, str]:
    """One colour scale for the grains of every frame, and the colour bar's ``extend``:
    von Mises stress from 0 to its 99th percentile; other fields from the 1st to the 99th
    percentile."""
    values = np.concatenate([frame.field[frame.grain] for frame in frames])
    if not values.size:
        return Normalize(vmin=0.0, vmax=1.0), "neither"
    top = float(np.percentile(values, _CLIP_PERCENTILE))
    if field.name == "von_mises":
        low, extend = 0.0, "max"
    else:
        low, extend = float(np.percentile(values, 100.0 - _CLIP_PERCENTILE)), "both"
    return Normalize(vmin=low, vmax=top if top > low else low + 1.0), extend


def _draw_frame(ax: Axes, frame: _Frame, norm: Normalize, cmap: str | Colormap = _CMAP):
    """The grains of ``frame`` filled and shaded, their outlines, the walls; returns the
    filled artist (for the colour bar)."""
    filled = draw_grains(ax, grain_mesh(frame.points), frame.field, norm, cmap)
    draw_walls(ax, frame.points)
    return filled


def _frame_axes(ax: Axes, frames: Sequence[_Frame]) -> None:
    """Equal-aspect axes in metres that hold every square of ``frames``."""
    low = np.min([np.min(f.points.positions - np.sqrt(f.volume)[:, None] / 2, axis=0)
                  for f in frames], axis=0)
    high = np.max([np.max(f.points.positions + np.sqrt(f.volume)[:, None] / 2, axis=0)
                   for f in frames], axis=0)
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


def _snapshots_figure(run: _Run, field: FieldChoice) -> Figure:
    """Four snapshots spread over the compaction, on one colour scale."""
    start, end = run.compaction_times()
    picks = [_nearest_snapshot(run, start + f * (end - start)) for f in _SNAPSHOT_FRACTIONS]
    frames = [_read_frame(time, path, field) for time, path in picks]
    norm, extend = _field_norm(frames, field)
    figure = Figure(figsize=(3.0 * len(frames) + 1.8, 3.8), layout="constrained")
    axes = figure.subplots(1, len(frames), sharex=True, sharey=True, squeeze=False)[0]
    for ax, frame in zip(axes, frames, strict=True):
        filled = _draw_frame(ax, frame, norm)
        _frame_axes(ax, frames)
        ax.set_title(f"t = {frame.time:.3g} s\n{_state_title(run, frame.time)}", fontsize=9)
    for ax in axes[1:]:
        ax.set_ylabel("")
    figure.colorbar(filled, ax=list(axes), label=field.label(), extend=extend, shrink=0.85)
    figure.suptitle(f"{run.label}: {field.caption()}", fontsize=10)
    return figure


def _at_common_strain(runs: Sequence[_Run]) -> list[tuple[float, str]]:
    """For each run, the snapshot time nearest to the largest wall strain all runs reached,
    and a title with the run's label, strain and φ there."""
    target = min(float(np.max(run.strain()[run.compaction])) for run in runs)
    picks = []
    for run in runs:
        times = np.array([t for t, _ in run.snapshots])
        strains = np.array([(run.h0 - run.at("wall_gap", t)) / run.h0 for t in times])
        time = float(times[np.argmin(np.abs(strains - target))])
        strain = (run.h0 - run.at("wall_gap", time)) / run.h0
        title = f"{run.label}\n" + rf"$\varepsilon$ = {strain:.3f}, $\phi$ = " \
            f"{run.at('phi', time):.3f}, " + rf"$\sigma_{{yy}}/\sigma_0$ = " \
            f"{run.at('stress_yy', time) / run.sigma0:.3g}"
        picks.append((time, title))
    return picks


def _side_by_side_figure(first: _Run, second: _Run, field: FieldChoice) -> Figure:
    """Two runs at the largest wall strain both reached, on one shared colour scale."""
    picks = _at_common_strain([first, second])
    frames = [_read_frame(*_nearest_snapshot(run, time), field)
              for run, (time, _) in zip((first, second), picks, strict=True)]
    norm, extend = _field_norm(frames, field)
    figure = Figure(figsize=(8.0, 4.2), layout="constrained")
    axes = figure.subplots(1, 2)
    for ax, frame, (_, title) in zip(axes, frames, picks, strict=True):
        filled = _draw_frame(ax, frame, norm)
        _frame_axes(ax, [frame])
        ax.set_title(title, fontsize=9)
    figure.colorbar(filled, ax=list(axes), label=field.label(), extend=extend, shrink=0.85)
    figure.suptitle(field.caption(), fontsize=8)
    return figure


def _contact_snapshot(run: _Run, time: float) -> Path:
    """The contacts_<step>.vtu written with the points snapshot at ``time``."""
    pvd = run.folder / "snapshots" / "contacts.pvd"
    entries = read_pvd(pvd) if pvd.is_file() else []
    match = [name for t, name in entries if np.isclose(t, time, rtol=1e-12, atol=1e-15)]
    if not match:
        raise CaseError(f"{pvd}: no contact snapshot at t = {time:.6g} s")
    return pvd.parent / match[0]


def _pairs_at(run: _Run, time: float) -> PairForces:
    """The pair forces of the contact snapshot at ``time``."""
    path = _contact_snapshot(run, time)
    positions, data = read_points_vtu(path, dim=2)
    missing = [k for k in ("alpha", "beta", "fn", "status") if k not in data]
    if missing:
        raise CaseError(f"{path}: contact snapshot lacks {', '.join(missing)}")
    return pair_forces(data["alpha"], data["beta"], data["fn"], data["status"], positions,
                       data.get("ft"))


def _chain_panel(run: _Run, time: float, title: str) -> ChainPanel:
    """The force network of ``run`` at its snapshot nearest to ``time``."""
    time, path = _nearest_snapshot(run, time)
    points, volume, _ = _read_points(path)
    return ChainPanel(points, grain_outlines(points), _pairs_at(run, time),
                      body_centres(points.positions, volume, points.body), title)


def _chains_figure(first: _Run, second: _Run) -> Figure:
    """The contact force networks of two runs at the largest wall strain both reached."""
    panels = [_chain_panel(run, time, title) for run, (time, title)
              in zip((first, second), _at_common_strain([first, second]), strict=True)]
    low = np.min([p.points.positions.min(axis=0) for p in panels], axis=0)
    high = np.max([p.points.positions.max(axis=0) for p in panels], axis=0)
    pad = 0.03 * np.max(high - low)
    return chains_figure(panels, (low - pad, high + pad))


def _forces_at_levels(run: _Run, levels: Sequence[float]) -> list[tuple[str, np.ndarray]]:
    """The grain–grain pair forces, each over its snapshot's mean, pooled over the
    snapshots whose σ/σ0 lies within a factor 1.25 of each level (the nearest snapshot
    when none does; the label gives the σ/σ0 range actually pooled)."""
    times = np.array([t for t, _ in run.snapshots])
    sigma = np.array([run.at("stress_yy", t) for t in times]) / run.sigma0
    walls = list(_wall_bodies(run))
    result = []
    for level in levels:
        near = np.flatnonzero((sigma >= level / 1.25) & (sigma <= level * 1.25))
        if near.size == 0:
            near = np.array([int(np.argmin(np.abs(np.log(np.maximum(sigma, 1e-12) / level))))])
        pooled = []
        for t in times[near]:
            pairs = _pairs_at(run, float(t))
            keep = ~(np.isin(pairs.alpha, walls) | np.isin(pairs.beta, walls))
            if np.any(keep):
                pooled.append(pairs.force[keep] / pairs.force[keep].mean())
        low, high = sigma[near].min(), sigma[near].max()
        span = f"{low:.3g}" if np.isclose(low, high, rtol=0.01) else f"{low:.3g}–{high:.3g}"
        result.append((rf"$\sigma/\sigma_0$ = {span}",
                       np.concatenate(pooled) if pooled else np.zeros(0)))
    return result


def _wall_bodies(run: _Run) -> frozenset[int]:
    """The kinematic bodies of a run (from its first snapshot: walls stay walls)."""
    return _read_points(run.snapshots[0][1])[0].wall_bodies


def _distribution_levels(runs: Sequence[_Run]) -> list[float]:
    """Stress levels for P(f/⟨f⟩): 10 and 100 σ0 where all runs reached them, and 80% of
    the largest stress all runs reached unless its window overlaps another level's."""
    reached = min(float(np.max(run.series["stress_yy"][run.compaction])) / run.sigma0
                  for run in runs)
    levels = [level for level in (10.0, 100.0) if level <= reached]
    last = 0.8 * reached
    if last > 1.0 and all(abs(np.log(last / level)) > np.log(1.25 ** 2) for level in levels):
        levels.append(last)
    return levels


def _distribution_figure(runs: Sequence[_Run]) -> Figure | None:
    levels = _distribution_levels(runs)
    if not levels:
        return None
    return distribution_figure([(run.label, _forces_at_levels(run, levels)) for run in runs])


def _subsample(count: int, limit: int = _GIF_MAX_FRAMES) -> np.ndarray:
    """At most ``limit`` indices spread evenly over ``range(count)``, first and last included."""
    return np.unique(np.linspace(0, count - 1, min(count, limit)).round().astype(int))


def _write_animation(run: _Run, stem: Path, field: FieldChoice, mp4: bool | None = None
                     ) -> Path:
    """An animation of the snapshots (at most ~60 frames) on a fixed colour scale, with the
    time, φ/φ0 and σ/σ0 in each frame: ``stem``.mp4 when ffmpeg is available (matplotlib's
    writer; ``mp4`` decides where given), ``stem``.gif otherwise. Returns the file
    written."""
    frames = [_read_frame(*run.snapshots[i], field) for i in _subsample(len(run.snapshots))]
    norm, extend = _field_norm(frames, field)
    figure = Figure(figsize=_GIF_SIZE, layout="constrained")
    ax = figure.add_subplot()
    filled = _draw_frame(ax, frames[0], norm)
    _frame_axes(ax, frames)
    figure.colorbar(filled, ax=ax, label=field.label(), extend=extend, shrink=0.8)

    def show(index: int) -> list:
        frame = frames[index]
        for artist in [*ax.collections, *ax.patches]:
            artist.remove()
        _draw_frame(ax, frame, norm)
        title = f"{run.label}, t = {frame.time:.3g} s\n{_state_title(run, frame.time)}"
        ax.set_title(title, fontsize=8)
        return []

    show(0)
    figure.draw_without_rendering()  # lay out once; the frames then keep that layout
    figure.set_layout_engine("none")

    animation = FuncAnimation(figure, show, frames=len(frames), blit=False, repeat=False)
    if FFMpegWriter.isAvailable() if mp4 is None else mp4:
        path = stem.with_suffix(".mp4")
        animation.save(path, writer=FFMpegWriter(fps=_GIF_FPS, bitrate=_MP4_KBPS),
                       dpi=_MP4_DPI)
    else:
        path = stem.with_suffix(".gif")
        animation.save(path, writer=PillowWriter(fps=_GIF_FPS), dpi=_GIF_DPI)
    return path


def _animation_job(folder: str, stem: str, field: FieldChoice, mp4: bool) -> str:
    """The animation of the run in ``folder`` (in a worker process of
    :func:`_start_animations` or an :class:`AnimationQueue`; ``mp4`` as the caller
    decided). SIGTERM is ignored while it draws: a worker it killed would break the pool
    and with it the runs still going in the pool's other workers, which stop cleanly on
    SIGTERM (cli.py forwards it to them)."""
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        return str(_write_animation(_load_run(folder), Path(stem), field, mp4))
    finally:
        signal.signal(signal.SIGTERM, previous)


def _start_animations(jobs: list[tuple[_Run, Path]], field: FieldChoice
                      ) -> tuple[ProcessPoolExecutor | None, list[Future] | None]:
    """Each run's animation (``jobs``: run, file stem) started in its own process where
    there are several and more than one core: each takes ~8 s for the reference
    compaction's 34 snapshots, drawn in parallel with the other figures. (None, None)
    where they are drawn in this process instead (one animation, one core, or a daemonic
    process, which may not have children)."""
    workers = min(len(jobs), os.cpu_count() or 1)
    if workers < 2 or multiprocessing.current_process().daemon:
        return None, None
    pool = ProcessPoolExecutor(max_workers=workers,
                               mp_context=multiprocessing.get_context("spawn"))
    mp4 = FFMpegWriter.isAvailable()
    return pool, [pool.submit(_animation_job, str(run.folder), str(stem), field, mp4)
                  for run, stem in jobs]


class AnimationQueue:
    """Animations drawn in a caller's process pool as the runs finish (``softgrains run A
    B``: a finished run's animation is drawn on the core it frees while the other runs go
    on). Each is drawn under a provisional name in ``out_dir`` and renamed by
    :func:`plot_compaction`, which decides the final names once every run is known (an
    animation depends only on its own run and the field, not on the other runs)."""

    def __init__(self, pool: ProcessPoolExecutor, out_dir: str | Path,
                 field: FieldChoice = DEFAULT_FIELD) -> None:
        self.pool, self.out_dir, self.field = pool, Path(out_dir), field
        self.mp4 = FFMpegWriter.isAvailable()
        self._started: dict[Path, Future] = {}
        self._count = 0  # drawings started: each gets its own provisional name

    def start(self, folder: str | Path) -> bool:
        """Start the animation of the finished run in ``folder`` unless it is started or
        unusable (no compaction rows, no snapshots: then :func:`plot_compaction` decides,
        and reports what is wrong). Returns whether it is under way."""
        if Path(folder).resolve() in self._started:
            return True
        try:
            run = _load_run(folder)
        except CaseError:
            return False
        if run.snapshots:
            self.add(run)
        return bool(run.snapshots)

    def add(self, run: _Run) -> None:
        """Start the animation of ``run`` (loaded, with snapshots) unless it is started."""
        key = run.folder.resolve()
        if key in self._started:
            return
        self.out_dir.mkdir(parents=True, exist_ok=True)
        provisional = self.out_dir / f".animation-{self._count}.partial"
        self._count += 1
        self._started[key] = self.pool.submit(_animation_job, str(run.folder),
                                              str(provisional), self.field, self.mp4)

    def finish(self, run: _Run, stem: Path) -> Path:
        """Wait for the animation of ``run`` (started now if it was not) and move it to
        ``stem`` with its format's suffix; returns the file."""
        self.add(run)
        drawn = Path(self._started.pop(run.folder.resolve()).result())
        return drawn.replace(stem.with_suffix(drawn.suffix))

    def close(self) -> None:
        """Cancel the animations not yet started and remove those no figure claimed (a run
        :func:`plot_compaction` was not given, or an interrupted command), once drawn."""
        for future in self._started.values():
            if future.cancel():
                continue
            try:
                Path(future.result()).unlink(missing_ok=True)
            except Exception:  # noqa: BLE001 - a failed, unclaimed drawing leaves no file
                pass
        self._started.clear()


def _save(figure: Figure, path: Path, written: list[Path]) -> None:
    """Save ``figure`` to ``path`` and record it."""
    figure.savefig(path, dpi=_DPI)
    written.append(path)


def plot_compaction(run_dirs: Sequence[str | Path], out_dir: str | Path,
                    field: FieldChoice = DEFAULT_FIELD,
                    animations: AnimationQueue | None = None) -> list[Path]:
    """Draw the figures of one or more compaction runs into ``out_dir``.

    Writes ``phi_sigma.png`` (against the top wall's σ_yy), ``phi_sigma_average.png`` (against
    the volume-averaged σ_yy, when series.csv has it) and ``coordination.png`` (all runs
    overlaid), ``asphericity_phi.png`` when the runs wrote grain shapes; for each run with
    snapshots, ``snapshots.png`` (the grains shaded by ``field``) and an animation
    (``animation.mp4`` with ffmpeg, else ``animation.gif``; ``snapshots_<slug>.png`` and
    ``animation_<slug>.*`` when several runs are given) and ``force_distribution.png``
    (P(f/⟨f⟩) at a few stress levels); for the first two runs with snapshots,
    ``side_by_side.png`` and ``force_chains.png`` at the same wall strain. Every run is
    checked before anything is written (an unusable folder raises :class:`CaseError`).
    The animations are drawn by ``animations`` where given (some perhaps already drawn;
    its field must be ``field``), else in processes of their own (:func:`_start_animations`).
    Returns the paths written.
    """
    if animations is not None and animations.field != field:
        raise ValueError(f"plot_compaction: the animations are shaded by "
                         f"{animations.field.name}, the figures by {field.name}")
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
    jobs = [(run, out_dir / (f"animation_{slug}" if several else "animation"))
            for run, slug in with_snapshots]
    if animations is not None:  # (the runs loaded here: not read again to start them)
        for run, _ in jobs:
            animations.add(run)
        _snapshot_figures(runs, with_snapshots, out_dir, field, written)
        return written + [animations.finish(run, stem) for run, stem in jobs]
    pool, started = _start_animations(jobs, field)
    try:
        _snapshot_figures(runs, with_snapshots, out_dir, field, written)
        if started is None:
            written += [_write_animation(run, stem, field) for run, stem in jobs]
        else:
            written += [Path(future.result()) for future in started]
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return written


def _snapshot_figures(runs: list[_Run], with_snapshots: list[tuple[_Run, str]],
                      out_dir: Path, field: FieldChoice, written: list[Path]) -> None:
    """The figures drawn from the snapshots, the animations aside (see
    :func:`plot_compaction`)."""
    several = len(runs) > 1
    for run, slug in with_snapshots:
        name = f"snapshots_{slug}.png" if several else "snapshots.png"
        _save(_snapshots_figure(run, field), out_dir / name, written)
    with_contacts = [run for run, _ in with_snapshots
                     if (run.folder / "snapshots" / "contacts.pvd").is_file()]
    if with_contacts:
        distribution = _distribution_figure(with_contacts)
        if distribution is not None:
            _save(distribution, out_dir / "force_distribution.png", written)
    if len(with_snapshots) >= 2:
        first, second = (run for run, _ in with_snapshots[:2])
        _save(_side_by_side_figure(first, second, field), out_dir / "side_by_side.png",
              written)
        if first in with_contacts and second in with_contacts:
            _save(_chains_figure(first, second), out_dir / "force_chains.png", written)

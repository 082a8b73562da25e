"""plot_compaction draws the curves, snapshots and animations of compaction runs."""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from matplotlib.animation import FFMpegWriter
from matplotlib.image import imread
from PIL import Image

from softgrains.errors import CaseError
from softgrains.io.vtk import PvdSeries, write_points_vtu
from softgrains.viz.compaction import (
    AnimationQueue,
    FieldChoice,
    _load_run,
    _phi_sigma_figure,
    _side_by_side_figure,
    _start_animations,
    _subsample,
    plot_compaction,
)

COLUMNS = [
    "step", "time", "phase", "phi", "stress_yy", "stress_xx", "stress_mean_avg", "wall_gap",
    "coordination", "coordination_walls", "rattler_fraction",
]  # fmt: skip
H0, WIDTH, END_TIME = 1.0, 1.0, 1.0


def _points(gap: float, stiffness: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Two disks of grid points squashed to ``gap``, between a bottom and a top wall row;
    their stress is uniaxial (σ_xx = its von Mises stress)."""
    spacing = 0.1
    grid = np.stack(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3)), axis=-1).reshape(-1, 2)
    disk = spacing * grid[np.hypot(grid[:, 0], grid[:, 1]) <= 2.2]
    squash = gap / H0
    grains = np.concatenate([disk + [0.3, 0.25], disk + [0.7, 0.75]]) * [1.0, squash]
    wall_x = np.arange(0.05, WIDTH, spacing)
    walls = np.concatenate(
        [np.stack([wall_x, np.full_like(wall_x, -0.05)], axis=1),
         np.stack([wall_x, np.full_like(wall_x, gap + 0.05)], axis=1)]
    )  # fmt: skip
    positions = np.concatenate([grains, walls])
    n_grains, n = len(grains), len(positions)
    kinematic = np.r_[np.zeros(n_grains, int), np.ones(n - n_grains, int)]
    von_mises = np.r_[stiffness * (1.0 - squash) * (1.0 + grains[:, 1]), np.zeros(n - n_grains)]
    stress = np.zeros((n, 3, 3))
    stress[:, 0, 0] = von_mises
    point_data = {
        "body": np.r_[np.repeat([0, 1], n_grains // 2), np.full(n - n_grains, 2)],
        "kinematic": kinematic,
        "volume": np.full(n, spacing**2 * squash),
        "stress": stress,
        "von_mises": von_mises,
        "J": np.r_[np.full(n_grains, squash), np.ones(n - n_grains)],
    }
    return positions, point_data


def _contacts(gap: float, stiffness: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Contact records of ``_points``' frame: three nodes between the grains (bodies 0 and
    1), two with each wall row (body 2), forces growing with the squash."""
    load = stiffness * (1.0 - gap / H0) + 1.0
    positions = np.array([[0.5, 0.45], [0.5, 0.5], [0.5, 0.55], [0.3, 0.0], [0.7, gap]])
    return positions, {"alpha": np.array([0, 0, 0, 0, 1]), "beta": np.array([1, 1, 1, 2, 2]),
                       "fn": load * np.array([1.0, 2.0, 1.0, 1.5, 0.5]),
                       "status": np.array([1, 2, 1, 1, 2])}


def _make_run(
    folder: Path,
    label: str | None,
    *,
    final_gap: float = 0.7,
    snapshots: int = 7,
    stiffness: float = 1e4,
    protocol: bool = True,
) -> Path:
    """A synthetic run folder: series.csv, summary.json and (optionally) snapshots."""
    folder.mkdir(parents=True)
    times = np.linspace(0.0, END_TIME, 21)
    start = times[4]
    with (folder / "series.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(COLUMNS)
        for step, time in enumerate(times):
            s = max(0.0, (time - start) / (END_TIME - start))
            gap = H0 - s * (H0 - final_gap)
            phi = 0.6 * H0 / gap
            sigma = stiffness * (1e-3 + (H0 - gap) ** 2)
            phase = "precompaction" if time < start else "compaction"
            row = [step, time, phase, phi, sigma, 0.5 * sigma, 0.75 * sigma, gap, 3 + s, s, 0.1]
            writer.writerow(row)
    summary: dict[str, object] = {"steps": 21}
    if protocol:
        summary["protocol"] = {"sigma0": 1e3, "phi0": 0.6, "h0": H0, "friction": 0.3}
        if label is not None:
            summary["protocol"]["label"] = label
    (folder / "summary.json").write_text(json.dumps(summary))
    if snapshots:
        pvd = PvdSeries(folder / "snapshots" / "points.pvd")
        contacts = PvdSeries(folder / "snapshots" / "contacts.pvd")
        for index, time in enumerate(np.linspace(start, END_TIME, snapshots)):
            s = (time - start) / (END_TIME - start)
            gap = H0 - s * (H0 - final_gap)
            name = f"points_{index:08d}.vtu"
            write_points_vtu(folder / "snapshots" / name, *_points(gap, stiffness))
            pvd.add(time, name)
            name = f"contacts_{index:08d}.vtu"
            write_points_vtu(folder / "snapshots" / name, *_contacts(gap, stiffness))
            contacts.add(time, name)
    return folder


@pytest.fixture(autouse=True)
def _gif_animations(monkeypatch):
    """The tests below expect GIF animations: what a machine without ffmpeg writes."""
    monkeypatch.setattr(FFMpegWriter, "isAvailable", classmethod(lambda cls: False))


@pytest.mark.skipif(not FFMpegWriter.isAvailable(), reason="ffmpeg is not installed")
def test_with_ffmpeg_the_animation_is_an_mp4(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.undo()
    run = _make_run(tmp_path / "run_a", None, snapshots=3)
    paths = plot_compaction([run], tmp_path / "out")
    assert paths[-1].name == "animation.mp4" and 1000 < paths[-1].stat().st_size < 10e6


def _assert_png(path: Path) -> None:
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = imread(path)
    assert image.shape[0] > 200 and image.shape[1] > 200


def test_two_runs_write_every_figure(tmp_path: Path) -> None:
    soft = _make_run(tmp_path / "soft", "Soft μ=0.3", stiffness=1e4)
    stiff = _make_run(tmp_path / "stiff", "Stiff", final_gap=0.8, snapshots=5, stiffness=5e4)
    out = tmp_path / "figures"
    paths = plot_compaction([soft, stiff], out)
    names = [path.name for path in paths]
    assert names == [
        "phi_sigma.png",
        "coordination.png",
        "snapshots_soft-0-3.png",
        "snapshots_stiff.png",
        "side_by_side.png",
        "force_chains.png",
        "animation_soft-0-3.gif",
        "animation_stiff.gif",
    ]
    for path in paths:
        assert path.parent == out and path.is_file()
        if path.suffix == ".png":
            _assert_png(path)
    assert all(path.stat().st_size < 10e6 for path in paths)  # issue #13: animations < 10 MB
    with Image.open(out / "animation_soft-0-3.gif") as gif:
        assert gif.format == "GIF"
        assert gif.n_frames == 7
        assert gif.size == (400, 400)
    with Image.open(out / "animation_stiff.gif") as gif:
        assert gif.n_frames == 5


def test_animations_drawn_in_worker_processes_are_those_drawn_here(tmp_path: Path,
                                                                    monkeypatch) -> None:
    """Several runs' animations are drawn in parallel processes (one core: here, one after
    the other): the same files byte for byte, in the same format (GIF here: the format is
    decided in this process, where the fixture has hidden ffmpeg)."""
    soft = _make_run(tmp_path / "soft", "Soft μ=0.3", stiffness=1e4)
    stiff = _make_run(tmp_path / "stiff", "Stiff", final_gap=0.8, snapshots=5, stiffness=5e4)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    parallel = plot_compaction([soft, stiff], tmp_path / "parallel")
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    serial = plot_compaction([soft, stiff], tmp_path / "serial")
    assert [p.name for p in parallel] == [p.name for p in serial]
    for a, b in zip(parallel, serial, strict=True):
        if a.name.startswith("animation"):
            assert a.suffix == ".gif" and a.read_bytes() == b.read_bytes()
    jobs = [(_load_run(soft), tmp_path / "a"), (_load_run(stiff), tmp_path / "b")]
    assert _start_animations(jobs, FieldChoice()) == (None, None)  # one core: here
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    pool, started = _start_animations(jobs, FieldChoice())
    assert pool is not None and len(started) == 2
    assert [Path(f.result()).name for f in started] == ["a.gif", "b.gif"]
    pool.shutdown()


def test_animations_queued_as_runs_finish_are_the_serial_ones(tmp_path: Path,
                                                               monkeypatch) -> None:
    """`softgrains run A B`: a run's animation is started in the runs' pool as soon as the
    run ends (AnimationQueue.start), before the other runs are known; plot_compaction then
    names it and draws the rest. The files are those of the serial drawing byte for byte,
    nothing provisional is left behind, and an animation no figure claims is removed."""
    soft = _make_run(tmp_path / "soft", "Soft μ=0.3", stiffness=1e4)
    stiff = _make_run(tmp_path / "stiff", "Stiff", final_gap=0.8, snapshots=5, stiffness=5e4)
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    serial = plot_compaction([soft, stiff], tmp_path / "serial")
    out = tmp_path / "queued"
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=2, mp_context=spawn) as pool:
        queue = AnimationQueue(pool, out)
        queue.mp4 = False  # as decided in the serial drawing, where ffmpeg is hidden
        assert queue.start(stiff) and queue.start(stiff)  # the second call: already started
        assert not queue.start(tmp_path / "missing")  # unusable: left to plot_compaction
        queued = plot_compaction([soft, stiff], out, animations=queue)
        assert [p.name for p in queued] == [p.name for p in serial]
        for a, b in zip(queued, serial, strict=True):
            if a.name.startswith("animation"):
                assert a.read_bytes() == b.read_bytes()
        assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
        queue.start(soft)  # a drawing nobody claims
        queue.close()
        assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
        with pytest.raises(ValueError, match="shaded by"):
            plot_compaction([soft], out, FieldChoice("pressure"), animations=queue)


def test_one_run_uses_plain_names_and_folder_label(tmp_path: Path) -> None:
    run = _make_run(tmp_path / "run_a", None, snapshots=3)
    assert _load_run(run).label == "run_a"
    paths = plot_compaction([run], tmp_path / "out")
    assert [path.name for path in paths] == [
        "phi_sigma.png",
        "coordination.png",
        "snapshots.png",
        "animation.gif",
    ]


def test_animation_frames_are_subsampled() -> None:
    assert list(_subsample(5)) == [0, 1, 2, 3, 4]
    picks = _subsample(500)
    assert len(picks) == 60 and picks[0] == 0 and picks[-1] == 499
    assert np.all(np.diff(picks) > 0)


def test_phi_sigma_axes(tmp_path: Path) -> None:
    runs = [
        _load_run(_make_run(tmp_path / "a", "A", snapshots=0)),
        _load_run(_make_run(tmp_path / "b", "B", snapshots=0)),
    ]
    figure = _phi_sigma_figure(runs)
    (ax,) = figure.axes
    assert ax.get_xscale() == "log"
    assert "sigma_{yy}/\\sigma_0" in ax.get_xlabel()
    assert "phi/\\phi_0" in ax.get_ylabel()
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels[:2] == ["A", "B"] and "phi = 1" in labels[2]
    limit = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert len(limit) == 1  # same phi0: one limit line
    assert limit[0].get_ydata()[0] == pytest.approx(1 / 0.6)
    # only the compaction rows are drawn (17 of 21)
    assert len(ax.get_lines()[0].get_xdata()) == 17


def _add_column(folder: Path, name: str, scale: float, of: str) -> None:
    """Append column ``name`` = ``scale`` × column ``of`` to a synthetic run's series.csv."""
    path = folder / "series.csv"
    with path.open(newline="") as file:
        rows = list(csv.reader(file))
    rows[0].append(name)
    for row in rows[1:]:
        row.append(str(scale * float(row[COLUMNS.index(of)])))
    with path.open("w", newline="") as file:
        csv.writer(file).writerows(rows)


def test_phi_sigma_against_the_averaged_stress_when_the_series_has_it(tmp_path: Path) -> None:
    """A series with stress_yy_avg also gets phi_sigma_average.png, φ/φ0 against it."""
    folder = _make_run(tmp_path / "a", "A", snapshots=0)
    _add_column(folder, "stress_yy_avg", 0.8, "stress_yy")
    paths = plot_compaction([folder], tmp_path / "out")
    assert [p.name for p in paths] == ["phi_sigma.png", "phi_sigma_average.png",
                                       "coordination.png"]
    run = _load_run(folder)
    (top,) = _phi_sigma_figure([run]).axes
    (average,) = _phi_sigma_figure([run], "stress_yy_avg").axes
    assert "sample average" in average.get_xlabel()
    assert average.get_lines()[0].get_xdata() == pytest.approx(
        0.8 * top.get_lines()[0].get_xdata())


def test_phi_sigma_draws_the_covered_area_dotted(tmp_path: Path) -> None:
    """With a phi_covered column the figure adds a dotted curve per run in its colour."""
    folder = _make_run(tmp_path / "a", "A", snapshots=0)
    _add_column(folder, "phi_covered", 0.97, "phi")
    (ax,) = _phi_sigma_figure([_load_run(folder)]).axes
    solid, dotted = ax.get_lines()[:2]
    assert dotted.get_linestyle() == ":" and dotted.get_color() == solid.get_color()
    assert dotted.get_ydata() == pytest.approx(0.97 * solid.get_ydata())
    assert "area covered" in [t.get_text() for t in ax.get_legend().get_texts()][1]


def test_side_by_side_shares_one_colour_scale(tmp_path: Path) -> None:
    soft = _load_run(_make_run(tmp_path / "soft", "Soft", stiffness=1e4))
    stiff = _load_run(_make_run(tmp_path / "stiff", "Stiff", final_gap=0.8, stiffness=5e4))
    figure = _side_by_side_figure(soft, stiff, FieldChoice())
    panels = [ax for ax in figure.axes if ax.get_title()]
    assert len(panels) == 2
    grains = [next(c for c in ax.collections if c.get_array() is not None) for ax in panels]
    assert grains[0].norm is grains[1].norm
    assert grains[0].get_clim() == grains[1].get_clim()
    assert grains[0].get_clim()[1] > 0
    # the same strain: the stiff run stops at 0.2, so both panels are near strain 0.2
    for ax in panels:
        assert "Soft" in ax.get_title() or "Stiff" in ax.get_title()
        assert "0.200" in ax.get_title()


def test_run_without_snapshots_gets_only_curves(tmp_path: Path) -> None:
    bare = _make_run(tmp_path / "bare", "bare", snapshots=0)
    paths = plot_compaction([bare], tmp_path / "out")
    assert [path.name for path in paths] == ["phi_sigma.png", "coordination.png"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "coordination.png",
        "phi_sigma.png",
    ]
    # with another run that has snapshots: no side-by-side (only one run has them)
    full = _make_run(tmp_path / "full", "full", snapshots=3)
    names = [path.name for path in plot_compaction([bare, full], tmp_path / "out2")]
    assert names == [
        "phi_sigma.png",
        "coordination.png",
        "snapshots_full.png",
        "animation_full.gif",
    ]


def test_missing_series_is_a_case_error(tmp_path: Path) -> None:
    folder = tmp_path / "empty"
    folder.mkdir()
    with pytest.raises(CaseError, match=r"empty: no series\.csv"):
        plot_compaction([folder], tmp_path / "out")


def test_missing_protocol_is_a_case_error(tmp_path: Path) -> None:
    good = _make_run(tmp_path / "good", "good", snapshots=0)
    folder = _make_run(tmp_path / "noproto", "x", snapshots=0, protocol=False)
    with pytest.raises(CaseError, match=r"noproto.*no 'protocol'"):
        plot_compaction([good, folder], tmp_path / "out")
    assert not (tmp_path / "out").exists()  # nothing written before all runs are checked


def test_missing_phi_column_is_a_case_error(tmp_path: Path) -> None:
    folder = tmp_path / "nophi"
    folder.mkdir()
    (folder / "series.csv").write_text("step,time,phase\n0,0.0,compaction\n")
    with pytest.raises(CaseError, match=r"nophi.*missing compaction columns phi, stress_yy"):
        plot_compaction([folder], tmp_path / "out")


def test_a_run_with_unconverged_steps_says_so_in_its_label(tmp_path: Path) -> None:
    """on_failure = "warn" runs: the number of unconverged steps (contact_converged = 0)
    follows the run's name into every legend and title."""
    folder = _make_run(tmp_path / "a", "A", snapshots=0)
    _add_column(folder, "contact_converged", 0.0, "phi")  # every row unconverged
    run = _load_run(folder)
    assert run.label == f"A ({len(run.series['phi'])} unconverged steps)"
    labels = [t.get_text() for t in _phi_sigma_figure([run]).axes[0].get_legend().get_texts()]
    assert labels[0] == run.label
    clean = _make_run(tmp_path / "b", "B", snapshots=0)
    _add_column(clean, "contact_converged", 1.0, "phi")  # φ > 0: converged rows
    assert _load_run(clean).label == "B"


def test_stressed_runs_get_the_force_distribution_and_any_field(tmp_path: Path) -> None:
    """Runs that pass 10 σ0 get P(f/⟨f⟩) (issue #13, item 3); the grains can be shaded
    by any scalar point field, smoothed or raw, and an unknown field is a case error."""
    soft = _make_run(tmp_path / "soft", "Soft", stiffness=1e6, snapshots=4)
    stiff = _make_run(tmp_path / "stiff", "Stiff", stiffness=2e6, snapshots=4)
    names = [p.name for p in plot_compaction([soft, stiff], tmp_path / "out")]
    assert "force_distribution.png" in names and "force_chains.png" in names
    run = _load_run(soft)
    raw = _side_by_side_figure(run, run, FieldChoice("J", smoothed=False))
    assert "J = det F" in raw.axes[-1].get_ylabel() and "at the points" in raw.axes[-1].get_ylabel()
    assert "J = det F at the material points" in raw.get_suptitle()
    bar = next(c.colorbar for ax in raw.axes for c in ax.collections
               if getattr(c, "colorbar", None) is not None)
    assert bar.extend == "both"  # J is clipped at both ends (1st and 99th percentiles)
    with pytest.raises(CaseError, match="no scalar point field 'nope'.*von_mises"):
        _side_by_side_figure(run, run, FieldChoice("nope"))

"""Figures of the contact force network (issue #13, item 3): force chains over the grains'
outlines, and the distribution of the normal forces P(f/⟨f⟩)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from softgrains.observe.chains import PairForces, chain_segments, force_distribution
from softgrains.viz.grains import GrainPoints, draw_walls

_WIDEST = 6.0  # line width (points) of the largest pair force of a figure
_THINNEST = 0.3
_CHAIN_CMAP = "inferno_r"
_GRAIN_FILL = "0.9"
_SLIP_COLOR = "tab:cyan"
DISTRIBUTION_BINS = np.linspace(0.0, 4.0, 17)


@dataclass(frozen=True)
class ChainPanel:
    """One panel: the frame's points, its grains' outlines, pair forces, body centres and a
    title."""

    points: GrainPoints
    outlines: list[np.ndarray]
    pairs: PairForces
    centres: dict[int, np.ndarray]
    title: str


def chain_widths(force: np.ndarray, largest: float) -> np.ndarray:
    """Line widths proportional to the pair forces: F / F_max × the widest line (points),
    at least a hairline."""
    if largest <= 0.0:
        return np.full(force.shape, _THINNEST)
    return np.maximum(_WIDEST * force / largest, _THINNEST)


def draw_chains(ax: Axes, panel: ChainPanel, norm: Normalize) -> LineCollection:
    """The grains as light outlines, the walls, and one segment per pressing pair with its
    width and colour from the pair's normal force; slipping pairs (most of their force on
    slipping nodes) are marked at their contact point."""
    ax.add_collection(PolyCollection(panel.outlines, facecolors=_GRAIN_FILL,
                                     edgecolors="0.5", linewidths=0.4), autolim=False)
    draw_walls(ax, panel.points)
    pairs = panel.pairs
    segments = chain_segments(pairs, panel.centres, set(panel.points.wall_bodies))
    order = np.argsort(pairs.force)  # the strongest on top
    lines = LineCollection(segments[order], linewidths=chain_widths(pairs.force[order],
                                                                    norm.vmax),
                           array=pairs.force[order], cmap=_CHAIN_CMAP, norm=norm,
                           capstyle="round")
    ax.add_collection(lines, autolim=False)
    slipping = pairs.slip_share > 0.5
    if np.any(slipping):
        ax.plot(pairs.point[slipping, 0], pairs.point[slipping, 1], linestyle="none",
                marker="o", markersize=3.5, markerfacecolor="none",
                markeredgecolor=_SLIP_COLOR, markeredgewidth=1.0)
    return lines


def chains_figure(panels: Sequence[ChainPanel], limits: tuple[np.ndarray, np.ndarray]
                  ) -> Figure:
    """The force networks of ``panels`` side by side on one force scale and width scale."""
    largest = max((float(p.pairs.force.max()) for p in panels if p.pairs.force.size),
                  default=1.0)
    norm = Normalize(vmin=0.0, vmax=largest)
    figure = Figure(figsize=(4.0 * len(panels) + 1.0, 4.4), layout="constrained")
    axes = figure.subplots(1, len(panels), squeeze=False)[0]
    lines = None
    for ax, panel in zip(axes, panels, strict=True):
        lines = draw_chains(ax, panel, norm)
        ax.set_xlim(limits[0][0], limits[1][0])
        ax.set_ylim(limits[0][1], limits[1][1])
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_title(panel.title, fontsize=9)
    axes[0].set_ylabel("y [m]")
    figure.colorbar(lines, ax=list(axes), shrink=0.85,
                    label="pair normal force per unit depth [N/m]\n(line width ∝ force)")
    if any(np.any(p.pairs.slip_share > 0.5) for p in panels):
        axes[-1].legend(handles=[Line2D([], [], linestyle="none", marker="o",
                                        markerfacecolor="none", markeredgecolor=_SLIP_COLOR,
                                        label="sliding contact")],
                        loc="upper right", fontsize=7, frameon=True)
    return figure


def distribution_figure(curves: Sequence[tuple[str, Sequence[tuple[str, np.ndarray]]]]
                        ) -> Figure:
    """P(f/⟨f⟩) of the grain–grain pair forces: one panel per run, one line per stress level.
    ``curves``: (run label, [(level label, pooled pair forces), ...]) per run."""
    figure = Figure(figsize=(4.0 * len(curves) + 0.5, 3.6), layout="constrained")
    axes = figure.subplots(1, len(curves), squeeze=False, sharey=True)[0]
    for ax, (label, levels) in zip(axes, curves, strict=True):
        for level, forces in levels:
            centres, density = force_distribution(forces, DISTRIBUTION_BINS)
            shown = density > 0.0
            ax.plot(centres[shown], density[shown], marker="o", markersize=3,
                    label=f"{level} ({forces.size} pairs)")
        ax.text(0.98, 0.02, "forces over their snapshot's mean, pooled", fontsize=6,
                ha="right", va="bottom", transform=ax.transAxes)
        ax.set_yscale("log")
        ax.set_xlabel(r"$f/\langle f\rangle$ [–]")
        ax.set_title(label, fontsize=9)
        ax.grid(True, which="both", linewidth=0.5, alpha=0.3)
        ax.legend(frameon=False, fontsize=7)
    axes[0].set_ylabel(r"$P(f/\langle f\rangle)$ (grain–grain pairs)")
    return figure

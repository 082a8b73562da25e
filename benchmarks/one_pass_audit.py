"""Both sides of each grain–grain interface at a run's last state (issue 11;
``contact.grain_passes``): with one pass only one grain's outer points are contacts, and
this reads how far the other grain's points are inside the first one's surface.

For each run folder (checkpoint.h5 and case.toml), the run is resumed and its next step's
grain pairs evaluated with both passes (contact/surfaces.py): over the pairs in contact
(a sampling-side gap below 0.1 h), the least gap of the sampling side (the one-pass
contacts, surfaces.sampling_side) and of the other side, in cells h, and how many of the
other side's points lie below 0, −0.015, −0.03 and −0.05 h. With two passes both sides
are contacts; the same table then shows what the second pass holds.

Run:  python benchmarks/one_pass_audit.py RUN [RUN ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from softgrains.contact import sites, surfaces

sys.path.insert(0, str(Path(__file__).parent))
from dense_step_cost import resumed  # noqa: E402

DEPTHS = (0.0, 0.015, 0.03, 0.05)


def both_sides(run: Path) -> dict:
    """The two sides' gaps (in h) at the grain pairs in contact at the start of the step
    after ``run``'s checkpoint."""
    seen: dict = {}
    evaluate = sites.surface_contacts

    def spy(pairs, steps, spacing, reach, one_pass=frozenset(), round_bodies=frozenset(),
            kernel_surfaces=None):
        if not seen:
            sc = evaluate(pairs, steps, spacing, reach)
            sampling = np.zeros(len(sc), bool)
            for a, b in pairs:
                own, _ = surfaces.sampling_side(a, b, steps, round_bodies)
                sampling |= ((sc.alpha == a) & (sc.beta == b)
                             & (sc.owner_is_alpha == (own == a)))
            seen.update(sc=sc, sampling=sampling)
        return evaluate(pairs, steps, spacing, reach, one_pass, round_bodies, kernel_surfaces)

    with resumed(run) as sim:
        h = sim.case.grid.cell_size
        sites.surface_contacts = spy
        try:
            sim.step()
        finally:
            sites.surface_contacts = evaluate
    sc, sampling = seen["sc"], seen["sampling"]
    pair = sc.alpha * (int(sc.beta.max()) + 1) + sc.beta
    touching = np.isin(pair, np.unique(pair[sampling & (sc.gap < 0.1 * h)]))
    return {"pairs": np.unique(pair[touching]).size,
            "sampling": sc.gap[sampling & touching] / h,
            "other": sc.gap[~sampling & touching] / h}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    print("| run | pairs | least gap, sampling side [h] | other side [h] | other side "
          + " / ".join(f"< -{d:g}" for d in DEPTHS) + " |")
    print("| --- | --- | --- | --- | --- |")
    for run in args.runs:
        found = both_sides(run)
        other = found["other"]
        counts = " / ".join(str(int((other < -d).sum())) for d in DEPTHS)
        print(f"| {run.name} | {found['pairs']} | {found['sampling'].min():+.4f} | "
              f"{other.min():+.4f} | {counts} of {other.size} |")


if __name__ == "__main__":
    main()

"""The bodies' factorizations and contact compliances by the two direct paths: the dense
Cholesky (LAPACK potrf, then trsm and syrk: W = (L⁻¹G)ᵀ(L⁻¹G)) against the sparse LU
(SuperLU, then its solves for every column), on the grains of a run's state (issue 14;
session 38 chose linear_solvers.DENSE_LIMIT = 1500 from it: at D/h 20 a dense compaction's
grains have 600–1070 unknowns and ~270 compliance columns, and the dense path took a third
of the sparse one's time there).

The run folder's checkpoint is resumed and one step started; at its first compliance
update each grain's Newton matrix is factorised and its compliance formed both ways, best
of ``--repeat``, for its own contact sites and for the first ``--fractions`` of them (as a
share of its unknowns). Prints a table per grain and the totals, and the largest relative
difference between the two compliances.
Run:  python benchmarks/compliance_paths.py RUN_DIR [--grains 6] [--fractions 0.05 0.2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from contact_problems_from_run import resumed_without_stop

import softgrains.contact.coupling as coupling
import softgrains.integrator.linear_solvers as linear_solvers


def first_compliance_update(run: Path) -> tuple[dict, object]:
    """(steps, slots) of the first compliance update of a step from the run's checkpoint."""
    captured = []
    update = coupling._update_compliances

    def capture(steps, slots, fresh, delassus):
        if not captured:
            captured.append((steps, slots))
        return update(steps, slots, fresh, delassus)

    coupling._update_compliances = capture
    try:
        resumed_without_stop(run).step()
    finally:
        coupling._update_compliances = update
    return captured[0]


def timed(step, A, rows, sites, dense: bool, repeat: int) -> tuple[float, np.ndarray]:
    """Best seconds of a factorization of A and the compliance at ``sites``, and W."""
    kept = linear_solvers.DENSE_LIMIT
    linear_solvers.DENSE_LIMIT = 10**9 if dense else 0
    try:
        best = np.inf
        for _ in range(repeat):
            step._A, step._lu = A, None
            start = time.perf_counter()
            step.factorization()
            _, W = step.contact_response(rows, True, sites)
            best = min(best, time.perf_counter() - start)
    finally:
        linear_solvers.DENSE_LIMIT = kept
    return best, W


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="run folder with checkpoint.h5, case.toml")
    parser.add_argument("--grains", type=int, default=6, help="grains in the table")
    parser.add_argument("--fractions", type=float, nargs="*", default=[0.05, 0.2],
                        help="also the first columns, as a share of the unknowns")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    steps, slots = first_compliance_update(args.run)
    print("| grain | unknowns | columns | sparse LU [ms] | dense Cholesky [ms] | ratio |")
    print("| --- | --- | --- | --- | --- | --- |")
    totals, worst = np.zeros(2), 0.0
    for slot, body in enumerate(slots.bodies):
        step, H = steps[body], slots.H[slot]
        if H is None:
            continue
        A, rows = step.newton_matrix(), slots.rows[slot]
        counts = [H.shape[0]] + [min(H.shape[0], max(2, int(f * A.shape[0]) // 2 * 2))
                                 for f in args.fractions]
        for j, k in enumerate(counts):
            sparse, W_sparse = timed(step, A, rows, H[:k], False, args.repeat)
            dense, W_dense = timed(step, A, rows, H[:k], True, args.repeat)
            if j == 0:
                totals += sparse, dense
                worst = max(worst, float(np.abs(W_dense - W_sparse).max()
                                         / np.abs(W_sparse).max()))
            if slot < args.grains:
                print(f"| {body} | {A.shape[0]} | {k} | {1e3 * sparse:.1f} | "
                      f"{1e3 * dense:.1f} | {sparse / dense:.2f} |")
    print(f"\nall grains, their own sites: sparse {totals[0]:.3f} s, dense {totals[1]:.3f} s "
          f"(ratio {totals[0] / totals[1]:.2f}); largest relative difference of W "
          f"{worst:.1e}")


if __name__ == "__main__":
    main()

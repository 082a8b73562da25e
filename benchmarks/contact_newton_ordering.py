"""The contact Newton matrix J_EE of a dense state factorised with SuperLU's own ordering
and with nested dissection (issue 14, item 2; contact/ordering.py, session 56).

Resumes a run folder's checkpoint (e.g. a compaction run stopped at 100 σ0), takes one
step and keeps the first J_EE of at least ``--rows`` engaged rows that the contact solve
factorises; then, timed (best of ``--repeat``), 1 thread:
- COLAMD: J_EEᵀ factorised as the code does below DISSECTION_ROWS (transposed solves);
- dissected: the order by METIS (ordering.dissection_order, timed), J_EE untransposed,
  diagonal pivots at DIAGONAL_PIVOT (the code's path from DISSECTION_ROWS);
and for each the factor entries, the pivots off the diagonal (dissected), one solve and
``--columns`` solved at once. Prints a table.
Run:  NUMBA_NUM_THREADS=1 python benchmarks/contact_newton_ordering.py RUN_DIR \
          [--rows 2000] [--columns 8] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dense_step_cost import resumed  # noqa: E402

from softgrains.contact import newton_matrix  # noqa: E402
from softgrains.contact.ordering import dissection_order  # noqa: E402


def _captured(run: Path, rows: int) -> tuple:
    """(W's block rows, the engaged rows sorted, J_EE as CSR in that order) of the first
    factorization of at least ``rows`` engaged rows in the next step of ``run``."""
    kept = []
    original = newton_matrix._Factorization.__init__

    def capture(self, W, G, rho, shift, *args):
        original(self, W, G, rho, shift, *args)
        if not kept and self.engaged.size >= rows:
            engaged = np.sort(self.engaged)
            _, position = newton_matrix._positions(engaged, G.shape[0] * G.shape[1])
            J_ee, _ = newton_matrix._rows(W, G, rho, shift, 1.0, engaged, position)
            kept.append((W, engaged, J_ee))

    newton_matrix._Factorization.__init__ = capture
    try:
        with resumed(run, ["protocol.stop_stress_ratio=1e9"]) as sim:
            sim.step()
    finally:
        newton_matrix._Factorization.__init__ = original
    if not kept:
        raise SystemExit(f"{run}: no contact Newton matrix of {rows} engaged rows or more "
                         "in its next step (try --rows lower)")
    return kept[0]


def _best(function, repeat: int) -> tuple[float, object]:
    best, value = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        value = function()
        best = min(best, time.perf_counter() - start)
    return best, value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="run folder with checkpoint.h5, case.toml")
    parser.add_argument("--rows", type=int, default=newton_matrix.DISSECTION_ROWS)
    parser.add_argument("--columns", type=int, default=8)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    W, engaged, J_ee = _captured(args.run, args.rows)
    m = engaged.size
    rng = np.random.default_rng(0)
    b, B = rng.normal(size=m), rng.normal(size=(m, args.columns))
    order_time, order = _best(lambda: dissection_order(W, engaged), args.repeat)
    where = np.searchsorted(engaged, order)  # the dissected order as positions in E
    J_dissected = J_ee[where][:, where].tocsc()
    cases = [("COLAMD (J_EEᵀ, transposed solves)", 0.0,
              lambda: spla.splu(J_ee.T.tocsc()), "T"),
             ("nested dissection (J_EE)", order_time,
              lambda: spla.splu(J_dissected, permc_spec="NATURAL",
                                diag_pivot_thresh=newton_matrix.DIAGONAL_PIVOT), "N")]
    print(f"J_EE: {m} rows, {J_ee.nnz} entries ({args.run})")
    print(f"| ordering | order ms | factorization ms | factor entries | pivots off the "
          f"diagonal | 1 solve ms | {args.columns} columns ms |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for label, ordering, factorise, trans in cases:
        seconds, lu = _best(factorise, args.repeat)
        one, _ = _best(lambda lu=lu, trans=trans: lu.solve(b, trans=trans), args.repeat)
        many, _ = _best(lambda lu=lu, trans=trans: lu.solve(B, trans=trans), args.repeat)
        # (off the diagonal: rows pivoted elsewhere; meaningful with the natural column
        # order alone, COLAMD permutes the columns too)
        off = int(np.count_nonzero(lu.perm_r != np.arange(m))) if trans == "N" else "–"
        print(f"| {label} | {1e3 * ordering:.1f} | {1e3 * seconds:.1f} "
              f"| {lu.L.nnz + lu.U.nnz} | {off} | {1e3 * one:.2f} | {1e3 * many:.2f} |")


if __name__ == "__main__":
    main()

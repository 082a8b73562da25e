"""Solvers for the bodies' Newton systems A δu = −R in a dense state (issue 14, item 2):
one LU per body (LAPACK dense, SuperLU) against one SuperLU of the block-diagonal system
of all bodies.

From a run folder's checkpoint (e.g. a compaction run stopped at 100 σ0), each deformable
body's Newton matrix at the start of the next step is built; then, timed (best of
``--repeat``): the factorizations, the solve of one right-hand side per body (the Newton
direction), and the solve of ``--columns`` unit columns per body (its compliance columns
at the contacts: ~60 for a D/h 10 grain in the dense compaction). The global system is
solved with its right-hand sides stacked (SciPy's splu solves a dense block: each body's
columns are zero rows for the others). Prints a table: ms per pass over all bodies.
Session 34: also Cholesky per body (its "columns" the half solve L⁻¹B that the compliance
BᵀA⁻¹B = (L⁻¹B)ᵀ(L⁻¹B) needs, the bodies whose A is not positive definite by LU), and
that per-body work (factorization + half solve) on 1 and 2 threads (LAPACK called
without the GIL, integrator/lapack.py).
Run:  python benchmarks/newton_system_solvers.py RUN_DIR [--columns 60] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from softgrains.case import load_case
from softgrains.integrator.implicit import BodyStep
from softgrains.integrator.linear_solvers import DenseCholesky, DenseLU, dense, factorize
from softgrains.simulation import Simulation


def _newton_matrices(run: Path) -> list[sp.bsr_matrix]:
    """Each deformable body's Newton matrix at the start of the step after the checkpoint."""
    sim = Simulation(load_case(run / "case.toml"))
    sim.resume(run / "checkpoint.h5")
    state, model = sim.state, sim.model
    dt = sim.protocol.time_step() if sim.protocol is not None else model.dt
    steps = [BodyStep(sim.solver.steppers[b.index], sim.solver.body_points(state, b.index),
                      model.gravity, dt, state.step) for b in model.bodies if b.deformable]
    return [s.newton_matrix() for s in steps]


def _best(function, repeat: int) -> float:
    """The least wall time of ``repeat`` calls (after one untimed), in ms."""
    function()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return 1e3 * min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--columns", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    mats = _newton_matrices(args.run)
    sizes = [A.shape[0] for A in mats]
    rng = np.random.default_rng(0)
    rhs = [rng.normal(size=n) for n in sizes]
    columns = [np.eye(n)[:, rng.choice(n, min(args.columns, n), replace=False)]
               for n in sizes]
    csc = [sp.csc_matrix(A) for A in mats]
    print(f"{len(mats)} bodies, {np.mean(sizes):.0f} unknowns each on average, "
          f"{sum(A.nnz for A in csc)} nonzeros; {args.columns} compliance columns a body")
    print("| solver | factorize (ms) | one rhs a body (ms) | columns (ms) | fill nnz(L+U) |")
    print("| --- | --- | --- | --- | --- |")
    per_body = {"dense LU per body (LAPACK)": DenseLU, "SuperLU per body": spla.splu}
    for name, factor in per_body.items():
        matrices = mats if factor is DenseLU else csc
        lus = [factor(A) for A in matrices]
        fill = (sum(n * n for n in sizes) if factor is DenseLU
                else sum(f.L.nnz + f.U.nnz for f in lus))
        _row(name, fill, args.repeat,
             lambda m=matrices, f=factor: [f(A) for A in m],
             lambda lus=lus: [f.solve(b) for f, b in zip(lus, rhs, strict=True)],
             lambda lus=lus: [f.solve(c) for f, c in zip(lus, columns, strict=True)])
    chol = [factorize(A) for A in mats]
    spd = sum(isinstance(f, DenseCholesky) for f in chol)

    def half_solves(factors=chol):
        return [f.half_solve(c) if isinstance(f, DenseCholesky) else f.solve(c)
                for f, c in zip(factors, columns, strict=True)]

    _row(f"Cholesky per body ({spd} of {len(mats)} positive definite; else LU), columns "
         "by half solve", sum(n * n for n in sizes), args.repeat,
         lambda: [factorize(A) for A in mats],
         lambda: [f.solve(b) for f, b in zip(chol, rhs, strict=True)], half_solves)
    _threads(mats, columns, args.repeat)
    block = sp.block_diag(csc, format="csc")
    stacked = np.concatenate(rhs)
    stacked_columns = sp.block_diag([sp.csc_matrix(c) for c in columns]).toarray()
    for ordering in ("COLAMD", "NATURAL"):
        lu = spla.splu(block, permc_spec=ordering)
        _row(f"one SuperLU, block diagonal ({ordering})", lu.L.nnz + lu.U.nnz, args.repeat,
             lambda o=ordering: spla.splu(block, permc_spec=o),
             lambda lu=lu: lu.solve(stacked), lambda lu=lu: lu.solve(stacked_columns))


def _threads(mats: list, columns: list, repeat: int) -> None:
    """Each body's factorization and half solve (Cholesky, else LU and solve), its dense
    copy made beforehand, on 1 and 2 Python threads: ms per pass, and the ratio."""
    dense_copies = [np.asfortranarray(dense(A)) for A in mats]

    def body(k: int) -> None:
        matrix = dense_copies[k].copy(order="F")
        cholesky = DenseCholesky.attempt(matrix)
        if cholesky is not None:
            cholesky.half_solve(columns[k])
        else:
            DenseLU(dense_copies[k]).solve(columns[k])

    timings = {}
    for threads in (1, 2):
        with ThreadPoolExecutor(threads) as pool:
            timings[threads] = _best(lambda p=pool: list(p.map(body, range(len(mats)))),
                                     repeat)
    print(f"\nfactorization + half solve of every body: 1 thread {timings[1]:.1f} ms, "
          f"2 threads {timings[2]:.1f} ms (×{timings[1] / timings[2]:.2f})\n")


def _row(name: str, fill: int, repeat: int, factorize, solve_one, solve_columns) -> None:
    """One table row: the three timings and the factors' size."""
    print(f"| {name} | {_best(factorize, repeat):.1f} | {_best(solve_one, repeat):.1f} "
          f"| {_best(solve_columns, max(1, repeat // 5)):.1f} | {fill} |")

if __name__ == "__main__":
    main()

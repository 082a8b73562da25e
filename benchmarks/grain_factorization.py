"""A grain's Newton direction and contact compliance with A_s factorised dense (LAPACK
Cholesky of the n × n matrix) and as Ā's band plus a rank-2k update (integrator/banded.py,
the default since session 57), on the grains of a run's checkpoint (issue 14).

Each RUN_DIR (a run folder with checkpoint.h5 and case.toml, e.g. a compaction stopped
past 100 σ0) is resumed and one step is taken, recording the arguments of the one-call
direction kernel and the site columns of the compliance that follows it, for the first
--calls grains; then each kernel is timed on them (best of --repeat, 1 call after the
other; run with NUMBA_NUM_THREADS=1). Prints per run: unknowns n and lower bandwidth kd
(means), the direction's and the compliance's µs a call each way, their ratio, and the
largest difference between the two paths (relative to the largest entry).

Run:  python benchmarks/grain_factorization.py RUN_DIR [RUN_DIR ...] [--calls 60]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

import softgrains.integrator.implicit as implicit
from softgrains.integrator import lapack
from softgrains.integrator.banded import BandedDecoupled
from softgrains.integrator.dense_direction import (
    DONE,
    banded_momentum_direction,
    momentum_direction,
)
from softgrains.integrator.linear_solvers import DenseCholesky

sys.path.insert(0, str(Path(__file__).parent))
from dense_step_cost import resumed  # noqa: E402


def record(run: Path, calls: int) -> list[tuple]:
    """(direction arguments, compliance columns B, α) of the first ``calls`` grains whose
    direction took the band path in one step from ``run``'s checkpoint."""
    kept, pending = [], {}
    direction, compliance = implicit.banded_momentum_direction, BandedDecoupled.compliance

    def recording_direction(pbtrf, pbtrs, points, pattern, terms, rotations, rhs, factors,
                            du):
        before = copy.deepcopy((points, pattern, terms, rotations, rhs))
        outcome = direction(pbtrf, pbtrs, points, pattern, terms, rotations, rhs, factors, du)
        if outcome[0] == DONE:
            pending[id(factors[0])] = before
        return outcome

    def recording_compliance(self, B, alpha=1.0):
        if id(self.ab) in pending and len(kept) < calls:
            kept.append((pending.pop(id(self.ab)), np.array(B, order="F"), alpha))
        return compliance(self, B, alpha)

    implicit.banded_momentum_direction = recording_direction
    BandedDecoupled.compliance = recording_compliance
    try:
        with resumed(run, ["protocol.stop_stress_ratio=1e9"]) as sim:
            sim.step()
    finally:
        implicit.banded_momentum_direction = direction
        BandedDecoupled.compliance = compliance
    return kept


def _best(function, repeat: int) -> float:
    function()
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def compare(kept: list[tuple], repeat: int) -> dict:
    """Times and differences of the two paths on the recorded grains."""
    dense_args, band_args, results = [], [], []
    for (points, pattern, terms, rotations, rhs), _, _ in kept:
        n = rhs.size
        kd = implicit.lower_bandwidth(pattern.indptr, pattern.indices, pattern.data.shape[1])
        factors = BandedDecoupled.workspace(n, kd, rotations.fields.shape[1])
        dense_args.append((points, pattern, terms, rotations, rhs, np.empty((n, n)),
                           np.empty((n, n), order="F"), np.empty(n)))
        band_args.append((points, pattern, terms, rotations, rhs, factors, np.empty(n)))
        results.append(kd)

    def dense_directions():
        for args in dense_args:
            momentum_direction(lapack.DPOTRF, lapack.DPOTRS, *args)

    def band_directions():
        for args in band_args:
            banded_momentum_direction(lapack.DPBTRF, lapack.DPBTRS, *args)

    seconds = {"direction dense": _best(dense_directions, repeat),
               "direction band": _best(band_directions, repeat)}
    dense_factors = [DenseCholesky(args[6]) for args in dense_args]
    band_factors = [BandedDecoupled(*args[5]) for args in band_args]
    columns = [(B, alpha) for _, B, alpha in kept]
    seconds["compliance dense"] = _best(lambda: [f.compliance(B, a) for f, (B, a) in zip(
        dense_factors, columns, strict=True)], repeat)
    seconds["compliance band"] = _best(lambda: [f.compliance(B, a) for f, (B, a) in zip(
        band_factors, columns, strict=True)], repeat)
    du_diff = max(float(np.abs(d[7] - b[6]).max() / np.abs(d[7]).max())
                  for d, b in zip(dense_args, band_args, strict=True))
    W_diff = 0.0
    for f_dense, f_band, (B, alpha) in zip(dense_factors, band_factors, columns, strict=True):
        W = f_dense.compliance(B, alpha)
        W_diff = max(W_diff, float(np.abs(f_band.compliance(B, alpha) - W).max()
                                   / np.abs(W).max()))
    return {"n": np.mean([args[4].size for args in dense_args]), "kd": np.mean(results),
            "columns": np.mean([B.shape[1] for B, _ in columns]), "calls": len(kept),
            "seconds": seconds, "du": du_diff, "W": W_diff}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, nargs="+")
    parser.add_argument("--calls", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print("| run | calls | n | kd | sites | direction dense / band µs | ratio | "
          "compliance dense / band µs | ratio | max diff du / W |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for run in args.runs:
        kept = record(run, args.calls)
        if not kept:
            print(f"| {run.name} | none took the band path | | | | | | | | |")
            continue
        r = compare(kept, args.repeat)
        s = {k: v / r["calls"] * 1e6 for k, v in r["seconds"].items()}
        print(f"| {run.name} | {r['calls']} | {r['n']:.0f} | {r['kd']:.0f} | "
              f"{r['columns']:.0f} | {s['direction dense']:.0f} / {s['direction band']:.0f} | "
              f"{s['direction dense'] / s['direction band']:.2f} | "
              f"{s['compliance dense']:.0f} / {s['compliance band']:.0f} | "
              f"{s['compliance dense'] / s['compliance band']:.2f} | "
              f"{r['du']:.1e} / {r['W']:.1e} |", flush=True)


if __name__ == "__main__":
    main()

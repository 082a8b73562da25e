"""Linear solves of the Newton systems A δu = −R (ALGORITHM.md §3).

- ``direct``: sparse LU (SuperLU through scipy.sparse.linalg.splu) of A in CSC form.
- ``cg``: conjugate gradients preconditioned by the inverse d×d diagonal blocks of A
  (block Jacobi). A is symmetric: the tangent of a hyperelastic law plus a lumped mass.
- ``auto``: CG while it converges within ``CG_MAX_ITERATIONS``; the first time it does not
  (stiffness dominates the mass term at large Δt), switch that body to the direct solver for
  the rest of the run. benchmarks/bench_single_disk.py measured both (docs/dev-notes.md).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

CG_MAX_ITERATIONS = 200
CG_RELATIVE_TOLERANCE = 1e-10


def _block_jacobi(A: sp.bsr_matrix, diag_slot: np.ndarray) -> sp.bsr_matrix:
    """Inverse of A's diagonal blocks, as a block-diagonal BSR matrix."""
    blocks = np.linalg.inv(A.data[diag_slot])
    n = blocks.shape[0]
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=A.shape)


class LinearSolver:
    """Solves one body's Newton systems; remembers whether CG has failed for it."""

    def __init__(self, kind: str) -> None:
        if kind not in ("auto", "direct", "cg"):
            raise ValueError(f"unknown linear solver {kind!r}")
        self.kind = kind
        self.use_direct = kind == "direct"
        self.last_method = ""
        self.last_iterations = 0
        self.last_factorization = None  # the LU of the last direct solve (contact reuses it)

    def solve(self, A: sp.bsr_matrix, b: np.ndarray, diag_slot: np.ndarray,
              direct: bool = False) -> np.ndarray:
        """x = A⁻¹ b; ``direct`` forces the LU (a body in contact needs it for its Delassus
        compliance anyway: CG first would be spent for nothing)."""
        if not (self.use_direct or direct):
            x, info, its = self._cg(A, b, diag_slot)
            if info == 0:
                self.last_method, self.last_iterations = "cg", its
                self.last_factorization = None
                return x
            if self.kind == "cg":
                raise np.linalg.LinAlgError(
                    f"CG did not converge in {CG_MAX_ITERATIONS} iterations "
                    "(try linear_solver = \"direct\" or \"auto\")")
            self.use_direct = True
        self.last_method, self.last_iterations = "direct", 1
        self.last_factorization = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")
        return self.last_factorization.solve(b)

    @staticmethod
    def _cg(A, b, diag_slot):
        count = [0]

        def tick(_):
            count[0] += 1

        M = _block_jacobi(A, diag_slot)
        x, info = spla.cg(A, b, rtol=CG_RELATIVE_TOLERANCE, atol=0.0,
                          maxiter=CG_MAX_ITERATIONS, M=M, callback=tick)
        return x, info, count[0]

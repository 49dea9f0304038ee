"""Algebraic multigrid (pyamg) as a conjugate-gradient preconditioner: no factorization."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .cg import cg
from .direct import Factor, SolverError


def hierarchy(
    K, *, max_coarse: int = 500, symmetric_gs: bool = False, method: str = "rs",
    coarse_solver: str = "splu", interpolation: str = "classical",
):
    """A multigrid hierarchy of the SPD matrix `K` (pyamg), built once.

    ``method="rs"`` is Ruge-Stueben (classical AMG, for M-matrices such as graph Laplacians),
    ``"sa"`` smoothed aggregation (for other SPD matrices: the biharmonic-like system of
    ``regularization``, the anisotropic one of ``diffusion``). ``symmetric_gs`` uses a
    forward Gauss-Seidel sweep before and a backward one after the coarse correction, which
    keeps the V-cycle symmetric (required for CG) with one sweep each; ``coarse_solver``
    ("splu", or "pinv" for a singular matrix such as an unpinned facet operator) is then the
    coarsest level's. ``interpolation`` is Ruge-Stueben's ("classical" or the cheaper
    "direct").
    """
    import pyamg

    if method == "sa":
        return pyamg.smoothed_aggregation_solver(sp.csr_matrix(K), max_coarse=max_coarse)
    kw = {}
    if symmetric_gs:
        kw = {
            "presmoother": ("gauss_seidel", {"sweep": "forward"}),
            "postsmoother": ("gauss_seidel", {"sweep": "backward"}),
            "coarse_solver": coarse_solver,
        }
    return pyamg.ruge_stuben_solver(sp.csr_matrix(K), max_coarse=max_coarse,
                                    interpolation=interpolation, **kw)


def preconditioner(K, **kw):
    """One V-cycle of :func:`hierarchy` as a callable ``z = M(r)``."""
    ml = hierarchy(K, **kw)
    if kw.get("symmetric_gs"):
        return vcycle(ml)
    M = ml.aspreconditioner(cycle="V")
    return lambda r: M @ r


def vcycle(ml):
    """One symmetric V-cycle of a :func:`hierarchy` built with ``symmetric_gs=True``, as a
    callable ``z = M(r)``: a forward Gauss-Seidel sweep down, the coarse solve, a backward
    sweep up, from a zero start.

    The same arithmetic as pyamg's ``aspreconditioner(cycle="V")``, without the two residual
    norms (two more fine-level products) that pyamg's ``solve`` takes around every cycle to
    test a tolerance a single preconditioning cycle never uses: on the discontinuity route's
    systems one cycle costs about a third less (docs/benchmarks.md).
    """
    from pyamg.amg_core import gauss_seidel

    def sweep(A, x, b, n, forward):
        if forward:
            gauss_seidel(A.indptr, A.indices, A.data, x, b, 0, n, 1)
        else:
            gauss_seidel(A.indptr, A.indices, A.data, x, b, n - 1, -1, -1)

    def down(levels, lvl, b):
        if lvl == len(levels) - 1:  # read at every call: a Galerkin refresh may replace them
            return np.asarray(ml.coarse_solver(levels[lvl].A, b), dtype=b.dtype).reshape(b.shape)
        lv = levels[lvl]
        A = lv.A
        x = np.zeros_like(b)
        sweep(A, x, b, A.shape[0], True)
        x += lv.P @ down(levels, lvl + 1, lv.R @ (b - A @ x))
        sweep(A, x, b, A.shape[0], False)
        return x

    def apply(r):
        return down(ml.levels, 0, np.ascontiguousarray(r, dtype=float))

    return apply


def amg(K, *, rtol: float = 1e-10, maxiter: int = 500, method: str = "rs",
        progress=None) -> Factor:
    """Multigrid-preconditioned CG, warm-started from the previous solution (a loop's
    consecutive right-hand sides are close). `method` as in :func:`hierarchy`; `progress`
    as in :func:`facetlift.linalg.cg`."""
    K = sp.csr_matrix(K)
    M = preconditioner(K, method=method)
    state = {"x0": None}

    def _solve(b):
        x, info = cg(K, b, M, x0=state["x0"], rtol=rtol, maxiter=maxiter, progress=progress)
        factor.info = info
        if not info.converged:
            raise SolverError(
                f"multigrid-preconditioned CG did not converge in {info.iterations} iterations "
                f"(relative residual {info.relative_residual:.2e} > rtol={rtol:g})"
            )
        state["x0"] = x
        return x

    factor = Factor(_solve, "amg")
    return factor

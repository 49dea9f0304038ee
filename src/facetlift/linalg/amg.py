"""Algebraic multigrid (pyamg) as a conjugate-gradient preconditioner: no factorization."""

from __future__ import annotations

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
    M = hierarchy(K, **kw).aspreconditioner(cycle="V")
    return lambda r: M @ r


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

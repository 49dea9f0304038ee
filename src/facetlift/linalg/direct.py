"""Sparse Cholesky-type factorizations: scipy's SuperLU (always there) and MKL PARDISO.

Both return a :class:`Factor` whose ``solve(b)`` reuses the factorization (the paper's
"prefactored" global step).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError


class Factor:
    """A prepared SPD matrix: ``x = factor.solve(b)`` for any number of right-hand sides.

    Attributes
    ----------
    backend : str
        The backend that prepared it.
    info : object or None
        What the last solve reported (a :class:`facetlift.linalg.CGInfo` for iterative
        backends, None for factorizations).
    """

    def __init__(self, solve: Callable[[np.ndarray], np.ndarray], backend: str, release=None):
        self._solve = solve
        self.backend = backend
        self._release = release
        self.info = None

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = self._solve(np.ascontiguousarray(b, dtype=float))
        if not np.all(np.isfinite(x)):
            raise SolverError(f"{self.backend} solve returned non-finite values")
        return x

    def __del__(self):
        if self._release is not None:
            try:
                self._release()
            except Exception:  # pragma: no cover - interpreter shutdown
                pass


def superlu(K, grid=None) -> Factor:
    """SuperLU with the symmetric-mode options that make it 2-2.5x faster than scipy's default
    (no pivoting; ../shared/notes/solver-bench.md). The unknowns are ordered by nested
    dissection on the grid where `grid` (rows, cols) gives their positions
    (:mod:`facetlift.linalg.ordering`: 1.7-2.5x faster again on facet systems), else by
    SuperLU's minimum degree on A+A'."""
    import scipy.sparse.linalg as spla

    perm = None
    if grid is not None:
        from .ordering import nested_dissection

        perm = nested_dissection(*grid)
        if perm.size != K.shape[0]:
            raise ValueError(f"superlu: `grid` holds {perm.size:,} positions for "
                             f"{K.shape[0]:,} unknowns")
        K = sp.csr_matrix(K)[perm][:, perm]
    K = sp.csc_matrix(K)
    try:
        lu = spla.splu(
            K, permc_spec="MMD_AT_PLUS_A" if perm is None else "NATURAL",
            diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
    except RuntimeError as e:  # "Factor is exactly singular"
        raise SolverError(f"SuperLU factorization failed: {e}") from e
    if perm is None:
        return Factor(lu.solve, "superlu")

    def _solve(b):
        x = np.empty_like(b)
        x[perm] = lu.solve(np.ascontiguousarray(b[perm]))
        return x

    return Factor(_solve, "superlu")


def pardiso_available() -> bool:
    """Whether ``pypardiso`` (extra ``facetlift[mkl]``) imports."""
    try:
        import pypardiso  # noqa: F401
    except Exception:  # ImportError, or MKL's shared library failing to load
        return False
    return True


def pardiso(K) -> Factor:
    """Intel MKL PARDISO through ``pypardiso``, set up for this problem: real SPD matrix type
    (``mtype=2``, upper triangle only), no iterative refinement (MKL's default of two steps
    triples the solve time with no gain here), minimum-degree ordering below two million
    unknowns (fastest analysis) and parallel nested dissection above."""
    from pypardiso import PyPardisoSolver

    upper = sp.triu(sp.csr_matrix(K), format="csr")
    upper.sort_indices()
    ps = PyPardisoSolver(mtype=2)
    ps.set_iparm(1, 1)  # use the iparm values set here
    ps.set_iparm(2, 0 if upper.shape[0] < 2_000_000 else 3)
    ps.set_iparm(8, 0)  # no iterative refinement
    try:
        ps.factorize(upper)
    except Exception as e:
        raise SolverError(f"PARDISO factorization failed: {e}") from e

    def _solve(b):
        try:
            return ps.solve(upper, b)
        except Exception as e:
            raise SolverError(f"PARDISO solve failed: {e}") from e

    def _release():
        if hasattr(ps, "free_memory"):  # pypardiso >= 0.4.2
            ps.free_memory(everything=True)

    return Factor(_solve, "pardiso", release=_release)

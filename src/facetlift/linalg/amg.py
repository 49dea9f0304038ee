"""Algebraic multigrid (pyamg) as a conjugate-gradient preconditioner: no factorization."""

from __future__ import annotations

import contextlib
import threading

import numpy as np
import scipy.sparse as sp

from .cg import cg
from .direct import Factor, SolverError
from .matvec import parallel


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

    if method == "sa":  # (Ruge-Stueben's setup draws no random numbers: no seeding)
        with _seeded():
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


_SEED_LOCK = threading.Lock()


@contextlib.contextmanager
def _seeded(seed: int = 0):
    """A smoothed-aggregation setup made deterministic without numpy's global random state.

    The setup's spectral-radius estimates (pyamg's ``approximate_spectral_radius``, called by
    its Jacobi prolongation smoother) start from ``np.random.rand`` unless given a start
    vector, so the same input gave hierarchies 2e-12 apart. Until 2026-12-07 the global state
    was seeded here and put back afterwards, which a host's thread drawing from it meanwhile
    saw: 527,166 of one audit's draws repeated the seed-0 stream. Now the smoother's name for
    the estimator is pointed, for the setup's duration, at one that starts from a fixed vector
    (a private ``RandomState(seed)``'s draws) where none is given; numpy's global state is not
    touched. The swap is of a pyamg module attribute: another thread's smoothed-aggregation
    setup in that window also starts from the fixed vector (deterministic, and no worse).
    Only smoothed aggregation does this (dgp's explicit ``backend="amg"`` and the
    regularization and diffusion methods); Ruge-Stueben, which the discontinuity route and
    poisson's multigrid use, draws nothing."""
    from pyamg.aggregation import smooth

    with _SEED_LOCK:  # (threads, e.g. Dask's, build one at a time: the swap is shared)
        estimator = smooth.approximate_spectral_radius

        def fixed_start(A, *args, initial_guess=None, **kwargs):
            if initial_guess is None:
                initial_guess = np.random.RandomState(seed).rand(A.shape[1], 1)
            return estimator(A, *args, initial_guess=initial_guess, **kwargs)

        smooth.approximate_spectral_radius = fixed_start
        try:
            yield
        finally:
            smooth.approximate_spectral_radius = estimator


def preconditioner(K, **kw):
    """One V-cycle of :func:`hierarchy` as a callable ``z = M(r)``."""
    M = hierarchy(K, **kw).aspreconditioner(cycle="V")
    return lambda r: M @ r


def vcycle(ml):
    """One symmetric V-cycle of a :func:`hierarchy` built with ``symmetric_gs=True``, as a
    callable ``z = M(r)``: a forward Gauss-Seidel sweep down, the coarse solve, a backward
    sweep up, from a zero start.

    The same arithmetic as pyamg's ``aspreconditioner(cycle="V")`` with the "splu" coarse
    solver (a singular coarsest matrix, for which :func:`hierarchy` offers "pinv", is not
    supported: pass such hierarchies to pyamg), without the two residual
    norms (two more fine-level products) that pyamg's ``solve`` takes around every cycle to
    test a tolerance a single preconditioning cycle never uses (a 300^2 Poisson cycle: 10.9 ->
    8.7 ms), and with the coarsest level factorized once per matrix (docs/benchmarks.md).
    """
    from pyamg.amg_core import gauss_seidel
    from scipy.sparse.linalg import splu

    for lv in ml.levels[:-1]:
        sweeps = (getattr(lv.presmoother, "keywords", {}).get("sweep"),
                  getattr(lv.postsmoother, "keywords", {}).get("sweep"))
        if sweeps != ("forward", "backward"):
            raise ValueError("vcycle needs a hierarchy built with symmetric_gs=True "
                             f"(one forward and one backward Gauss-Seidel sweep), not {sweeps}")

    def sweep(A, x, b, n, forward):
        if forward:
            gauss_seidel(A.indptr, A.indices, A.data, x, b, 0, n, 1)
        else:
            gauss_seidel(A.indptr, A.indices, A.data, x, b, n - 1, -1, -1)

    factor = {}

    def coarsest(A, b):
        # pyamg's "splu" coarse solver transposes a selection matrix at every call (half a
        # millisecond a cycle); the same solve, factorized once per coarse matrix
        if factor.get("A") is not A:
            Ac = A.tocsc(copy=True)
            Ac.eliminate_zeros()
            keep = np.flatnonzero(np.diff(Ac.indptr))  # rows and columns that are not empty
            factor.update(A=A, keep=keep, lu=splu(Ac[keep][:, keep].tocsc()))
        x = np.zeros_like(b)
        x[factor["keep"]] = factor["lu"].solve(b[factor["keep"]])
        return x

    def down(levels, lvl, b):
        if lvl == len(levels) - 1:  # read at every call: a Galerkin refresh may replace them
            return coarsest(levels[lvl].A, b)
        lv = levels[lvl]
        A = lv.A
        x = np.zeros_like(b)
        sweep(A, x, b, A.shape[0], True)
        Am, P, R = A, lv.P, lv.R
        if lvl == 0:  # (the finest level's products on two threads, if a core is free)
            Am, P, R = parallel(A), parallel(P), parallel(R)
        x += P @ down(levels, lvl + 1, R @ (b - Am @ x))
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


def refresh(ml, K, coarse_solver: str = "splu", reinterpolate: bool = False) -> None:
    """Give the hierarchy `ml` a new finest matrix `K` (same pattern of unknowns): the
    coarsening and the interpolation are kept, the coarse operators recomputed
    (``A_{l+1} = R A_l P``, Galerkin) and pyamg's coarse solver replaced by a new one of
    kind `coarse_solver` (it factorizes at its first use); a fraction of the cost of a new
    hierarchy. The callables of :func:`vcycle` see the new operators (their coarsest factor
    is redone at the next call).

    With `reinterpolate` each level's interpolation is also formed anew from the new matrix:
    Ruge-Stueben direct interpolation on the level's old coarse points, from the same coarse
    neighbours as before (the old pattern; the costly splitting is kept), so couplings the
    new matrix has weakened, e.g. across a new cut, stop carrying the coarse correction
    (unless such a coupling is a point's only coarse neighbour: direct interpolation scales
    its row to reproduce constants). Needs a hierarchy of :func:`hierarchy` with
    ``method="rs"``."""
    import pyamg

    levels = ml.levels
    if reinterpolate and any(not hasattr(lv, "splitting") for lv in levels[:-1]):
        raise ValueError("refresh: reinterpolate=True needs a Ruge-Stueben hierarchy (its "
                         "levels' C/F splitting); this one has none (smoothed aggregation?)")
    levels[0].A = sp.csr_matrix(K)
    for fine, coarse in zip(levels[:-1], levels[1:], strict=True):
        if reinterpolate:
            _reinterpolate(fine)
        coarse.A = (fine.R @ fine.A @ fine.P).tocsr()
    ml.coarse_solver = pyamg.multilevel.coarse_grid_solver(coarse_solver)


def _reinterpolate(level) -> None:
    """Give the hierarchy `level` (of a Ruge-Stueben hierarchy) the direct interpolation of
    its (new) matrix ``level.A`` on its coarse points ``level.splitting`` (True = coarse),
    from each fine point's coarse neighbours in its old ``level.P``, and ``R = P^T``: the
    arithmetic of pyamg's :func:`direct_interpolation` (its two kernels, called here) with a
    strength pattern of P's columns; a coarse point's row of the pattern is left empty (the
    kernels read none there). The old P and R are dropped before the new ones are formed.
    Every index array takes one type, 64-bit if any of A's is (the kernels take one; scipy
    picks the smallest type for a product, which a 64-bit matrix then mismatched)."""
    from pyamg import amg_core

    A, splitting = level.A.tocsr(), np.asarray(level.splitting, dtype=bool)
    n = A.shape[0]
    dt = np.int64 if np.int64 in (A.indices.dtype, A.indptr.dtype) else np.int32
    P = level.P.tocsr()
    level.P = level.R = None
    cpts = np.flatnonzero(splitting).astype(dt)
    counts = np.diff(P.indptr)
    keep = np.repeat(~splitting, counts)  # (entries on fine points' rows)
    counts[splitting] = 0
    indptr = np.zeros(n + 1, dtype=dt)
    np.cumsum(counts, out=indptr[1:])
    pattern = sp.csr_matrix((np.ones(int(indptr[-1])), cpts[P.indices[keep]], indptr),
                            shape=A.shape)
    del P, keep, counts, indptr
    C = pattern.multiply(A).tocsr()  # (A's entries on the pattern)
    del pattern
    a_ptr, a_ind = A.indptr.astype(dt, copy=False), A.indices.astype(dt, copy=False)
    c_ptr, c_ind = C.indptr.astype(dt, copy=False), C.indices.astype(dt, copy=False)
    split = splitting.astype(dt)
    p_ptr = np.empty(n + 1, dtype=dt)
    amg_core.rs_direct_interpolation_pass1(n, c_ptr, c_ind, split, p_ptr)
    p_ind = np.empty(int(p_ptr[-1]), dtype=dt)
    p_data = np.empty(int(p_ptr[-1]), dtype=A.dtype)
    amg_core.rs_direct_interpolation_pass2(n, a_ptr, a_ind, A.data, c_ptr, c_ind, C.data,
                                           split, p_ptr, p_ind, p_data)
    del C, c_ptr, c_ind
    level.P = sp.csr_array((p_data, p_ind, p_ptr), shape=(n, int(splitting.sum())))
    level.R = level.P.T.tocsr()


def block_aggregates(rows, cols, size: int, groups=None) -> sp.csr_matrix:
    """(n, k) indicator matrix of square blocks of ``size`` x ``size`` grid points.

    Point ``i`` at grid position ``(rows[i], cols[i])`` belongs to the block of its position
    (and of its `groups` label, e.g. its connected component, so that a block never joins
    points that share no equation). The columns span the piecewise-constant functions on the
    blocks: the coarse space of :func:`balanced`.
    """
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    n = rows.size
    if n == 0:
        return sp.csr_matrix((0, 0))
    rows, cols = rows - rows.min(), cols - cols.min()
    key = (rows // size) * (int(cols.max()) // size + 1) + cols // size
    if groups is not None:
        g = np.asarray(groups, dtype=np.int64)
        g = g - g.min()
        key = key * (int(g.max()) + 1) + g
    _, agg = np.unique(key, return_inverse=True)
    return sp.csr_matrix((np.ones(n), (np.arange(n), agg.ravel())), shape=(n, int(agg.max()) + 1))


def balanced(K, V, Z):
    """Two-level preconditioner: the coarse space spanned by the columns of `Z` (n, k) solved
    exactly, the smoother/preconditioner `V` (a callable, symmetric positive definite) for the
    rest, in the symmetric "balancing" form ``M = C + (I - C K) V (I - K C)`` with
    ``C = Z (Z^T K Z)^{-1} Z^T``; SPD for any SPD `V` where ``Z^T K Z`` is nonsingular.
    Blocks on which `K` vanishes (rows of zeros, nothing to correct) are dropped; if the
    coarse matrix is still singular, `V` is returned alone.

    Multigrid built by Ruge-Stueben coarsening on the discontinuity route's glued systems
    resolves their smooth, piecewise-constant error (the offsets of whole regions, a whole
    component with one pinned vertex) slowly; blocks of 8 x 8 vertices catch it and halve
    the CG iterations on objects with a rim of missing normals (docs/benchmarks.md). Costs
    per application: `V`, one product with `K`, one with ``K Z`` and two coarse solves.
    """
    import scipy.sparse.linalg as spla

    Z = sp.csr_matrix(Z)
    KZ = sp.csr_matrix(K @ Z)  # a few entries a row where K has nine
    E = (Z.T @ KZ).tocsc()
    d = E.diagonal()
    live = d > 1e-12 * max(float(d.max(initial=0.0)), np.finfo(float).tiny)
    if not live.all():
        Z, KZ, E = Z[:, live], KZ[:, live].tocsr(), E[live][:, live].tocsc()
    if E.shape[0] == 0:
        return V
    try:
        lu = spla.splu(E)
    except RuntimeError:  # an exactly singular coarse matrix: no coarse space
        return V
    ZT = Z.T.tocsr()

    def apply(r):
        c = lu.solve(ZT @ r)
        t = r - KZ @ c  # r - K x for x = Z c
        y = V(t)
        t -= K @ y
        return Z @ (c + lu.solve(ZT @ t)) + y

    return apply

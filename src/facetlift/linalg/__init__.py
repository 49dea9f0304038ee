"""The linear-solver layer: one backend table, one choice of backend, one CG.

Backends (``backend=`` of the methods that solve sparse SPD systems):

``"pardiso"``
    Intel MKL PARDISO through ``pypardiso`` (extra ``facetlift[mkl]``, ~1.1 GB, Intel Simplified
    Software License), SPD matrix type, no iterative refinement.
``"superlu"``
    scipy's SuperLU in symmetric mode (no pivoting), ordered by nested dissection on the grid
    where the caller gives the unknowns' grid positions (:mod:`facetlift.linalg.ordering`),
    else by minimum degree on A+A'. Always available.
``"amg"``
    pyamg Ruge-Stueben multigrid as a CG preconditioner: no factorization, the least memory.
``"pcg"``
    CG with a preconditioner the caller supplies, e.g. the fictitious-domain spectral
    preconditioner of :mod:`facetlift.linalg.spectral` for facet operators: no set-up and an
    O(n log n) cost per iteration.

``"auto"`` is resolved by :func:`choose`, the only place that decides which backend runs,
from the size and the ``kind`` of system: DGP facet systems always take "pcg" with
:class:`facetlift.linalg.facet.FacetPreconditioner` (the box spectral solve plus an exact
solve on the vertices of facets without a target; multigrid where the box is poor, or a
factorization where a model of its time beats CG's predicted remainder, chosen by measurement
in :func:`facetlift.linalg.facet.solve`), except on thin domains, which factorize where the
factorization fits; graph
Laplacians and other SPD systems factorize up to :data:`LARGE` unknowns and take
multigrid-CG above. :func:`factorize` prepares a matrix for repeated solves (the paper's
"prefactored" global step); :func:`solve` does one solve and reports what it did;
:class:`Series` solves the nearby systems of a reweighting with one multigrid hierarchy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .cg import CGInfo, cg
from .direct import Factor, SolverError, pardiso_available

__all__ = [
    "BACKENDS",
    "KINDS",
    "CGInfo",
    "Factor",
    "Series",
    "SolveInfo",
    "SolverError",
    "available_backends",
    "cg",
    "check_backend",
    "choose",
    "factorize",
    "factorizer",
    "solve",
]

#: Backend names accepted by ``backend=``.
BACKENDS = ("auto", "pardiso", "superlu", "amg", "pcg")

#: Above this many unknowns a factorization costs minutes and many GB without PARDISO (SuperLU
#: at 2048^2: ~100 s and 12 GB extrapolated), so "auto" turns to iterative solvers.
LARGE = 250_000

#: ... and for graph Laplacians (kind "graph") with SuperLU, where Ruge-Stueben multigrid-CG
#: catches up sooner: measured with SuperLU in nested-dissection order (interleaved, best of
#: 2), ``poisson`` on a disk 0.20 vs 0.23 s at 40k pixels and on the human mask 0.29 vs 0.39 s
#: at 56k (factorization faster), 0.54 vs 0.44 s at 89k, 0.91 vs 0.73 s at 159k, 1.33 vs
#: 1.07 s at 218k (multigrid faster); ``m_estimator`` (one hierarchy for every reweighting)
#: 1.82 vs 0.91 s at 159k; ``alpha_surface`` 1.82 s both at 159k (docs/benchmarks.md).
GRAPH_LARGE = 80_000


@dataclass
class SolveInfo:
    """What :func:`solve` did: the backend that ran and, for CG backends, its iterations."""

    backend: str
    iterations: int | None = None
    residual: float | None = None


def available_backends() -> list[str]:
    """Backends usable in this environment (without ``"auto"``)."""
    return (["pardiso"] if pardiso_available() else []) + ["superlu", "amg", "pcg"]


def check_backend(backend) -> str:
    """`backend` if it is a known and installed backend, else a ValueError naming it."""
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ValueError(f"`backend` must be one of {BACKENDS}; got {backend!r}")
    if backend == "pardiso" and not pardiso_available():
        raise ValueError("`backend`='pardiso' needs Intel MKL: pip install 'facetlift[mkl]'")
    return backend


#: What kind of SPD system is solved (``kind=`` of :func:`choose`):
#: ``"facet"``: a DGP facet system on a domain (:mod:`facetlift.linalg.facet` preconditions it
#: on any mask, with missing normals and grazing rims); ``"graph"``: an M-matrix such as a
#: weighted graph Laplacian (classical multigrid suits it); ``"spd"``: any other SPD matrix
#: (smoothed-aggregation multigrid above :data:`LARGE`).
KINDS = ("facet", "graph", "spd")


def factorizer() -> str:
    """The factorization backend: "pardiso" where installed, else "superlu" (for a caller
    that has decided to factorize whatever the size, e.g. a system CG solves slowly)."""
    return "pardiso" if pardiso_available() else "superlu"


def choose(
    n: int,
    backend: str = "auto",
    *,
    kind: str = "graph",
    preconditioner: bool = False,
    trusted: bool = False,
    thin: bool = False,
) -> str:
    """The backend that solves an SPD system of `n` unknowns: the one policy.

    Parameters
    ----------
    n : int
    backend : str
        A name from :data:`BACKENDS`; anything but "auto" is returned as it is (checked).
    kind : {"facet", "graph", "spd"}
        What the matrix is (:data:`KINDS`). Facet systems always take "pcg" with
        :class:`~facetlift.linalg.facet.FacetPreconditioner` (20-60 iterations at every size
        and on every mask, no factorization: docs/benchmarks.md).
    preconditioner : bool
        The caller has another cheap problem-specific preconditioner ("pcg" is possible).
    trusted : bool
        That preconditioner converges in a few dozen iterations on this system: prefer it at
        every size. An untrusted one is used only where factorizing is too costly.
    thin : bool
        A facet system on a thin domain (:func:`facetlift.linalg.facet.thin`, a strip a few
        pixels wide): it factorizes with little fill, faster than any preconditioner helps
        CG there (a spiral 4 pixels wide with 30 % missing normals, 250k vertices: SuperLU
        0.65 s, multigrid-CG 254 iterations and 35 s), so it is factorized at every size
        where the factorization fits (:func:`facetlift.memory.factorization_fits`), else CG.

    Returns
    -------
    str
        "pcg", "pardiso", "superlu" or "amg".

    Notes
    -----
    Up to :data:`LARGE` unknowns a factorization (PARDISO where installed, else SuperLU) is
    the fastest for general systems, and for graph Laplacians with SuperLU up to
    :data:`GRAPH_LARGE`; above it the factorization grows
    superlinearly in time and memory (PARDISO 14.7 s and 5 GB at 2048^2) and multigrid-CG,
    linear in both, takes over (also with PARDISO installed).
    """
    backend = check_backend(backend)
    if kind not in KINDS:
        raise ValueError(f"`kind` must be one of {KINDS}; got {kind!r}")
    if backend != "auto":
        return backend
    if kind == "facet" and thin:
        # (only where the factorization fits: a 4096^2 map with 30 % of its normals NaN and
        # no mask reads as thin through its holes, and was refused for the 44 GiB of a
        # factorization where CG fits in a few; a large-maps audit)
        from ..memory import factorization_fits

        return factorizer() if factorization_fits(n) else "pcg"
    if kind == "facet" or (preconditioner and trusted):
        return "pcg"
    if n <= (GRAPH_LARGE if kind == "graph" and not pardiso_available() else LARGE):
        return factorizer()
    if preconditioner and not pardiso_available():
        return "pcg"
    return "amg"


def factorize(
    K,
    backend: str = "auto",
    *,
    kind: str = "graph",
    preconditioner: Callable[[np.ndarray], np.ndarray] | None = None,
    trusted: bool = False,
    rtol: float = 1e-11,
    progress: Callable[[int, float], None] | None = None,
    grid: tuple[np.ndarray, np.ndarray] | None = None,
) -> Factor:
    """Prepare the SPD matrix `K` (n, n) for repeated solves (``Factor.solve(b)``).

    The backend is :func:`choose`'s; iterative backends start every solve from the previous
    solution (a loop's consecutive right-hand sides are close) and call `progress`
    (iteration, relative residual) after every CG iteration; a factorization is one library
    call and reports nothing. `grid` (rows, cols) (each (n,)): the unknowns' positions on the
    pixel or vertex grid, for SuperLU's nested-dissection ordering
    (:mod:`facetlift.linalg.ordering`; PARDISO orders its own).
    """
    name = _route(K, backend, kind, preconditioner, trusted)
    if name == "pcg":
        return _pcg_factor(K, preconditioner, rtol, progress)
    if name == "pardiso":
        from .direct import pardiso

        return pardiso(K)
    if name == "amg":
        from .amg import amg

        return amg(K, rtol=rtol, method="sa" if kind == "spd" else "rs", progress=progress)
    from .direct import superlu

    return superlu(K, grid)


def solve(
    K,
    b: np.ndarray,
    backend: str = "auto",
    *,
    kind: str = "graph",
    preconditioner: Callable[[np.ndarray], np.ndarray] | None = None,
    trusted: bool = False,
    rtol: float = 1e-11,
    x0: np.ndarray | None = None,
    flexible: bool = False,
    progress: Callable[[int, float], None] | None = None,
    grid: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, SolveInfo]:
    """Solve ``K x = b`` once for a symmetric positive (semi-)definite `K` (n, n).

    With a `preconditioner` and the "pcg" route, `K` may be singular with `b` in its range;
    `flexible` selects CG's Polak-Ribiere update there (for preconditioners that are SPD only
    up to rounding, such as float32 transforms). `kind` is :func:`choose`'s. `progress`
    (iteration, relative residual) is called after every CG iteration of the "pcg" and "amg"
    routes (the methods' ``progress=`` option); factorizations are one library call without
    an iteration to report. `grid`: the unknowns' grid positions, as for :func:`factorize`.

    Returns
    -------
    x : (n,) float
    info : SolveInfo

    Raises
    ------
    SolverError
        The factorization failed or CG did not converge.
    """
    name = _route(K, backend, kind, preconditioner, trusted)
    if name == "pcg":
        x, cinfo = _cg(K, b, preconditioner, x0, rtol, flexible, progress)
        _raise_unless_converged(cinfo, rtol, "preconditioned CG")
        return x, SolveInfo("pcg", cinfo.iterations, cinfo.relative_residual)
    factor = factorize(K, name, kind=kind, rtol=rtol, progress=progress, grid=grid)
    x = factor.solve(b)
    it = factor.info.iterations if factor.info is not None else None
    return x, SolveInfo(name, it)


class Series:
    """Solve a sequence of nearby SPD systems ``K_k x = b_k`` (the rounds of a reweighting:
    IRLS, growing edge sets), each with :func:`choose`'s backend for the first.

    Multigrid keeps the first matrix's hierarchy as the preconditioner of the later ones
    (still SPD and close; rebuilt when CG needs more than `rebuild_after` iterations) and
    starts each CG from the previous solution; factorizations refactorize every matrix
    (ordered on `grid`, the unknowns' grid positions, as for :func:`factorize`).

    Attributes
    ----------
    backend : str
    iterations : list of int
        CG iterations per solve (multigrid).
    setups : int
        Hierarchies built.
    """

    def __init__(self, backend: str = "auto", *, kind: str = "graph", rtol: float = 1e-11,
                 rebuild_after: int = 60, grid=None):
        self._backend, self._kind, self._rtol, self._grid = backend, kind, rtol, grid
        self._rebuild_after = rebuild_after
        self.backend = None
        self._M = None
        self._x = None
        self.iterations = []
        self.setups = 0

    def _hierarchy(self, K):
        from .amg import preconditioner

        self.setups += 1
        return preconditioner(K, method="sa" if self._kind == "spd" else "rs")

    def solve(self, K, b: np.ndarray) -> np.ndarray:
        if self.backend is None:
            self.backend = choose(K.shape[0], self._backend, kind=self._kind)
        if self.backend != "amg":
            return factorize(K, self.backend, kind=self._kind, grid=self._grid).solve(b)
        import scipy.sparse as sp

        K = sp.csr_matrix(K)
        if self._M is None:
            self._M = self._hierarchy(K)
        x0 = self._x
        x, info = cg(K, b, self._M, x0=x0, rtol=self._rtol, maxiter=self._rebuild_after)
        its = info.iterations
        if not info.converged:
            self._M = self._hierarchy(K)
            x, info = cg(K, b, self._M, x0=x, rtol=self._rtol, maxiter=500)
            its += info.iterations
            _raise_unless_converged(info, self._rtol, "multigrid-preconditioned CG")
        self.iterations.append(its)
        self._x = x
        return x


def _route(K, backend, kind, preconditioner, trusted) -> str:
    """:func:`choose` for `K`; the CG route needs the caller's preconditioner."""
    name = choose(K.shape[0], backend, kind=kind, preconditioner=preconditioner is not None,
                  trusted=trusted)
    if name == "pcg" and preconditioner is None:
        raise ValueError("`backend`='pcg' needs a `preconditioner`")
    return name


def _cg(K, b, preconditioner, x0, rtol, flexible, progress=None):
    """CG with `preconditioner`; a facet preconditioner brings its own policy (box or
    multigrid, :func:`facetlift.linalg.facet.solve`)."""
    from .facet import FacetPreconditioner, solve

    if isinstance(preconditioner, FacetPreconditioner):
        return solve(K, b, preconditioner, x0=x0, rtol=rtol, progress=progress)
    return cg(K, b, preconditioner, x0=x0, rtol=rtol, flexible=flexible, progress=progress)


def _raise_unless_converged(info: CGInfo, rtol: float, what: str) -> None:
    if not info.converged:
        raise SolverError(
            f"{what} did not converge in {info.iterations} iterations (relative residual "
            f"{info.relative_residual:.2e} > rtol={rtol:g})"
        )


def _pcg_factor(K, preconditioner, rtol, progress=None) -> Factor:
    state = {"x0": None}

    def _solve(b):
        x, info = _cg(K, b, preconditioner, state["x0"], rtol, True, progress)
        factor.info = info
        _raise_unless_converged(info, rtol, "preconditioned CG")
        state["x0"] = x
        return x

    factor = Factor(_solve, "pcg")
    return factor

"""Discontinuity-preserving DGP: facets with their own corners, robustly glued to the vertices.

The smooth DGP fixed point (see :mod:`facetlift.methods.dgp`) minimises, over the vertex
values ``z`` (height, or log-depth for a perspective camera),
``sum_f ||P (C_f z) - b_f||^2``: every facet is shaped by its own target and all facets that
share a vertex share its value. Across an occlusion boundary that sharing is wrong: the two
sides are different surfaces, and tying them together smears the depth jump over the whole
surface.

Formulation
    Every facet ``f`` gets its own copy ``y_f`` (4,) of its corner values, shaped by its
    target, and each copy is glued to the shared vertex by a robust penalty::

        E(z, y) = sum_f ||P y_f - b_f||^2
                + sum_f sum_k  rho(y_f[k] - z[c(f, k)]),
        rho(r) = (k s)^2 / 2 * log(1 + (r / (k s))^2)          (Cauchy)

    ``P`` and ``b_f`` are the facet's slope/twist rows and targets of the smooth method. For
    small misfits ``rho(r) ~ r^2 / 2`` and the minimiser over ``y`` reproduces the smooth DGP
    solution exactly (with a uniform glue weight the facet blocks are the smooth blocks times a
    constant). A corner whose copy disagrees with the vertex by much more than ``k s`` pays
    only a logarithmic price, so a facet can detach from a vertex where the normals imply a
    jump: this is vertex splitting decided by the data, like the bilateral weights of BiNI
    (Cao et al., ECCV 2022) transposed to facets.

Scale
    ``s`` is the pixel footprint in the unknown's units: the pixel size ``h`` for an
    orthographic view (heights), ``1 / sqrt(fx fy)`` for a perspective one (log-depth: a
    surface at 45 degrees to the ray changes ``log Z`` by about ``1/f`` per pixel). The one
    parameter ``discontinuity_k`` is therefore dimensionless: the misfit at a facet corner, in
    pixel footprints (a slope inconsistency), at which the glue weight halves.

Solution (iteratively reweighted least squares = majorise-minimise)
    With the glue weights ``w_fk = 1 / (1 + (r_fk / (k s))^2)`` frozen, ``E`` is quadratic;
    eliminating each facet's copy (a 4x4 Schur complement, ``M_f = (A_f + W_f)^{-1}``,
    ``A_f = P^T P``) leaves a 9-point system on the vertices with per-facet blocks
    ``W_f - W_f M_f W_f`` and right-hand side ``W_f M_f P^T b_f``. The Cauchy weights make each
    quadratic a majoriser of ``E``, so ``E`` decreases monotonically. The first iterate is the
    smooth solution. The smooth solution spreads the non-integrability of a jump over the whole
    surface, and the cut then "unzips" along the boundary a few pixels per reweighting; so the
    first reweighting also counts, at each corner, the loop mismatch of the targets around its
    vertex (:func:`vertex_curl`, the change of the jump per pixel along a boundary) as misfit,
    which marks the whole boundary at once (later reweightings use the misfit alone, so wrongly
    seeded corners glue back). Each reweighting is followed by 3 conjugate-gradient steps,
    preconditioned with one algebraic-multigrid hierarchy (pyamg) of the smooth system and
    warm-started from the previous iterate (every step lowers the majoriser, so ``E`` still
    decreases); weights above 0.99 (misfit below ``0.1 k s``) are taken as exactly 1, so only
    facets near discontinuities are re-assembled. If multigrid-CG stalls on the smooth start
    (bands of facets without a normal leave nearly free modes), :func:`facetlift.linalg.solve`
    computes it instead. 20 reweightings (``discontinuity_iter``) are a time budget, not a
    convergence guarantee: long jumps that grow slowly along their boundary keep improving
    for ~100.

The returned facet values are the means of the facets' own copies (so depths at facet
centres stay sharp at a jump); vertex values are the glued ``z``.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp

from ... import linalg
from ...linalg.amg import hierarchy
from ...operators.stencil import E_TWIST, E_X, E_Y, facet_form, scatter_corners

log = logging.getLogger(__name__)

#: Default for ``discontinuity_k`` (see the module docstring and docs/perspective.md).
DEFAULT_K = 0.3

#: Default number of reweightings after the smooth start.
DEFAULT_ITER = 20

#: Conjugate-gradient steps per reweighting.
CG_STEPS = 3

#: Multigrid-CG steps allowed for the smooth start before falling back to linalg.solve.
START_CG = 40


def _blas_single_thread():
    """Limit BLAS to one thread while iterating (OpenBLAS threading of the small vector
    operations inside CG and multigrid costs more than it gains, badly so on a busy machine)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - declared dependency
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(1, user_api="blas")


class FacetBlocks:
    """Assemble per-facet 4x4 blocks (each its own values) into a fixed 9-point CSR pattern.

    Parameters
    ----------
    domain : Domain
    pin : float
        Diagonal weight added at one vertex per connected component (fixes the constant).
    """

    def __init__(self, domain, pin: float = 1.0):
        self.domain = domain
        pattern = facet_form(domain, [(1.0, np.ones((4, 4)))])
        pattern.sort_indices()
        n = domain.n_vertices
        self.indptr = pattern.indptr
        self.indices = pattern.indices
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(pattern.indptr))
        keys = rows * n + pattern.indices
        c = domain.corners
        fk = (c[:, :, None] * n + c[:, None, :]).reshape(-1)  # (m*16,) row-major (a, b)
        idx_dtype = np.int32 if keys.size < 2**31 else np.int64
        self.slot = np.searchsorted(keys, fk).astype(idx_dtype).reshape(-1, 16)
        self.nnz = keys.size
        first = domain.first_vertices
        diag = np.searchsorted(keys, first * n + first)
        self.pin = np.bincount(diag, np.full(first.size, pin), minlength=self.nnz)

    def assemble_update(self, K0: sp.csr_matrix, facets: np.ndarray, dQ: np.ndarray):
        """``K0`` plus the blocks `dQ` (k, 4, 4) of the facets `facets` (k,), same pattern."""
        data = K0.data + np.bincount(
            self.slot[facets].reshape(-1), dQ.reshape(-1), minlength=self.nnz
        )
        return self._csr(data)

    def assemble(self, Q: np.ndarray) -> sp.csr_matrix:
        """(n, n) CSR of ``sum_f C_f^T Q_f C_f`` plus the pins; `Q` is (m, 4, 4) or (m, 16)."""
        data = np.bincount(self.slot.reshape(-1), Q.reshape(-1), minlength=self.nnz)
        return self._csr(data + self.pin)

    def _csr(self, data):
        n = self.domain.n_vertices
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(n, n))


def scatter_corners_subset(domain, facets, values):
    """``C^T v`` for the (k, 4) corner values of the facets `facets` only."""
    return np.bincount(
        domain.corners[facets].ravel(), weights=values.ravel(), minlength=domain.n_vertices
    )


def _facet_system(bx, by, flat_weight):
    """``A = P^T P`` (4, 4) of a facet without a target, and ``a_f = P^T b_f`` (m, 4).

    A facet with a target has ``A = I - 11^T / 4`` (slopes and twist, see
    :func:`_glue_inverse`).
    """
    slope = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
    A_other = flat_weight * slope + np.outer(E_TWIST, E_TWIST)
    a = bx[:, None] * E_X + by[:, None] * E_Y
    return A_other, a


#: Misfits below this fraction of ``k s`` keep the full glue weight 1 (the Cauchy weight there
#: is above 0.99); this lets every reweighting touch only the facets near a discontinuity.
CORE = 0.1


def vertex_curl(domain, bx, by, target):
    """Discrete curl of the target slopes around every vertex.

    The mismatch accumulated by the four facet planes around a vertex along one loop: zero
    for an integrable field (up to discretisation and noise), the change of the jump per pixel
    along a depth discontinuity whose size varies. In the units of `bx`, `by` (one pixel).

    Returns
    -------
    (n,) float
        0 where not all four facets around the vertex have a target.
    """
    H, W = domain.shape
    r, c = domain.pixels
    gx = np.full((H + 2, W + 2), np.nan)
    gy = np.full((H + 2, W + 2), np.nan)
    gx[r + 1, c + 1] = np.where(target, bx, np.nan)
    gy[r + 1, c + 1] = np.where(target, by, np.nan)
    # vertex (i, j): facets TL=(i-1, j-1), TR=(i-1, j), BL=(i, j-1), BR=(i, j) (padded +1)
    tl, tr = (gx[:-1, :-1], gy[:-1, :-1]), (gx[:-1, 1:], gy[:-1, 1:])
    bl, br = (gx[1:, :-1], gy[1:, :-1]), (gx[1:, 1:], gy[1:, 1:])
    dqdx = (tr[1] + br[1] - tl[1] - bl[1]) / 2
    dpdy = (tl[0] + tr[0] - bl[0] - br[0]) / 2  # y up: the top row is +y
    curl = np.nan_to_num(dqdx - dpdy)
    return curl[domain.vertex_mask]


def glue_weight(r: np.ndarray, ks: float) -> np.ndarray:
    """Cauchy weight ``1 / (1 + (r / ks)^2)``, exactly 1 for ``|r| < CORE * ks``."""
    x2 = (r / ks) ** 2
    return np.where(x2 < CORE**2, 1.0, 1.0 / (1.0 + x2))


def _pcg(K, b, x0, M, rtol, maxiter):
    """A few CG steps from `x0`; returns (x, iterations)."""
    x, info = linalg.cg(K, b, lambda r: M @ r, x0=x0, rtol=rtol, maxiter=maxiter)
    return x, info.iterations


def _glue_inverse(target, w, A_other):
    """``M_f = (A_f + diag(w_f))^{-1}`` for the facets with glue weights `w` (k, 4): (k, 4, 4).

    For a facet with a target ``A_f = I - 11^T / 4``, so ``A_f + W_f`` is a diagonal minus a
    rank-one matrix and Sherman-Morrison gives the inverse in closed form; the few facets
    without a target are inverted directly.
    """
    dinv = 1.0 / (1.0 + w)  # (m, 4)
    d = 0.5 * dinv
    c = 1.0 / (1.0 - 0.25 * dinv.sum(axis=1))
    M = c[:, None, None] * d[:, :, None] * d[:, None, :]
    idx = np.arange(4)
    M[:, idx, idx] += dinv
    other = ~target
    if other.any():
        M[other] = np.linalg.inv(A_other + w[other][:, :, None] * np.eye(4))
    return M


def solve_discontinuous(
    domain, bx, by, target, *, scale: float, k: float = DEFAULT_K, max_iter: int = DEFAULT_ITER,
    tol: float = 1e-2, flat_weight: float = 1e-9, cg_iter: int | None = None, callback=None,
):
    """Minimise the robust facet energy of the module docstring.

    Parameters
    ----------
    domain : Domain
    bx, by : (m,) float
        Target slopes of the unknown per facet (zero where `target` is False), as for
        :func:`facetlift.methods.dgp.solve_direct`.
    target : (m,) bool
    scale : float
        Pixel footprint ``s`` in the unknown's units.
    k : float
        Misfit (in units of `scale`) at which a corner's glue weight halves.
    max_iter : int
        Reweightings after the smooth solution (0 returns the smooth solution).
    tol : float
        Stop when the largest change of the vertex values in one reweighting is below
        ``tol * scale``.
    flat_weight : float
        Slope weight of facets without a target (see dgp).
    callback : callable(iteration, z, change), optional
        Called after every reweighting with the vertex values and the largest change (in
        units of `scale`).
    cg_iter : int
        Conjugate-gradient steps per reweighting. Each step lowers the current quadratic
        majoriser, so the energy still decreases monotonically; solving each system exactly
        is wasted work while the weights are still changing.

    Returns
    -------
    z : (n,) float
        Vertex values.
    zf : (m,) float
        Facet-centre values: means of the facets' own corner copies.
    info : dict
        ``iterations``, ``converged``, ``cg_iterations`` (list), ``detached`` (fraction of
        facet corners with glue weight < 1/2), ``seconds``.
    """
    t0 = time.perf_counter()
    ks = k * scale
    m = domain.n_facets
    A_other, a = _facet_system(bx, by, flat_weight)
    blocks = FacetBlocks(domain)
    corners = domain.corners
    diag = np.arange(4)
    tgt = target[:, None]
    all_target = bool(target.all())
    with _blas_single_thread():
        # smooth start: every corner fully glued (w = 1), the smooth DGP system scaled by 1/2;
        # with w = 1 there are only two kinds of facet blocks (with and without a target)
        M0 = _glue_inverse(np.array([True, False]), np.ones((2, 4)), A_other)
        Q0 = np.eye(4) - M0  # (2, 4, 4)
        Ma0 = a @ M0[0] if all_target else np.where(tgt, a @ M0[0], a @ M0[1])
        K0 = blocks.assemble(np.where(tgt, Q0[0].ravel(), Q0[1].ravel()))
        rhs0 = scatter_corners(domain, Ma0)
        P = hierarchy(K0, symmetric_gs=True).aspreconditioner(cycle="V")
        t1 = time.perf_counter()
        z, it = _pcg(K0, rhs0, np.zeros(domain.n_vertices), P, 1e-8, START_CG)
        cg_its = [it]
        if it >= START_CG:
            # an ill-conditioned start (bands of facets without a normal leave near-free
            # modes that multigrid-CG resolves slowly): take the library's solver
            try:
                z = linalg.solve(K0, rhs0)[0]
            except linalg.SolverError:
                z, it = _pcg(K0, rhs0, z, P, 1e-8, 2000)
                cg_its.append(it)

        # the reweighted state: weights w (m, 4); facets with a weight < 1 ("active", a set
        # that only grows) carry their own M_f and M_f a_f, all others the w = 1 ones
        w = np.ones((m, 4))
        active = np.zeros(m, dtype=bool)
        act = np.zeros(0, dtype=np.int64)
        M_act = np.zeros((0, 4, 4))
        Ma_act = np.zeros((0, 4))

        def misfit(z):
            """Own corner values minus the glued vertex values, (m, 4)."""
            zc = z[corners]
            own = zc @ M0[0] if all_target else np.where(tgt, zc @ M0[0], zc @ M0[1])
            r = Ma0 + own - zc
            if act.size:
                r[act] = Ma_act + np.einsum("fab,fb->fa", M_act, w[act] * zc[act]) - zc[act]
            return r

        curl = np.abs(vertex_curl(domain, bx, by, target))
        converged = False
        it_irls = 0
        for it_irls in range(1, max_iter + 1):
            r = misfit(z)
            if it_irls == 1:  # seed: the loop mismatch of the targets around each vertex
                r = np.maximum(np.abs(r), curl[corners])
            w = glue_weight(r, ks)
            active |= (w < 1.0).any(axis=1)
            act = np.nonzero(active)[0]
            wa = w[act]
            M_act = _glue_inverse(target[act], wa, A_other)
            Ma_act = np.einsum("fab,fb->fa", M_act, a[act])
            dQ = -(wa[:, :, None] * M_act * wa[:, None, :])
            dQ[:, diag, diag] += wa
            dQ -= Q0[np.where(target[act], 0, 1)]
            K = blocks.assemble_update(K0, act, dQ)
            rhs = rhs0 + scatter_corners_subset(domain, act, wa * Ma_act - Ma0[act])
            z_new, it = _pcg(K, rhs, z, P, 1e-10, CG_STEPS if cg_iter is None else cg_iter)
            cg_its.append(it)
            change = np.abs(z_new - z).max()
            z = z_new
            if callback is not None:
                callback(it_irls, z, change / scale)
            if change < tol * scale:
                converged = True
                break
        y = misfit(z) + z[corners]
    t2 = time.perf_counter()
    info = {
        "iterations": it_irls,
        "converged": converged,
        "cg_iterations": cg_its,
        "detached": float((w < 0.5).mean()),
        "discontinuity_k": k,
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return z, y.mean(axis=1), info

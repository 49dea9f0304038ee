"""Bilateral normal integration (BiNI; Cao, Santo, Shi, Okura, Matsushita, ECCV 2022).

facetlift's own implementation from the paper's description and its published algorithm, for
comparison on the same input (the discontinuity benchmark runs it beside ``dgp``).

Energy
    The unknown is the camera's (:mod:`facetlift.camera`: height in pixel units of the
    footprint, or log-depth) at the pixel centres. Every pixel ``p`` with a usable normal has
    four one-sided terms, forward and backward along x and along y, each with its own normal:
    ``w (c_p (u_q - u_p) - c_p g_p)^2`` where ``g_p`` is the grid slope the normal implies along
    that axis and ``c_p`` the normal's scale (``n_z / h`` orthographically; in perspective
    BiNI's ``n~_z = (u - c_u) n_x + (v - c_v) n_y + f n_z`` per axis, with ``f_x`` for the
    column and ``f_y`` for the row differences, as its reference code writes it, and the
    normal's components as targets: see :func:`_scales`). A missing neighbour drops the term.

Bilateral weights
    Along each axis ``w_+ = sigmoid(k ((A_- u)^2 - (A_+ u)^2))`` and ``w_- = 1 - w_+``, with
    ``A_+- u = c_p (u_q - u_p)`` the scaled one-sided differences: the side with the larger
    difference is taken as discontinuous. ``k`` (default 2, BiNI's DiLiGenT setting) is in
    squared pixel footprints.

Solver (as BiNI's reference code)
    Start from ``w = 1/2`` and ``u = 0``; every iteration solves the weighted normal equations
    by Jacobi-preconditioned CG warm-started from the previous iterate to ``cg_tol`` (1e-3),
    then updates the weights from the new ``u``, and stops when the relative change of the
    energy falls below `tol` (1e-4) or after `max_iter` (150) iterations. BiNI's results
    depend on that inexact CG path (an exact solve changes them on most DiLiGenT objects), so
    the same path is kept here. Pieces that the weights cut off keep whatever constant the
    path leaves them: BiNI has no rule for them.

Without the bilateral weights
    ``discontinuities=False`` keeps ``w = 1/2`` and solves once. It is not ``poisson``: each
    term keeps its ``c_p`` (BiNI's ``n_z``, or ``n~_z``), so it is a least squares weighted by
    ``c_p^2``, which leans on the flat parts. Measured on 2026-12-07: mean error 3.6e-4 against
    poisson's 7.4e-5 on the analytic ``face`` at 128^2 (with ``c_p = 1`` both give 7.4e-5);
    MADE 0.20 mm against 0.056 on the bunny rendered without jumps at 256 x 306, and 1.20 mm
    against 0.52 on the DiLiGenT bear. A tighter ``cg_tol`` changes neither (1e-10: 0.202,
    1.202).

Missing samples
    A pixel without a usable normal has no terms of its own; its neighbours' terms toward it
    place it. Inside a larger hole no term reaches a pixel, and CG would leave it at its start:
    those pixels get the harmonic fill of the pixels around (:func:`fill_unreached`,
    ``info["filled"]``; an extension of ours: BiNI integrates a masked map without holes).

Parts joined only at a corner
    BiNI's differences join 4-neighbours, so two parts of the mask that touch only at a pixel
    corner (one component of facetlift's 8-connected domain) share no term, and CG left the
    second part's constant (a perspective camera: its scale) wherever its path ended, with no
    warning (found by an audit: a two-square mask 1.4 units off). After the loop each such part
    is moved so that the diagonal step across its corner matches the two normals' slopes
    (:func:`join_pinches`, ``info["pinched"]``; an extension of ours, as every other method
    here joins such parts through the same diagonal).

Reference
    X. Cao, H. Santo, B. Shi, F. Okura, Y. Matsushita. Bilateral Normal Integration. ECCV 2022.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from .. import linalg
from .._warnings import warn
from ..errors import ConvergenceWarning
from ..operators import graph as pg
from ..options import Option
from . import MethodResult

#: The options of the bilateral reweighting (none apply with discontinuities=False, one solve).
_BILATERAL = {"discontinuities": True}

OPTIONS = (
    Option("discontinuities", True, "bilateral weights (False: both sides 1/2, one least squares "
           "whose terms keep BiNI's n_z weights: not poisson's result)", kind="bool"),
    Option("k", 2.0, "sharpness of the bilateral sigmoid, in squared pixel footprints",
           low=0.0, low_open=True, when=_BILATERAL),
    Option("max_iter", 150, "most reweightings", kind="int", low=1, when=_BILATERAL),
    Option("tol", 1e-4, "stop when the energy changes by less than this fraction", low=0.0,
           when=_BILATERAL),
    Option("cg_tol", 1e-3, "relative residual of each inner CG solve", low=0.0, low_open=True,
           high=1.0, high_open=True),
    Option("cg_max_iter", 5000, "most CG iterations per solve", kind="int", low=1),
    Option("progress", None, "callable(iteration, relative energy change)", kind="callable",
           none=True),
)


def _sigmoid(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))  # 1 / (1 + exp(-x)) without overflow


def operators(problem):
    """The four one-sided difference operators (scaled by ``c_p``) and their targets.

    Returns
    -------
    A : list of 4 (n, n) CSR
        Rows ``c_p (u_q - u_p)`` for +x, -x, +y, -y (empty rows where q is missing or p has
        no usable normal).
    b : list of 4 (n,) float
        ``c_p g_p`` (zero where p has no usable normal).
    """
    graph = pg.build(problem.domain)
    n = graph.n
    scales, (gx, gy) = _scales(problem)
    G = pg.difference(graph).tocsr()  # (E, n): u[head] - u[tail]
    out_A, out_b = [], []
    # (edge index per pixel, sign of head - tail along +axis, target slope)
    for edges, sign, g, scale in ((graph.right, 1.0, gx, scales[0]),
                                  (graph.left, 1.0, gx, scales[0]),
                                  (graph.up, -1.0, gy, scales[1]),
                                  (graph.down, -1.0, gy, scales[1])):
        has = (edges >= 0) & problem.usable
        rows = np.flatnonzero(has)
        sel = sp.csr_matrix((np.ones(rows.size), (rows, edges[has])), shape=(n, graph.n_edges))
        A = sp.diags(scale * sign) @ sel @ G
        out_A.append(A.tocsr())
        # a term whose neighbour is missing has an empty row; its constant residual still
        # counts in the energy (and so in the stopping rule), as in BiNI
        out_b.append(np.where(problem.usable, scale * np.nan_to_num(g), 0.0))
    return out_A, out_b


def _scales(problem):
    """``(c_x, c_y), (g_x, g_y)`` (m,): the scale of the one-sided differences along x and
    along y, and the slopes they are compared with.

    Orthographic: ``n_z / h`` on both axes. Perspective: BiNI's ``n~_z`` written as its
    reference code does, per axis with its own focal length, ``f_x n_z - (c_y - row) n_y -
    (col - c_x) n_x`` for the column differences and ``f_y n_z - ...`` for the row differences
    (n in facetlift's frame). It differs from the exact ``f (n . r)`` by at most a few 0.1 %
    on DiLiGenT, but BiNI's inexact CG path, and so its result, is that sensitive: with the
    geometric-mean focal length for both axes the bear's MADE is 0.376 mm instead of 0.334 mm.
    The slopes are then BiNI's ``n_x / c_x`` and ``n_y / c_y`` (its targets are the normal's
    components), not the exact log-depth slopes of :meth:`facetlift.camera.Pinhole.grid_slopes`.
    A skewed ``K`` (BiNI has no skew term) takes the exact cosine and slopes instead.
    """
    cam, usable = problem.camera, problem.usable
    K = getattr(cam, "K", None)
    if not cam.perspective or K[0, 1] != 0:
        # orthographic, or a skewed pinhole (BiNI's n~_z has no skew term): the exact ray
        # cosine per footprint and the camera's exact slopes
        s = problem.view_cosines / cam.footprint()
        return (s, s), problem.grid_slopes
    r, c = problem.domain.pixels
    nrm = np.where(usable[:, None], problem.normals, [0.0, 0.0, 1.0])
    off = -(K[1, 2] - r) * nrm[:, 1] - (c - K[0, 2]) * nrm[:, 0]
    sx = np.where(usable, K[0, 0] * nrm[:, 2] + off, 0.0)
    sy = np.where(usable, K[1, 1] * nrm[:, 2] + off, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (sx, sy), (np.where(usable, nrm[:, 0] / sx, np.nan),
                          np.where(usable, nrm[:, 1] / sy, np.nan))


def run(problem, *, discontinuities, k, max_iter, tol, cg_tol, cg_max_iter, progress):
    """Integrate `problem` with BiNI; values (m,) of the camera's unknown at pixel centres."""
    t0 = time.perf_counter()
    A, b = operators(problem)
    n = problem.domain.n_facets
    w = [np.full(n, 0.5) for _ in range(4)]
    u = np.zeros(n)

    def energy(u, w):
        terms = zip(A, b, w, strict=True)
        return sum(float(np.sum(wi * (Ai @ u - bi) ** 2)) for Ai, bi, wi in terms)

    E = energy(u, w)
    pin = np.zeros(n)
    pin[problem.domain.first_facets] = 1e-8  # keeps each component's constant finite
    cg_its, changes = [], []
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        M = sum(Ai.T @ sp.diags(wi) @ Ai for Ai, wi in zip(A, w, strict=True)) + sp.diags(pin)
        rhs = sum(Ai.T @ (wi * bi) for Ai, bi, wi in zip(A, b, w, strict=True))
        d = np.clip(M.diagonal(), 1e-5, None)
        u, info = linalg.cg(M.tocsr(), rhs, lambda r, d=d: r / d, x0=u, rtol=cg_tol,
                            maxiter=cg_max_iter)
        cg_its.append(info.iterations)
        solved = info  # (the last solve's: its iterate is the result)
        if discontinuities:
            sq = [(Ai @ u) ** 2 for Ai in A]
            wx = _sigmoid(k * (sq[1] - sq[0]))
            wy = _sigmoid(k * (sq[3] - sq[2]))
            w = [wx, 1.0 - wx, wy, 1.0 - wy]
        E_new = energy(u, w)
        change = abs(E_new - E) / E if E > 0 else 0.0
        changes.append(change)
        E = E_new
        if progress is not None:
            progress(it, change)
        if change < tol or not discontinuities:
            converged = True
            break
    if not converged:
        warn(f"bini: the energy still changed by {changes[-1]:.2g} after {max_iter} iterations",
             ConvergenceWarning)
    if not solved.converged:  # (the result is that solve's iterate: not the energy's minimum)
        res = solved.residuals[-1] if solved.residuals else float("nan")
        warn(f"bini: the linear solve stopped at cg_max_iter={cg_max_iter} iterations with a "
             f"relative residual of {res:.2g} (cg_tol={cg_tol:g}): raise cg_max_iter",
             ConvergenceWarning)
        converged = False
    u, filled = fill_unreached(problem, A, u)
    u, pinched = join_pinches(problem, u)
    info = {
        "iterations": it,
        "converged": converged,
        "energy": E,
        "changes": changes,
        "cg_iterations": cg_its,
        "filled": filled,
        "pinched": pinched,
        "seconds": {"solve": time.perf_counter() - t0},
    }
    return MethodResult(values=u, info=info)


def join_pinches(problem, u):
    """`u` with every 4-connected part of the mask that touches the rest of its component only
    at pixel corners moved (a constant of the camera's unknown) so that the diagonal steps
    across those corners match the slopes of the two normals there (least squares over the
    parts, the largest part of each component staying put), and how many parts moved. A part
    whose corner steps have no usable normal on either side keeps its values."""
    from scipy.ndimage import label
    from scipy.sparse.linalg import spsolve

    domain = problem.domain
    graph = pg.build(domain)
    diag = np.flatnonzero(graph.kind == pg.DIAGONAL)
    if diag.size == 0:
        return u, 0
    _, (gx, gy) = _scales(problem)
    t, has = pg.targets(graph, np.where(problem.usable, gx, np.nan),
                        np.where(problem.usable, gy, np.nan))
    diag = diag[has[diag]]
    if diag.size == 0:
        return u, 0
    lab, k = label(domain.mask, structure=pg.FOUR)
    part = lab[domain.pixels] - 1
    tail, head = graph.tail[diag], graph.head[diag]
    want = t[diag] - (u[head] - u[tail])  # o[part of head] - o[part of tail]
    rows = np.arange(diag.size)
    D = sp.csr_matrix((np.r_[-np.ones(diag.size), np.ones(diag.size)],
                       (np.r_[rows, rows], np.r_[part[tail], part[head]])), shape=(diag.size, k))
    size = np.bincount(part, minlength=k)
    comp = np.zeros(k, dtype=np.int64)
    comp[part] = domain.facet_component
    largest = np.zeros(k, bool)  # (the largest part of each component stays put)
    order = np.lexsort((-size, comp))
    largest[order[np.r_[True, comp[order][1:] != comp[order][:-1]]]] = True
    pin = np.where(largest, 1.0, 1e-9)  # (a part without a usable corner step: offset 0)
    o = np.atleast_1d(spsolve((D.T @ D + sp.diags(pin)).tocsc(), D.T @ want))
    joined = np.zeros(k, bool)
    joined[part[tail]] = joined[part[head]] = True
    return u + o[part], int((joined & ~largest).sum())


def fill_unreached(problem, A, u):
    """`u` with the pixels that no term reaches (inside a hole of missing normals: their own
    terms and their neighbours' toward them are all absent) set to the harmonic interpolation
    of the pixels around them, and how many there were. The energy leaves them free, so CG
    left them at its start, a step at the hole's edge (the DiLiGenT bear with a 40 x 80 hole:
    10 mm inside it where dgp is 0.25; found by a fresh-user check). A region that touches no
    reached pixel keeps its values."""
    from scipy.sparse.csgraph import connected_components

    n = u.size
    reached = np.zeros(n, bool)
    for Ai in A:
        reached |= np.diff(Ai.tocsc().indptr) > 0
    free = np.flatnonzero(~reached)
    if free.size == 0 or free.size == n:
        return u, 0
    G = pg.difference(pg.build(problem.domain)).tocsr()
    L = (G.T @ G).tocsr()  # the pixel graph's Laplacian
    fixed = np.flatnonzero(reached)
    LF = L[free]
    LFF, LFD = LF[:, free].tocsr(), LF[:, fixed].tocsr()  # (free-free, free-reached)
    # only the free regions next to a reached pixel (a region without one keeps its values)
    count, label = connected_components(LFF, directed=False)
    touching = np.zeros(count, bool)
    touching[label[np.diff(LFD.indptr) > 0]] = True
    keep = touching[label]
    if not keep.any():
        return u, 0
    rhs = -(LFD[keep] @ u[fixed])
    # (an M-matrix, solved by multigrid-preconditioned CG: no factorization of a big hole)
    x, _ = linalg.solve(LFF[keep][:, keep].tocsr(), rhs, "amg", rtol=1e-10)
    free = free[keep]
    out = u.copy()
    out[free] = x
    return out, int(free.size)

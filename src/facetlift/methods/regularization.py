"""Regularized least squares: the gradient data term plus a smoothness prior, weight lambda.

Energy
    ``min_z sum_e (z_head - z_tail - t_e)^2 + lam * R(z)`` on the pixel graph of
    :mod:`facetlift.methods._graph` (data term exactly as :mod:`facetlift.methods.poisson`),
    with one of two priors ``R``:

``prior="laplacian"`` (default)
    ``R(z) = sum_p (z_left + z_right + z_up + z_down - 4 z_p)^2`` over the pixels whose four
    4-neighbours are all in the mask (no prior term at the boundary, where the 5-point stencil
    would be a one-sided first difference). Both terms are squared height differences, so
    ``lam`` is dimensionless and independent of the pixel size: in Fourier terms the prior
    dominates the data above the frequency ``omega h = 1 / sqrt(lam)``, i.e. it damps
    wavelengths shorter than ``2 pi sqrt(lam)`` pixels. It leaves harmonic surfaces (planes,
    the saddle ``x^2 - y^2``, whose discrete Laplacian is exactly zero) untouched and pulls
    others toward smaller curvature by ``O(lam h^2)``. One sparse solve. Default
    ``lam = 1.0`` (a cut-off near 6 pixels); not tuned on any data.

``prior="edge_preserving"``
    The half-quadratic edge-preserving regularization of the ECCV 2006 code
    (``halfquadractic.m``): ``R(z) = (1/4) sum_e phi(s_e)``-type penalty on the slopes
    ``s_e = (z_head - z_tail) / h`` with ``phi(s) = sqrt(1 + s^2)``, minimised by
    half-quadratic iterations ``sum_e (z_head - z_tail - t_e)^2 + (lam / 4) sum_e b_e
    (z_head - z_tail)^2`` with ``b_e = 1 / sqrt(1 + s_e^2)`` (``phi'(s) / s``) from the
    measured slopes in the first round and from the current surface afterwards, at most
    `max_iter` (default 10, as in the code) rounds, stopping when the relative height change
    is below `tol`. Default ``lam = 10`` (the code's value). This prior penalises slopes
    themselves, so it flattens every surface that is not level, planes included (heights
    shrink by roughly ``1 / (1 + lam b / 4)``: an exact tilted plane comes back at 0.29 of its
    height with ``lam = 10``, 0.80 with ``lam = 1``); the code rescales its output to the
    height range of the Poisson solution afterwards, which we do not do.

Masks and missing samples
    As :mod:`facetlift.methods.poisson`. ``lam -> 0`` gives the Poisson solution.

Options
    Declared in :data:`OPTIONS`.

Reference
    A. Agrawal, R. Raskar, R. Chellappa. What is the range of surface reconstructions from a
    gradient field? ECCV 2006 (regularization as a member of the generalized equation).
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
from . import _graph as g

PRIORS = {"laplacian": 1.0, "edge_preserving": 10.0}

OPTIONS = (
    Option("lam", None, "weight of the smoothness prior (default 1 for 'laplacian', 10 for "
           "'edge_preserving')", low=0.0, high=1e8, none=True),
    Option("prior", "laplacian", "smoothness prior", kind="choice", choices=tuple(PRIORS)),
    *g.iteration_options(10, "rounds", when={"prior": "edge_preserving"}),
    g.BACKEND,
    g.PROGRESS,
)


def laplacian_rows(graph: pg.PixelGraph) -> sp.csr_matrix:
    """(P, n) 5-point Laplacian rows at the pixels with all four 4-neighbours in the mask."""
    inner = (graph.left >= 0) & (graph.right >= 0) & (graph.up >= 0) & (graph.down >= 0)
    pix = np.nonzero(inner)[0]
    nb = np.stack(
        [
            graph.tail[graph.left[pix]],
            graph.head[graph.right[pix]],
            graph.tail[graph.up[pix]],
            graph.head[graph.down[pix]],
            pix,
        ],
        axis=1,
    )
    vals = np.tile([1.0, 1.0, 1.0, 1.0, -4.0], pix.size)
    rows = np.repeat(np.arange(pix.size), 5)
    return sp.csr_matrix((vals, (rows, nb.ravel())), shape=(pix.size, graph.n))


def run(problem, *, lam, prior, max_iter, tol, backend, progress) -> MethodResult:
    """Integrate `problem` with a smoothness prior; values (m,) at pixel centres."""
    lam = PRIORS[prior] if lam is None else lam

    t0 = time.perf_counter()
    domain, graph, t, has, h = g.setup(problem)
    w = g.edge_weights(has)
    L = pg.laplacian(graph, w)
    rhs = pg.divergence(graph, w * t)
    info = {"prior": prior, "lam": float(lam)}
    if prior == "laplacian":
        R = laplacian_rows(graph)
        K = pg.pin(domain, L + float(lam) * (R.T @ R))
        pr, pc = domain.pixels  # (R^T R couples pixels two apart: separators two lines wide)
        z = g.spd_solve(K, rhs, backend, kind="spd", progress=progress, grid=(pr // 2, pc // 2))
        info.update(iterations=1, converged=True, prior_rows=int(R.shape[0]))
    else:
        slope = np.where(has, t / h, 0.0)  # measured slopes for the first round
        # one hierarchy for every round
        series = linalg.Series(backend, kind="spd", grid=domain.pixels)
        z = None
        converged = False
        changes = []
        n_iter = 0
        while n_iter < int(max_iter):
            n_iter += 1
            b = 1.0 / np.sqrt(1.0 + slope**2)
            K = pg.pin(domain, L + (float(lam) / 4.0) * pg.laplacian(graph, b))
            z_new = series.solve(K, rhs)
            if z is not None:
                changes.append(g.relative_change(z_new, z))
            if progress is not None:  # (the first round: a change from nothing, 1)
                progress(n_iter, changes[-1] if changes else 1.0)
            z = z_new
            if changes and changes[-1] < tol:
                converged = True
                break
            slope = (z[graph.head] - z[graph.tail]) / h
        if not converged and not changes:  # (max_iter 1: the test compares two rounds)
            warn(f"regularization: max_iter={n_iter} ran one round, and the convergence test "
                 "compares two: raise `max_iter` to 2 or more", ConvergenceWarning)
        elif not converged:
            warn(f"regularization: no convergence in {n_iter} rounds (last relative change "
                 f"{changes[-1]:.3g} >= tol={tol}); raise `max_iter`", ConvergenceWarning)
        info.update(iterations=n_iter, converged=converged, changes=changes)
    info["seconds"] = {"solve": time.perf_counter() - t0}
    return MethodResult(values=z, info=info)

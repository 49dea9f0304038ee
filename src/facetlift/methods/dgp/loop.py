"""The paper's local/global loop (``solver="iterative"``, Sec. 4 and 5 of Xie et al.).

Local shaping (Eq. 1-2) projects each facet's corners onto the plane with its target normal
through its current centre; global blending (Eq. 5-8) solves ``A^T A z = A^T b`` with the
prefactored ``A^T A`` (mean subtraction) or averages the corner copies (without it). The loop
stops when the average angular deviation changes by less than `tol` degrees (Sec. 5).
"""

from __future__ import annotations

import time

import numpy as np

from ... import linalg
from ..._warnings import warn
from ...errors import ConvergenceWarning
from ...linalg.dense import rowwise
from ...linalg.facet import FacetPreconditioner, thin
from ...linalg.spectral import RectangleSolver
from ...operators.stencil import (
    E_X,
    E_Y,
    N_MEAN_FREE,
    corner_views,
    facet_form,
    grid_scatter,
    grid_slopes,
    pin_components,
    prior_form,
)
from .common import empty_components, mean_angle


def local_shaping(domain, z, bx, by, target):
    """Eq. 1-2: project each facet's corners onto its target plane through its centre.

    Facets without a target take their current least-squares plane (Sec. 4.4). Returns the
    projected corner heights (m, 4) and the facet centres (m,).
    """
    zf = z[domain.corners]
    centre = zf.mean(axis=1)
    gx = np.where(target, bx, rowwise(zf, E_X))
    gy = np.where(target, by, rowwise(zf, E_Y))
    projected = centre[:, None] + gx[:, None] * E_X + gy[:, None] * E_Y
    return projected, centre


def solve_iterative(
    domain, bx, by, target, h, mean_subtraction=True, max_iter=5000, tol=1e-3,
    backend="auto", progress=None, *, weights=None, prior=None, offset=(0, 0),
):
    """The paper's local/global loop from the flat mesh; returns vertex values and info.

    `weights` (m,) scale every facet's term of the global step (the normals' confidence);
    `prior` ``(w, t, fixed)`` adds ``sum_f w_f (mean z_f - t_f)^2`` to it (docs/fusion.md).
    Either needs the mean-subtracted global step.
    """
    t0 = time.perf_counter()
    empty_components(domain, target, offset=offset)
    factor = valence = None
    fused = weights is not None or prior is not None
    if fused and not mean_subtraction:
        raise ValueError("a `prior` or `confidence` needs mean_subtraction=True with "
                         "solver='iterative' (the averaging step has no weighted form)")
    fixed = None if prior is None else prior[2]
    wimg = 1.0 if weights is None else domain.to_image(weights, fill=0.0)
    prhs = None
    if mean_subtraction:
        # on a full rectangle A^T A is diagonalised by the DCT-I: the spectral box solver is
        # exact, O(n log n), and needs no matrix; on other masks it preconditions CG (every
        # facet carries the full block N here, so no facet is weak), warm-started each step
        route = linalg.choose(domain.n_vertices, backend, kind="facet", thin=thin(domain))
        exact = bool(domain.mask.all()) and route == "pcg" and not fused
        if not exact:
            w = 1.0 if weights is None else weights
            K = facet_form(domain, [(w, N_MEAN_FREE)])
            if prior is not None:
                KP, prhs = prior_form(domain, prior[0], prior[1])
                K = K + KP
            if not (fused and route == "pcg"):  # CG needs no pin (rhs in the range);
                K = pin_components(domain, K, skip=fixed)  # the box cannot see one
    else:
        valence = np.bincount(domain.corners.ravel(), minlength=domain.n_vertices)
    t1 = time.perf_counter()
    pre = None
    if mean_subtraction and exact:
        factor = linalg.Factor(RectangleSolver(*domain.shape).solve, "spectral")
    elif mean_subtraction:
        strong = np.ones(domain.n_facets, dtype=bool)
        lumped = None
        if prior is not None:
            from .fixed_point import _lumped

            lumped = _lumped(domain, prior)
        pre = FacetPreconditioner(domain, K, strong, prior=lumped) if route == "pcg" else None
        if pre is not None:
            pre.may_factorize = backend == "auto"  # (backend="pcg": CG, as asked)
        factor = linalg.factorize(K, route, kind="facet", preconditioner=pre,
                                  grid=domain.vertices)
    t2 = time.perf_counter()
    # The loop runs on facet and vertex images (grid slicing, no scattered gathers): each
    # step is exactly local_shaping() followed by the scatter C^T of Eq. 8.
    fmask = domain.mask
    vm = domain.vertex_mask
    T = domain.to_image(target.astype(float), fill=0.0) > 0
    BX = domain.to_image(bx, fill=0.0)
    BY = domain.to_image(by, fill=0.0)
    free = fmask & ~T
    Z = np.zeros(vm.shape)
    devs = [mean_angle(*grid_slopes(Z), BX, BY, T, h)]
    t_local = t_global = 0.0
    converged = False
    for it in range(1, max_iter + 1):
        ta = time.perf_counter()
        # local shaping: target plane (known) or current plane (unknown / outlier) through
        # the current centre; with mean subtraction the centre drops out (Eq. 5-6)
        gx, gy = grid_slopes(Z)
        gx = np.where(T, BX, np.where(free, gx, 0.0))
        gy = np.where(T, BY, np.where(free, gy, 0.0))
        centre = None if mean_subtraction else sum(corner_views(Z)) * (0.25 * fmask)
        rhs = grid_scatter(gx * wimg, gy * wimg, centre)[vm]
        if prhs is not None:
            rhs += prhs
        tb = time.perf_counter()
        Z[vm] = factor.solve(rhs) if mean_subtraction else rhs / valence
        tc = time.perf_counter()
        t_local += tb - ta
        t_global += tc - tb
        devs.append(mean_angle(*grid_slopes(Z), BX, BY, T, h))
        if progress is not None:
            progress(it, devs[-1])
        if abs(devs[-1] - devs[-2]) < tol:
            converged = True
            break
    z = Z[vm]
    if not converged:
        warn(
            f"dgp: no convergence in {max_iter} iterations (last change of the average "
            f"deviation {abs(devs[-1] - devs[-2]):.3g} deg"
            + (", and tol=0 never stops the loop early" if tol == 0 else f" >= tol={tol}")
            + "); raise `max_iter`", ConvergenceWarning
        )
    info = {
        "solver": "iterative",
        "mean_subtraction": mean_subtraction,
        "iterations": it,
        "converged": converged,
        "deviation": devs[1:],
        "seconds": {
            "setup": t1 - t0,
            "factorization": t2 - t1,
            "local": t_local,
            "global": t_global,
        },
        "backend": factor.backend if factor is not None else "diagonal",
    }
    if factor is not None and pre is not None and pre.direct is not None:
        info["backend"] += "+superlu"  # (the facet solve factorized: linalg.facet.solve)
    return z, info

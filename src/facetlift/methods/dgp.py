"""Surface-from-gradients by discrete geometry processing (Xie et al., CVPR 2014).

Every domain pixel is a quad facet of an (H+1) x (W+1) vertex grid (see
:mod:`facetlift.conventions`); the unknowns are the vertex heights ``z``. An iteration has two
steps.

Local shaping (Eq. 1-2)
    Each facet's four corners are projected along z onto the plane with its target normal
    through the facet's current centre ``c``: ``p_f[k] = c + p dx_k + q dy_k`` with the corner
    offsets ``(dx_k, dy_k)`` from the centre and ``(p, q) = (-n_x / n_z, -n_y / n_z)``.

Global blending with mean subtraction (Eq. 5-8)
    ``min_z sum_f || N z_f - N p_f ||^2`` with ``N = I - 11^T / 4``: ``A^T A z = A^T b`` with
    ``A = blockdiag(N) C``. ``A^T A`` never changes, so it is factorized once. Without mean
    subtraction (Eq. 4, ``mean_subtraction=False``) the target is ``z_f ~ p_f`` itself, which
    converges far more slowly (Fig. 4).

Missing samples and outliers (Sec. 4.4)
    Facets without a normal, or with ``n . (0, 0, 1) < outlier_eps``, take their *current*
    normal each iteration: the least-squares plane of their corners.

Fixed point (beyond the paper)
    In the basis mean / x-slope / y-slope / twist of a facet's corner vector, ``N p_f`` of a
    known facet is ``(h p) e_x + (h q) e_y``, independent of the current shape, and that of an
    unknown facet is the x- and y-slope part of its current ``z_f``. The loop is therefore a
    preconditioned Richardson iteration whose fixed point solves the single least-squares
    problem ``min_z sum_known ||N z_f - b_f||^2 + sum_unknown (e_twist . z_f)^2``: at an unknown
    facet only the non-planar (+-+-) part is penalised. ``solver="direct"`` solves that
    problem at once; ``solver="iterative"`` runs the paper's loop. Where the unknown facets
    leave the fixed point undetermined (a band of unknown facets across a component), a tiny
    ``flat_weight`` on their slopes selects the flattest solution, which is also where the loop
    started from a flat mesh ends.

Options (keyword-only, through :func:`facetlift.integrate`)
    solver : {"direct", "iterative"}, default "direct"
    mean_subtraction : bool, default True (only used by the iterative solver)
    max_iter : int, default 5000
    tol : float, default 1e-3
        Stop when the average angular deviation (degrees, over facets with a target normal)
        changes by less than `tol` between iterations (Sec. 5).
    outlier_eps : float, default 0.0871557 (cos 85 deg)
    backend : {"auto", "pardiso", "superlu", "amg"}, see :mod:`facetlift.linalg`
    flat_weight : float, default 1e-9
    progress : callable(iteration, deviation_deg), optional

Reference
    W. Xie, Y. Zhang, C. C. L. Wang, R. C.-K. Chung. Surface-from-Gradients: An Approach Based
    on Discrete Geometry Processing. CVPR 2014.
"""

from __future__ import annotations

import logging
import time
import warnings

import numpy as np

from .. import linalg
from ..conventions import OUTLIER_EPS
from ..problem import Problem
from ..stencil import (
    E_TWIST,
    E_X,
    E_Y,
    N_MEAN_FREE,
    facet_form,
    pin_components,
    scatter_corners,
)
from . import MethodResult

log = logging.getLogger(__name__)

SOLVERS = ("direct", "iterative")


def run(
    problem: Problem,
    *,
    solver: str = "direct",
    mean_subtraction: bool = True,
    max_iter: int = 5000,
    tol: float = 1e-3,
    outlier_eps: float = OUTLIER_EPS,
    backend: str = "auto",
    flat_weight: float = 1e-9,
    progress=None,
) -> MethodResult:
    """Integrate `problem` with the DGP method; returns vertex depths (see module docstring)."""
    if solver not in SOLVERS:
        raise ValueError(f"`solver` must be one of {SOLVERS}; got {solver!r}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"`max_iter` must be a positive integer; got {max_iter!r}")
    if not (tol >= 0):
        raise ValueError(f"`tol` must be >= 0; got {tol!r}")
    if not (0 <= outlier_eps < 1):
        raise ValueError(f"`outlier_eps` must be in [0, 1); got {outlier_eps!r}")
    if not (flat_weight > 0):
        raise ValueError(f"`flat_weight` must be > 0; got {flat_weight!r}")
    if problem.perspective:
        raise ValueError("the 'dgp' method takes orthographic input here (`K` must be None)")
    p, q = problem.slopes
    target = problem.known & (problem.normals[:, 2] >= outlier_eps)
    slopes = dgp_slopes(problem.pixel_size, p, q, target)
    if solver == "direct":  # both loops share this fixed point
        z, info = solve_direct(problem.domain, *slopes, target, backend, flat_weight)
    else:
        z, info = solve_iterative(
            problem.domain, *slopes, target, problem.pixel_size, mean_subtraction,
            int(max_iter), tol, backend, progress,
        )
    info["outliers"] = int((problem.known & ~target).sum())
    info["missing"] = int((~problem.known).sum())
    return MethodResult(vertex_depth=-z, info=info)


def dgp_slopes(h, p, q, target):
    """Per-facet target corner offsets along e_x and e_y: (h p, h q), zero where no target."""
    bx = np.where(target, h * np.nan_to_num(p), 0.0)
    by = np.where(target, h * np.nan_to_num(q), 0.0)
    return bx, by


def _check_components(domain, target):
    have = np.bincount(domain.facet_component[target], minlength=domain.n_components)
    empty = np.nonzero(have == 0)[0]
    if empty.size:
        warnings.warn(
            f"{empty.size} connected component(s) have no usable normal (e.g. component "
            f"{empty[0] + 1}); they are reconstructed flat",
            stacklevel=4,
        )


def solve_direct(domain, bx, by, target, backend="auto", flat_weight=1e-9, weights=None):
    """The fixed point of the local/global loop in one sparse solve.

    Returns vertex heights (n,) and an info dict. `weights` (m,) optionally scales each
    facet's terms.
    """
    t0 = time.perf_counter()
    _check_components(domain, target)
    w = np.ones(domain.n_facets) if weights is None else weights
    slope_block = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
    twist_block = np.outer(E_TWIST, E_TWIST)
    wk = np.where(target, w, flat_weight * w)
    K = facet_form(domain, [(wk, slope_block), (w, twist_block)])
    K = pin_components(domain, K)
    rhs = scatter_corners(domain, (w * bx)[:, None] * E_X + (w * by)[:, None] * E_Y)
    t1 = time.perf_counter()
    z = linalg.solve(K, rhs, backend)
    t2 = time.perf_counter()
    dev = average_deviation(domain, z, bx, by, target)
    info = {
        "solver": "direct",
        "iterations": 1,
        "converged": True,
        "deviation": [dev],
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    return z, info


def facet_slopes(domain, z):
    """Current (e_x . z_f, e_y . z_f) of every facet: h times its least-squares slopes."""
    zf = z[domain.corners]
    return zf @ E_X, zf @ E_Y


def average_deviation(domain, z, bx, by, target) -> float:
    """Mean angle (degrees) between current facet normals and target normals."""
    if not target.any():
        return 0.0
    gx, gy = facet_slopes(domain, z)
    gx, gy, bx, by = gx[target], gy[target], bx[target], by[target]
    # normals (-gx, -gy, h) and (-bx, -by, h) in units of h; h cancels in the angle
    a = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
    b = np.stack([-bx, -by, np.ones_like(bx)], axis=1)
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    return float(np.degrees(np.arctan2(cross, np.einsum("ij,ij->i", a, b))).mean())


def local_shaping(domain, z, bx, by, target):
    """Eq. 1-2: project each facet's corners onto its target plane through its centre.

    Facets without a target take their current least-squares plane (Sec. 4.4). Returns the
    projected corner heights (m, 4) and the facet centres (m,).
    """
    zf = z[domain.corners]
    centre = zf.mean(axis=1)
    gx = np.where(target, bx, zf @ E_X)
    gy = np.where(target, by, zf @ E_Y)
    projected = centre[:, None] + gx[:, None] * E_X + gy[:, None] * E_Y
    return projected, centre


def solve_iterative(
    domain, bx, by, target, h, mean_subtraction=True, max_iter=5000, tol=1e-3,
    backend="auto", progress=None,
):
    """The paper's local/global loop from the flat mesh; returns vertex heights and info."""
    t0 = time.perf_counter()
    _check_components(domain, target)
    if mean_subtraction:
        K = pin_components(domain, facet_form(domain, [(1.0, N_MEAN_FREE)]))
    else:
        K = None
        valence = np.bincount(domain.corners.ravel(), minlength=domain.n_vertices)
    t1 = time.perf_counter()
    factor = linalg.factorize(K, backend) if mean_subtraction else None
    t2 = time.perf_counter()
    z = np.zeros(domain.n_vertices)
    devs = [average_deviation(domain, z, bx, by, target)]
    t_local = t_global = 0.0
    converged = False
    for it in range(1, max_iter + 1):
        ta = time.perf_counter()
        projected, centre = local_shaping(domain, z, bx, by, target)
        tb = time.perf_counter()
        if mean_subtraction:
            z = factor.solve(scatter_corners(domain, projected - centre[:, None]))
        else:
            z = scatter_corners(domain, projected) / valence
        tc = time.perf_counter()
        t_local += tb - ta
        t_global += tc - tb
        devs.append(average_deviation(domain, z, bx, by, target))
        if progress is not None:
            progress(it, devs[-1])
        if abs(devs[-1] - devs[-2]) < tol:
            converged = True
            break
    if not converged:
        warnings.warn(
            f"dgp: no convergence in {max_iter} iterations (last change of the average "
            f"deviation {abs(devs[-1] - devs[-2]):.3g} deg > tol={tol}); raise `max_iter`",
            stacklevel=3,
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
    return z, info

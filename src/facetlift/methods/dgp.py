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

Perspective cameras (``K`` given)
    The unknown becomes the log-depth ``log Z`` on the pixel grid (vertex spacing one pixel,
    vertex ``(i, j)`` at pixel coordinates ``(row, col) = (i - 1/2, j - 1/2)``). A normal fixes
    the derivatives of ``log Z`` along columns and rows exactly
    (:func:`facetlift.perspective.log_depth_slopes`), which become the facets' target slopes;
    the same local/global machinery then runs unchanged. Depth is ``exp`` of the result, scaled
    so that each component's median facet depth is 1 (perspective depth is only defined up to
    scale). The outlier test uses the cosine between the normal and the direction toward the
    camera instead of ``n_z``, and its default threshold is only ``1/255`` (half a quantisation
    step of an 8-bit normal map, i.e. indistinguishable from edge-on): in log-depth every
    camera-facing normal has finite slopes, and the steep normals at silhouettes are what
    links the depth of an occluding surface to the one behind it (on the DiLiGenT bear,
    dropping the 32 normals with cosine below cos 85 deg raises the error of
    ``discontinuities=True`` from 0.062 to 0.155 mm).
    See docs/perspective.md.

Depth discontinuities (``discontinuities=True``)
    Every facet keeps its own corner values, glued to the shared vertices by a robust
    (Cauchy) penalty, so facets can separate where the normals imply a depth jump; see
    :mod:`facetlift.methods._discontinuity`. Only with ``solver="direct"``; it has its own
    multigrid-CG solver (``backend`` is not used).

Options (keyword-only, through :func:`facetlift.integrate`)
    solver : {"direct", "iterative"}, default "direct"
    mean_subtraction : bool, default True (only used by the iterative solver)
    max_iter : int, default 5000
    tol : float, default 1e-3
        Stop when the average angular deviation (degrees, over facets with a target normal)
        changes by less than `tol` between iterations (Sec. 5).
    outlier_eps : float, optional
        Default 0.0871557 (cos 85 deg) for orthographic input, 1/255 for perspective input
        (see "Perspective cameras").
    backend : {"auto", "pcg", "pardiso", "superlu", "amg"}, see :mod:`facetlift.linalg`;
        "auto" = "pcg": CG preconditioned by the exact spectral solver of the bounding box
        (:mod:`facetlift.spectral`), exact in one step on full rectangles
    flat_weight : float, default 1e-9
    progress : callable(iteration, deviation_deg), optional
    discontinuities : bool, default False
    discontinuity_k : float, default 0.3
        Corner misfit, in pixel footprints, at which the glue between a facet and a vertex
        halves (smaller cuts more readily).
    discontinuity_iter : int, default 20
        Reweightings after the smooth start.

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
from ..options import number, positive_int
from ..problem import Problem
from ..spectral import BoxPreconditioner, RectangleSolver
from ..stencil import (
    E_TWIST,
    E_X,
    E_Y,
    N_MEAN_FREE,
    corner_views,
    facet_form,
    grid_scatter,
    grid_slopes,
    pin_components,
    scatter_corners,
)
from . import MethodResult
from ._discontinuity import DEFAULT_ITER, DEFAULT_K, solve_discontinuous

log = logging.getLogger(__name__)

SOLVERS = ("direct", "iterative")


def run(
    problem: Problem,
    *,
    solver: str = "direct",
    mean_subtraction: bool = True,
    max_iter: int = 5000,
    tol: float = 1e-3,
    outlier_eps: float | None = None,
    backend: str = "auto",
    flat_weight: float = 1e-9,
    progress=None,
    discontinuities: bool = False,
    discontinuity_k: float = DEFAULT_K,
    discontinuity_iter: int = DEFAULT_ITER,
) -> MethodResult:
    """Integrate `problem` with the DGP method; returns vertex depths (see module docstring)."""
    if solver not in SOLVERS:
        raise ValueError(f"`solver` must be one of {SOLVERS}; got {solver!r}")
    max_iter = positive_int(max_iter, "max_iter")
    tol = number(tol, "tol", lambda v: v >= 0, ">= 0")
    if outlier_eps is None:
        outlier_eps = PERSPECTIVE_OUTLIER_EPS if problem.perspective else OUTLIER_EPS
    outlier_eps = number(outlier_eps, "outlier_eps", lambda v: 0 <= v < 1, "in [0, 1)")
    flat_weight = number(flat_weight, "flat_weight", lambda v: v > 0, "> 0")
    if not isinstance(mean_subtraction, (bool, np.bool_)):
        raise ValueError(f"`mean_subtraction` must be True or False; got {mean_subtraction!r}")
    if progress is not None and not callable(progress):
        raise ValueError(f"`progress` must be callable(iteration, deviation); got {progress!r}")
    if discontinuities and solver != "direct":
        raise ValueError(
            "`discontinuities`=True has its own solver; it cannot be combined with "
            f"`solver`={solver!r} (use solver='direct')"
        )
    if not (np.isfinite(discontinuity_k) and discontinuity_k > 0):
        raise ValueError(f"`discontinuity_k` must be a positive number; got {discontinuity_k!r}")
    if int(discontinuity_iter) != discontinuity_iter or discontinuity_iter < 0:
        raise ValueError(
            f"`discontinuity_iter` must be a non-negative integer; got {discontinuity_iter!r}"
        )
    bx, by, target = targets(problem, outlier_eps)
    if discontinuities:
        return _run_discontinuous(
            problem, bx, by, target, discontinuity_k, int(discontinuity_iter), flat_weight
        )
    if solver == "direct":  # both loops share this fixed point
        z, info = solve_direct(
            problem.domain, bx, by, target, backend, flat_weight, h=footprint(problem)
        )
    else:
        z, info = solve_iterative(
            problem.domain, bx, by, target, footprint(problem), mean_subtraction,
            int(max_iter), tol, backend, progress,
        )
    info["outliers"] = int((problem.known & ~target).sum())
    info["missing"] = int((~problem.known).sum())
    if problem.perspective:
        info["projection"] = "perspective"
        return MethodResult(vertex_depth=depth_from_log(problem.domain, z), info=info)
    return MethodResult(vertex_depth=-z, info=info)


def footprint(problem: Problem) -> float:
    """Width of a pixel in the unknown's units: the pixel size for heights, ``1/sqrt(fx fy)``
    for log-depth (a surface at 45 degrees to the ray changes ``log Z`` by about that much per
    pixel). With it, facet slopes ``(bx, by)`` and ``h`` give angles as for heights."""
    if problem.perspective:
        return 1.0 / float(np.sqrt(problem.K[0, 0] * problem.K[1, 1]))
    return problem.pixel_size


def _run_discontinuous(problem, bx, by, target, k, max_iter, flat_weight):
    domain = problem.domain
    _check_components(domain, target)
    scale = footprint(problem)
    z, zf, info = solve_discontinuous(
        domain, bx, by, target, scale=scale, k=k, max_iter=max_iter, flat_weight=flat_weight
    )
    info["solver"] = "discontinuous"
    info["deviation"] = [average_deviation(domain, z, bx, by, target, scale)]
    info["outliers"] = int((problem.known & ~target).sum())
    info["missing"] = int((~problem.known).sum())
    if problem.perspective:
        info["projection"] = "perspective"
        shift = _component_medians(domain, zf)
        return MethodResult(
            depth=np.exp(zf - shift[domain.facet_component]),
            vertex_depth=np.exp(z - shift[domain.vertex_component]),
            info=info,
        )
    return MethodResult(depth=-zf, vertex_depth=-z, info=info)


#: Default outlier threshold on the view cosine for perspective input (see module docstring).
PERSPECTIVE_OUTLIER_EPS = 1.0 / 255


def targets(problem: Problem, outlier_eps: float = OUTLIER_EPS):
    """Per-facet target slopes (bx, by) of the unknown and the facets that have a target.

    Orthographic: the unknown is the height, ``(bx, by) = (h p, h q)``, and a facet is an
    outlier when ``n_z < outlier_eps``. Perspective: the unknown is the log-depth
    ``log Z`` on the pixel grid (vertex spacing one pixel), ``bx = d log Z / d col`` and
    ``by = -d log Z / d row`` (the grid's y axis points up, against the row index), see
    :mod:`facetlift.perspective`; a facet is an outlier when the cosine between its normal
    and the direction toward the camera is below `outlier_eps`.

    Returns
    -------
    bx, by : (m,) float, zero where there is no target
    target : (m,) bool
    """
    if not problem.perspective:
        p, q = problem.slopes
        target = problem.known & (problem.normals[:, 2] >= outlier_eps)
        bx, by = dgp_slopes(problem.pixel_size, p, q, target)
        return bx, by, target
    from ..perspective import log_depth_slopes, view_cosine

    r, c = problem.domain.pixels
    n = np.where(problem.known[:, None], problem.normals, 0.0)
    with np.errstate(invalid="ignore"):
        cos = view_cosine(problem.K, r, c, n)
    target = problem.known & (cos >= outlier_eps)
    du, dv = log_depth_slopes(problem.K, r, c, np.where(target[:, None], n, [0.0, 0.0, 1.0]))
    return np.where(target, du, 0.0), np.where(target, -dv, 0.0), target


def depth_from_log(domain, z):
    """Vertex depths ``exp(z)`` scaled so that each component's median facet depth is 1."""
    med = _component_medians(domain, domain.facet_centres(z))
    return np.exp(z - med[domain.vertex_component])


def _component_medians(domain, facet_values):
    from scipy import ndimage

    labels = domain.facet_component + 1
    index = np.arange(1, domain.n_components + 1)
    return np.atleast_1d(ndimage.median(facet_values, labels, index))


def dgp_slopes(h, p, q, target):
    """Per-facet target corner offsets along e_x and e_y: (h p, h q), zero where no target."""
    bx = np.where(target, h * np.nan_to_num(p), 0.0)
    by = np.where(target, h * np.nan_to_num(q), 0.0)
    return bx, by


def _check_components(domain, target):
    """Warn about components without any target normal; returns their indices."""
    have = np.bincount(domain.facet_component[target], minlength=domain.n_components)
    empty = np.nonzero(have == 0)[0]
    if empty.size:
        warnings.warn(
            f"{empty.size} connected component(s) have no usable normal (e.g. component "
            f"{empty[0] + 1}); they are reconstructed flat",
            stacklevel=4,
        )
    return empty


def _flatten(domain, z, empty):
    """Components without a target normal are flat (their tilt is only weakly determined)."""
    if empty.size:
        z[np.isin(domain.vertex_component, empty)] = 0.0
    return z


def solve_direct(
    domain, bx, by, target, backend="auto", flat_weight=1e-9, weights=None, *, h=1.0
):
    """The fixed point of the local/global loop in one sparse solve.

    Returns vertex heights (n,) and an info dict. `weights` (m,) optionally scales each
    facet's terms; `h` is the vertex spacing (for the reported angular deviation).
    """
    t0 = time.perf_counter()
    empty = _check_components(domain, target)
    w = np.ones(domain.n_facets) if weights is None else weights
    slope_block = np.outer(E_X, E_X) + np.outer(E_Y, E_Y)
    twist_block = np.outer(E_TWIST, E_TWIST)
    wk = np.where(target, w, flat_weight * w)
    rhs = scatter_corners(domain, (w * bx)[:, None] * E_X + (w * by)[:, None] * E_Y)
    # Route. With every normal known the operator is close to that of the bounding box, and
    # CG preconditioned by the box's exact spectral solver converges in ~25-40 iterations at
    # any resolution (exact at once on a full rectangle). Facets without a target only carry
    # the twist term plus the tiny `flat_weight`: clusters of them (at silhouettes) create
    # near-null modes that CG resolves slowly (hundreds of iterations measured on a real
    # normal map), so then a sparse factorization is used unless the system is too large.
    simple = weights is None and bool(target.all())
    use_pcg = backend == "pcg" or (
        backend == "auto" and (simple or domain.n_vertices > linalg.AMG_THRESHOLD)
    )
    pre = BoxPreconditioner(domain) if use_pcg else None
    if pre is not None and pre.exact and simple:
        t1 = time.perf_counter()
        z = pre(rhs)  # the operator is the box operator itself: one exact spectral solve
        used, cg_its = "spectral", 0
    else:
        K = facet_form(domain, [(wk, slope_block), (w, twist_block)])
        if pre is None:
            K = pin_components(domain, K)
        t1 = time.perf_counter()
        z = linalg.solve(K, rhs, "pcg" if pre is not None else backend, preconditioner=pre)
        used = "pcg-spectral" if pre is not None else backend
        cg_its = linalg.pcg.last_iterations if pre is not None else None
    z = _flatten(domain, z, empty)
    t2 = time.perf_counter()
    dev = average_deviation(domain, z, bx, by, target, h)
    info = {
        "solver": "direct",
        "backend": used,
        "iterations": 1,
        "converged": True,
        "deviation": [dev],
        "seconds": {"setup": t1 - t0, "solve": t2 - t1},
    }
    if cg_its is not None:
        info["cg_iterations"] = cg_its
    return z, info


def facet_slopes(domain, z):
    """Current (e_x . z_f, e_y . z_f) of every facet: h times its least-squares slopes."""
    zf = z[domain.corners]
    return zf @ E_X, zf @ E_Y


def average_deviation(domain, z, bx, by, target, h=1.0) -> float:
    """Mean angle (degrees) between current facet normals and target normals.

    `bx`, `by` and the current facet slopes are height differences across a facet of width
    `h`, so the normals are ``(-gx, -gy, h)`` and ``(-bx, -by, h)``.
    """
    if not target.any():
        return 0.0
    gx, gy = facet_slopes(domain, z)
    return _mean_angle(gx, gy, bx, by, target, h)


def _mean_angle(gx, gy, bx, by, target, h) -> float:
    """Mean angle (degrees) between normals (-gx, -gy, h) and (-bx, -by, h) where `target`."""
    if not target.any():
        return 0.0
    gx, gy, bx, by = gx[target], gy[target], bx[target], by[target]
    # atan2(|a x b|, a . b), accurate near zero unlike arccos
    h2 = h * h
    cross = np.sqrt(h2 * ((by - gy) ** 2 + (gx - bx) ** 2) + (gx * by - gy * bx) ** 2)
    return float(np.degrees(np.arctan2(cross, gx * bx + gy * by + h2)).mean())


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
    rect = backend in ("auto", "pcg") and bool(domain.mask.all())
    if mean_subtraction and not rect:
        K = pin_components(domain, facet_form(domain, [(1.0, N_MEAN_FREE)]))
    elif not mean_subtraction:
        valence = np.bincount(domain.corners.ravel(), minlength=domain.n_vertices)
    t1 = time.perf_counter()
    if not mean_subtraction:
        factor = None
    elif rect:  # A^T A of a full rectangle is diagonalised by the DCT-I: exact, O(n log n)
        factor = RectangleSolver(*domain.shape)
    else:
        pre = BoxPreconditioner(domain) if backend in ("auto", "pcg") else None
        factor = linalg.factorize(K, backend, preconditioner=pre)
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
    devs = [_mean_angle(*grid_slopes(Z), BX, BY, T, h)]
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
        rhs = grid_scatter(gx, gy, centre)[vm]
        tb = time.perf_counter()
        Z[vm] = factor.solve(rhs) if mean_subtraction else rhs / valence
        tc = time.perf_counter()
        t_local += tb - ta
        t_global += tc - tb
        devs.append(_mean_angle(*grid_slopes(Z), BX, BY, T, h))
        if progress is not None:
            progress(it, devs[-1])
        if abs(devs[-1] - devs[-2]) < tol:
            converged = True
            break
    z = Z[vm]
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

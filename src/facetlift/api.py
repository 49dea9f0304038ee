"""The public entry point :func:`integrate`."""

from __future__ import annotations

import logging
import time

import numpy as np

from . import methods
from .domain import Domain
from .problem import Problem, prepare
from .surface import Surface

log = logging.getLogger("facetlift")


def integrate(
    normals,
    mask=None,
    *,
    method: str = "dgp",
    pixel_size: float = 1.0,
    known=None,
    K=None,
    backfacing: str = "error",
    **options,
) -> Surface:
    """Reconstruct a surface from a normal map.

    Parameters
    ----------
    normals : (H, W, 3) array_like of float
        Normals, x right, y up, z toward the viewer (:mod:`facetlift.conventions`); they are
        renormalised. NaN marks a missing sample inside the mask.
    mask : (H, W) array_like of bool, optional
        Integration domain; any shape, several connected components allowed (each gets its
        own constant). Default: the pixels with finite, non-zero normals.
    method : str
        A registered method, see ``facetlift.methods.REGISTRY`` or ``facetlift methods``.
    pixel_size : float
        Pixel width in world units for orthographic input.
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the other mask pixels are missing samples.
    K : (3, 3) array_like, optional
        Perspective intrinsics (OpenCV layout); None for an orthographic view.
    backfacing : {"error", "outlier"}
        Raise on normals with n_z <= 0 inside the mask, or treat them as missing samples.
    **options
        Method-specific keyword options (e.g. ``solver``, ``max_iter``, ``tol`` for "dgp").

    Returns
    -------
    Surface

    Raises
    ------
    ValueError
        Bad input (the message names the argument), an unknown method or option, or input
        the method cannot take (missing samples, perspective).
    facetlift.linalg.SolverError
        The linear solver failed.
    """
    t0 = time.perf_counter()
    info = methods.get(method)
    problem = prepare(
        normals, mask, known=known, pixel_size=pixel_size, K=K, backfacing=backfacing
    )
    return solve(problem, method, info=info, t0=t0, **options)


def solve(problem: Problem, method: str = "dgp", *, info=None, t0=None, **options) -> Surface:
    """Run `method` on a prepared :class:`~facetlift.problem.Problem`."""
    t0 = time.perf_counter() if t0 is None else t0
    info = info or methods.get(method)
    allowed = info.options()
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise ValueError(
            f"unknown option(s) {unknown} for method {method!r}; valid options: {sorted(allowed)}"
        )
    if not problem.known.all() and not info.missing:
        raise ValueError(
            f"method {method!r} cannot take missing samples ({int((~problem.known).sum())} "
            "pixels in the mask have no normal); fill them or use a method that can, e.g. 'dgp'"
        )
    if problem.perspective and not info.perspective:
        raise ValueError(f"method {method!r} does not support perspective input (`K`)")
    t1 = time.perf_counter()
    cropped, offset = crop(problem)
    result = info.run(cropped, **options)
    t2 = time.perf_counter()
    surface = uncrop(make_surface(cropped, result), problem, offset)
    out = dict(result.info)
    out["method"] = method
    seconds = dict(out.get("seconds", {}))
    seconds["prepare"] = t1 - t0
    seconds["total"] = time.perf_counter() - t0
    seconds["method"] = t2 - t1
    out["seconds"] = seconds
    surface.info = out
    log.info("%s: %s", method, {k: v for k, v in out.items() if k != "deviation"})
    return surface


def crop(problem: Problem) -> tuple[Problem, tuple[int, int]]:
    """The same problem on the bounding box of its mask, and the box's (row, col) offset.

    Methods then work on arrays the size of the object, not of the image (a small object in
    a large photo). Facet order (row-major) is unchanged; a perspective ``K`` gets its
    principal point shifted so that every pixel keeps its viewing ray.
    """
    mask = problem.domain.mask
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    if (r1 - r0, c1 - c0) == mask.shape:
        return problem, (0, 0)
    K = None
    if problem.K is not None:
        K = problem.K.copy()
        K[0, 2] -= c0
        K[1, 2] -= r0
    sub = Problem(
        domain=Domain.from_mask(mask[r0:r1, c0:c1]),
        normals=problem.normals,
        known=problem.known,
        pixel_size=problem.pixel_size,
        K=K,
    )
    return sub, (int(r0), int(c0))


def uncrop(surface: Surface, problem: Problem, offset: tuple[int, int]) -> Surface:
    """Place a surface computed by :func:`crop`'s sub-problem back into the full image."""
    if offset == (0, 0) and surface.shape == problem.domain.shape:
        return surface
    r0, c0 = offset
    H, W = problem.domain.shape
    h, w = surface.shape
    depth = np.full((H, W), np.nan)
    depth[r0 : r0 + h, c0 : c0 + w] = surface.depth
    vdepth = np.full((H + 1, W + 1), np.nan)
    vdepth[r0 : r0 + h + 1, c0 : c0 + w + 1] = surface.vertex_depth
    return Surface(
        depth=depth,
        vertex_depth=vdepth,
        mask=problem.domain.mask.copy(),
        pixel_size=problem.pixel_size,
        K=problem.K,
    )


def make_surface(problem: Problem, result: methods.MethodResult) -> Surface:
    """Fill facet and vertex depths from whichever the method returned, then fix constants."""
    d = problem.domain
    if result.vertex_depth is not None:
        vdep = np.asarray(result.vertex_depth, dtype=float)
        fdep = d.facet_centres(vdep) if result.depth is None else np.asarray(result.depth, float)
    elif result.depth is not None:
        fdep = np.asarray(result.depth, dtype=float)
        counts = np.bincount(d.corners.ravel(), minlength=d.n_vertices)
        vdep = np.bincount(d.corners.ravel(), np.repeat(fdep, 4), d.n_vertices) / counts
    else:  # pragma: no cover - a method bug
        raise RuntimeError("method returned neither depth nor vertex_depth")
    if not problem.perspective:
        shift = np.bincount(d.facet_component, fdep, d.n_components) / d.component_sizes
        fdep = fdep - shift[d.facet_component]
        vdep = vdep - shift[d.vertex_component]
    return Surface(
        depth=d.to_image(fdep),
        vertex_depth=d.to_vertex_image(vdep),
        mask=d.mask.copy(),
        pixel_size=problem.pixel_size,
        K=problem.K,
    )

"""The public entry points :func:`integrate` and :func:`solve`."""

from __future__ import annotations

import logging
import time

import numpy as np

from . import memory, methods
from .domain import Domain
from .linalg import SolverError
from .options import validate
from .problem import Problem, prepare
from .surface import Surface

log = logging.getLogger("facetlift")


def integrate(
    normals,
    mask=None,
    *,
    method: str = "dgp",
    pixel_size: float = 1.0,
    K=None,
    known=None,
    discontinuities: bool = False,
    solver: str | None = None,
    backfacing: str = "missing",
    outlier_eps: float | None = None,
    max_memory=None,
    **options,
) -> Surface:
    """Reconstruct a surface from a normal map.

    Parameters
    ----------
    normals : (H, W, 3) array_like of float
        Normals, x right, y up, z toward the viewer (:mod:`facetlift.conventions`); they are
        renormalised. NaN marks a missing sample inside the mask; pixels outside the mask may
        hold anything.
    mask : (H, W) array_like of bool, optional
        Integration domain; any shape, several connected components allowed (each gets its
        own constant). Default: the pixels with finite, non-zero normals.
    method : str
        A registered method, see ``facetlift.methods.REGISTRY`` or ``facetlift methods``.
    pixel_size : float
        Pixel width in world units for orthographic input.
    K : (3, 3) array_like, optional
        Perspective intrinsics (OpenCV layout); None for an orthographic view.
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the other mask pixels are missing samples.
    discontinuities : bool
        Let the depth jump where the normals imply it (methods that declare the capability,
        e.g. "dgp").
    solver : str, optional
        The method's solver, for methods that have the option (``"direct"`` or
        ``"iterative"`` for "dgp").
    backfacing : {"missing", "error"}
        Normals facing away from the camera inside the mask: missing samples, or an error.
    outlier_eps : float, optional
        Grazing threshold on the cosine between a normal and the direction toward the camera
        (the paper's outlier rule); below it a normal is a missing sample. Default: the
        camera's (:mod:`facetlift.camera`).
    **options
        Method options (``facetlift methods`` lists them, with types and defaults).

    Returns
    -------
    Surface

    Raises
    ------
    ValueError
        Bad input (the message names the argument), an unknown method or option, a bad
        option value, an option that does not apply to the chosen route, or input the method
        cannot take (perspective, discontinuities).
    facetlift.SolverError
        The solver failed or produced non-finite depth inside the mask.
    facetlift.errors.MemoryLimitError
        The job's estimated peak memory exceeds `max_memory`.

    Warns
    -----
    UserWarning
        Once, when normals inside the mask cannot be used (non-finite, zero-length,
        back-facing or grazing): they become missing samples (``info["input"]`` counts them).
    """
    t0 = time.perf_counter()
    info = methods.get(method)
    if discontinuities:
        options["discontinuities"] = _check_discontinuities(info, discontinuities)
    if solver is not None:
        options["solver"] = solver
    problem = prepare(
        normals, mask, known=known, pixel_size=pixel_size, K=K, backfacing=backfacing,
        outlier_eps=outlier_eps,
    )
    return solve(problem, method, t0=t0, max_memory=max_memory, **options)


def _check_discontinuities(info: methods.MethodInfo, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"`discontinuities` must be True or False; got {value!r}")
    if not info.discontinuities:
        able = sorted(k for k, v in methods.REGISTRY.items() if v.discontinuities)
        raise ValueError(
            f"method {info.name!r} does not handle depth discontinuities; methods that do: "
            f"{able}"
        )
    return True


def solve(
    problem: Problem, method: str = "dgp", *, t0: float | None = None, max_memory=None,
    **options,
):
    """Run `method` on a prepared :class:`~facetlift.problem.Problem`.

    Every option is validated against the method's declarations before it runs
    (:func:`facetlift.options.validate`), and the job's peak memory is planned against
    `max_memory` (:func:`facetlift.memory.plan`); see :func:`integrate` for what is raised.
    """
    t0 = time.perf_counter() if t0 is None else t0
    info = methods.get(method)
    values = validate(info.specs(), options, method)
    if problem.perspective and not info.perspective:
        able = sorted(k for k, v in methods.REGISTRY.items() if v.perspective)
        raise ValueError(
            f"method {method!r} does not support perspective input (`K`); methods that do: "
            f"{able}"
        )
    if not problem.usable.all() and not info.missing:
        raise ValueError(
            f"method {method!r} cannot take missing samples ({int((~problem.usable).sum())} "
            "pixels in the mask have no usable normal); fill them or use a method that can, "
            "e.g. 'dgp'"
        )
    plan = memory.plan(problem, method, values, max_memory)
    t1 = time.perf_counter()
    cropped, offset = crop(problem)
    result = info.run(cropped, **values)
    t2 = time.perf_counter()
    surface = uncrop(make_surface(cropped, result, method), problem, offset)
    out = dict(result.info)
    out["method"] = method
    out["projection"] = problem.camera.projection
    out["input"] = dict(problem.counts)
    out["memory_estimate"] = plan.estimate
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
    a large photo). Facet order (row-major) is unchanged; the camera is cropped too, so that
    every pixel keeps its viewing ray.
    """
    mask = problem.domain.mask
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    if (r1 - r0, c1 - c0) == mask.shape:
        return problem, (0, 0)
    sub = problem.restrict(
        Domain.from_mask(mask[r0:r1, c0:c1]), problem.camera.cropped(int(r0), int(c0))
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
        depth=depth, vertex_depth=vdepth, mask=problem.domain.mask.copy(), camera=problem.camera
    )


def make_surface(problem: Problem, result: methods.MethodResult, method: str = "") -> Surface:
    """Depth from the method's values of the camera's unknown: facet and vertex values filled
    from whichever the method returned, each component's constant fixed by the camera's
    gauge (:meth:`facetlift.camera.Camera.gauge`), then converted to depth.

    Raises
    ------
    SolverError
        If a value inside the domain is not finite.
    """
    d = problem.domain
    if result.vertex_values is not None:
        vval = np.asarray(result.vertex_values, dtype=float)
        fval = d.facet_centres(vval) if result.values is None else np.asarray(result.values, float)
    elif result.values is not None:
        fval = np.asarray(result.values, dtype=float)
        counts = np.bincount(d.corners.ravel(), minlength=d.n_vertices)
        vval = np.bincount(d.corners.ravel(), np.repeat(fval, 4), d.n_vertices) / counts
    else:  # pragma: no cover - a method bug
        raise RuntimeError("method returned neither values nor vertex_values")
    if not (np.isfinite(fval).all() and np.isfinite(vval).all()):
        bad = int((~np.isfinite(fval)).sum())
        raise SolverError(
            f"method {method!r} produced non-finite depth at {bad} of {fval.size} pixels inside "
            "the mask"
        )
    cam = problem.camera
    shift = cam.gauge(fval, d.facet_component, d.n_components)
    depth = cam.to_depth(fval - shift[d.facet_component])
    vdepth = cam.to_depth(vval - shift[d.vertex_component])
    return Surface(
        depth=d.to_image(depth), vertex_depth=d.to_vertex_image(vdepth), mask=d.mask.copy(),
        camera=cam,
    )

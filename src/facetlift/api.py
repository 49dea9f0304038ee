"""The public entry points :func:`integrate` and :func:`solve`."""

from __future__ import annotations

import contextlib
import functools
import inspect
import logging
import time

import numpy as np

from . import frames, memory, methods
from ._warnings import recording, reemit, said_if_raised, warn
from .conventions import CORNER_OFFSETS
from .domain import Domain
from .linalg import SolverError
from .metrics import diagnose
from .options import validate
from .prior_fit import check as prior_fit_check
from .prior_outliers import DENSE
from .problem import Problem, check_prior_outliers, normals_from_gradients
from .problem import prepare as _prepare
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
    discontinuities: bool | None = None,
    solver: str | None = None,
    backfacing: str = "missing",
    outlier_eps: float | None = None,
    normal_frame: str | None = None,
    normal_rotation=None,
    max_memory=None,
    prior=None,
    prior_weight=None,
    confidence=None,
    prior_blur=None,
    prior_outliers: str = "remove",
    prior_fit: str | None = None,
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
        own constant). Default: the pixels with finite, non-zero normals (isolated ones left
        out, with a warning).
    method : str
        A registered method, see ``facetlift.methods.REGISTRY`` or ``facetlift methods``.
    pixel_size : float
        Pixel width in world units for orthographic input.
    K : (3, 3) array_like, nine numbers (row by row), four (fx, fy, cx, cy) or Pinhole, optional
        Perspective intrinsics (OpenCV layout: cx a column, cy a row from the top); None for
        an orthographic view.
    known : (H, W) array_like of bool, optional
        Pixels whose normal is given; the other mask pixels are missing samples.
    discontinuities : bool, optional
        Let the depth jump where the normals imply it (methods that declare the capability,
        e.g. "dgp"). None keeps the method's default (False for "dgp", True for "bini");
        False turns it off where the method has the option (it was ignored: "bini" kept its
        bilateral weights).
    solver : str, optional
        The method's solver, for methods that have the option (``"direct"`` or
        ``"iterative"`` for "dgp").
    backfacing : {"missing", "error"}
        Normals facing away from the camera inside the mask: missing samples, or an error.
    outlier_eps : float, optional
        Grazing threshold on the cosine between a normal and the direction toward the camera
        (the paper's outlier rule); below it a normal is a missing sample. Default: the
        camera's (:mod:`facetlift.camera`), except with ``discontinuities=True`` for "dgp":
        0.0436194 (cos 87.5 deg) for every camera (``facetlift.methods.JUMP_GRAZING``;
        docs/results.md, "Discontinuities: the grazing rule").
    normal_frame : str, optional
        The frame `normals` are given in: ``"opengl"`` (the default, facetlift's own),
        ``"directx"`` (alias ``"y_down"``), ``"opencv"`` or an axis string such as
        ``"x,-y,-z"`` (:mod:`facetlift.frames`).
    normal_rotation : (3, 3) array_like, optional
        For normals given in world space (Blender's Normal pass, a multi-view pipeline's):
        the rotation from world to the camera frame named by `normal_frame`, applied at every
        pixel (``n_cam = R @ n_world``) before the frame and before the checks that look at
        which way the normals face. A 3x4 or 4x4 pose gives its upper-left 3x3. Blender:
        ``camera.matrix_world.to_3x3().transposed()`` with the default frame; COLMAP: the
        image's world-to-camera ``R`` with ``normal_frame="opencv"`` (docs/conventions.md,
        "Normals in world space"). It must be a proper rotation (orthonormal within
        ``facetlift.frames.ROTATION_TOLERANCE``, determinant +1). NaN normals stay missing.
    max_memory : int, float or str, optional
        Refuse the job (MemoryLimitError) if its estimated peak memory exceeds this many bytes
        (or a size such as ``"8G"``). Default: the available physical memory minus a margin,
        and the process's address-space limit (:mod:`facetlift.memory`).
    prior : (H, W) array_like of float or (rows, cols, depths[, weights]), optional
        Depth known besides the normals, in the output's depth convention (orthographic:
        depth along the viewing axis in world units; perspective: metric z-depth > 0), NaN
        where unknown: a dense map, a sparse one or a few points; or three arrays of pixel
        rows, columns (rounded to the nearest pixel) and depths, and optionally a fourth of
        per-point weights >= 0 that multiply `prior_weight` (points in one pixel: their
        weighted mean depth, and the weights' weighted mean). Every connected component
        with a sample gets its constant (and, for a perspective camera, its scale) from the
        prior: depth is then absolute (metric for a pinhole camera); components without a
        sample keep the usual convention, and ``info["prior"]["gauged_components"]`` names
        them. See docs/fusion.md. (A string is the option ``prior`` of a method that has one,
        e.g. regularization's smoothness prior.)
    prior_weight : float or (H, W) array_like of float
        Weight (>= 0) of the prior term ``w (u - u_prior)^2`` of each sample, relative to the
        normal term of one pixel: 1.0 makes one prior sample count as much as one pixel's
        normal (a depth error at a sample costs as much as the same change of depth across
        one pixel against the normals). Dimensionless: independent of image size and depth
        units (for a perspective camera both terms are in log-depth). Large values fit the
        prior exactly where given; the largest must be at least 1e-10 of the normals' weight
        (:data:`facetlift.problem.PRIOR_RATIO`). Default (None): 1, or 0.003 with a `prior_blur`
        (``facetlift.problem.BLURRED_PRIOR_WEIGHT``: a blurred prior is met by undoing its blur,
        which weights above about 0.03 turn into its own errors; docs/fusion.md).
    confidence : (H, W) array_like of float, optional
        Weight (>= 0) of each pixel's normal term; 0 is the same as a missing normal, 1 the
        default everywhere; positive values below 1e-8 of the largest are raised to it, with
        a warning (:data:`facetlift.problem.CONFIDENCE_RANGE`). For methods with the
        ``confidence`` capability.
    prior_blur : float, optional
        A coarse or blurred prior (a monocular network's depth, a low-resolution sensor, a
        depth map upsampled from a coarse grid): the standard deviation, in pixels, of the
        Gaussian blur it is seen through. The prior is then compared with the result blurred
        alike, so it fixes the low frequencies and offsets while the normals keep the detail
        (docs/fusion.md, "Blurred priors"): for a map of block means blurred by one coarse
        pixel and upsampled bilinearly by a factor f, 1.1 f (block means alone, 0.5 f, did
        worse than pixel by pixel on the measured cases: compare both). With
        ``discontinuities=True`` a surface that runs away from the prior (beyond its depth
        range) is integrated with the prior pixel by pixel instead, with a warning
        (``info["prior_blur"]["fallback"]``). None or 0: compared pixel by pixel. For methods
        with the ``prior_blur`` capability ("dgp" with ``solver="direct"``).
    prior_outliers : {"remove", "keep"}
        "remove" (default; None too): samples of a sparse prior (on at most a quarter of the
        mask's pixels, not blurred) that disagree with every neighbouring sample they can be
        compared with, along the normals, are left out before the solve, counted in
        ``info["prior"]["outliers"]`` (``skipped`` says why where the prior is not checked)
        and named in a warning (mismatched SfM points, a sensor's stray returns:
        docs/fusion.md, "Outlier samples"); "keep" uses every sample.
    prior_fit : {"none", "affine", "scale", "disparity"}
        What the `prior` is known up to. "none" (default; None too): depth in the output's
        convention. "affine": depth up to an unknown scale and shift (``depth = a * prior +
        b``, a > 0: a monocular network's affine-invariant depth); "scale": up to a scale;
        "disparity" (pinhole camera only): an affine-invariant inverse depth (``1 / depth = a *
        prior + b``; MiDaS, Depth Anything's relative models). The route then runs twice: on
        the normals alone, then with the prior aligned to that surface by a robust fit that
        uses only the surface's local shape: differences between nearby samples in one of its
        connected pieces with no cut between them (the pieces' offsets, and the levels a jump
        it did not cut misplaced, are left to the prior), or, where that leaves the scale
        undetermined, the shape within each piece (:mod:`facetlift.prior_fit`);
        ``info["prior"]["fit"]`` gives
        ``method``, ``scale``, ``shift`` and the scale's relative error. The result keeps the
        normals' own units (a pinhole camera's median depth near 1, not metric). A prior
        that cannot be aligned (constant, running against the normals, its scale
        undetermined) is left out with a warning: the result is then the normals-only one
        (``info["prior"]["left_out"]`` True; False where the fitted prior was used).
        docs/fusion.md, "A monocular depth map".
    **options
        Method options (``facetlift methods`` lists them, with types and defaults).
        ``progress=True`` shows the command line's progress bar on stderr (the methods'
        ``progress`` option otherwise takes a callable ``progress(iteration, value)``, which
        may carry a ``stage`` attribute: :mod:`facetlift._progress`).

    Returns
    -------
    Surface
        ``info["mean_deviation"]`` is the mean angle (degrees) between the input normals and
        the result's facets (``info["deviation_over_10"]`` the share of them deviating by
        more than 10 degrees); ``info["integrability"]`` compares the field with flipped
        ones.

    Raises
    ------
    ValueError
        Bad input (the message names the argument), an unknown method or option, a bad
        option value, an option that does not apply to the chosen route, or input the method
        cannot take (perspective, discontinuities), unsigned integers other than uint8/uint16,
        or normals that look [0, 1]-encoded or face away from the viewer
        (:func:`facetlift.frames.checked`); a `normal_rotation` that is no rotation
        (:func:`facetlift.frames.check_rotation`); a `prior` or `confidence` of the wrong shape,
        negative weights, a prior without a finite sample in the mask, non-positive
        perspective prior depth in a map where none is positive or more than 1 % of the nonzero
        samples are negative (fewer, zeros and inf are left out with a warning, as points of a
        ``(rows, cols, depths)`` prior with a non-positive depth are, unless every one is), a
        confidence with more than 1 % negative pixels in the mask (fewer are missing normals,
        +inf the largest confidence), or a prior / confidence for a method without the
        capability.
    facetlift.SolverError
        The solver failed or produced non-finite depth inside the mask.
    facetlift.errors.MemoryLimitError
        The job's estimated peak memory exceeds `max_memory`.

    Warns
    -----
    facetlift.UnusableNormalsWarning
        Once, when normals inside the mask cannot be used (infinite, zero-length,
        back-facing or grazing; with ``discontinuities=True`` also isolated outliers,
        ``MethodInfo.jump_isolated``): they become missing samples (``info["input"]`` counts
        them).
        A NaN normal is a missing sample by definition: counted as ``missing``, not warned
        about.
    facetlift.FrameWarning
        When `normals` is uint8/uint16 (decoded as ``v / max * 2 - 1``). When the field is far
        more integrable with y or x flipped (:func:`facetlift.frames.flip_check`).
    facetlift.ConvergenceWarning
        When an iterative method stops at its iteration cap, or a linear solve did not
        converge (the discontinuity route's cap is in ``info["converged"]`` only: a budget).
    UserWarning
        Others (isolated pixels, components without a normal, a prior's free components...).
        All are subclasses of UserWarning: ``warnings.simplefilter("error",
        facetlift.FrameWarning)`` turns one kind into an error.
    """
    t0 = time.perf_counter()
    info = methods.get(method)
    if normal_rotation is not None:  # (before the input's checks: its error alone)
        normal_rotation = frames.check_rotation(normal_rotation)
    if isinstance(prior, str):  # a method option named "prior" (regularization's smoothness
        if "prior" not in info.options():  # prior, a string), not a depth prior
            raise ValueError(
                f"`prior` must be a depth map (H, W) or samples (rows, cols, depths); got the "
                f"string {prior!r} (a string is the option 'prior' of a method that has one, "
                f"e.g. regularization; {method!r} has none)")
        options["prior"] = prior
        prior = None
        # (the depth prior's own settings beside it were refused as "prior=None", the string
        # given: an audit)
        given = [name for name, v, unset in (
            ("prior_weight", prior_weight, (None, 1.0)), ("prior_blur", prior_blur, (None,)),
            ("prior_outliers", prior_outliers, (None, "remove")),
            ("prior_fit", prior_fit, (None, "none"))) if not any(
                v is u or (isinstance(v, (str, float, int)) and v == u) for u in unset)]
        if given:
            raise ValueError(
                f"{', '.join(f'`{g}`' for g in given)} belong(s) to a depth prior; "
                f"prior={options['prior']!r} is {method}'s smoothness option (its weight is "
                "`lam`): leave them out, or give a depth map as the prior")
    fit_kind = prior_fit_check(prior_fit, prior is not None, K is not None)
    if fit_kind != "none":
        if not info.prior:
            raise _lacks(method, "prior")
        return _integrate_fitted(
            fit_kind, normals, mask, method=method, pixel_size=pixel_size, K=K, known=known,
            discontinuities=discontinuities, solver=solver, backfacing=backfacing,
            outlier_eps=outlier_eps, normal_frame=normal_frame,
            normal_rotation=normal_rotation, max_memory=max_memory, prior=prior,
            prior_weight=prior_weight, confidence=confidence, prior_blur=prior_blur,
            prior_outliers=prior_outliers, **options)
    note = isolated = share = None
    if discontinuities is not None and not _check_discontinuities(info, discontinuities):
        if "discontinuities" in info.options():  # (an explicit False, e.g. for "bini")
            options["discontinuities"] = False
    elif discontinuities:
        options["discontinuities"] = True
        isolated = info.jump_isolated
        if outlier_eps is None and info.jump_grazing is not None:
            outlier_eps = info.jump_grazing
            share = info.jump_grazing_share
            note = (f"the rule of {method!r} with discontinuities=True, cos "
                    f"{np.degrees(np.arccos(outlier_eps)):.3g} deg; "
                    "outlier_eps / --outlier-eps sets another")
    if solver is not None:
        options["solver"] = solver
    if K is not None and not info.perspective:  # (before the input's warnings: a user's)
        raise _no_perspective(method)
    _progress_option(options, info)
    # (a mistyped option is refused before the input is read and checked: its warnings, e.g.
    # about grazing normals, came first and hid the one line that mattered; progress=True is
    # a bar made in _solve)
    validate(info.specs(), {**options, "progress": _no_progress}
             if options.get("progress") is True else options, method,
             keywords=_INTEGRATE_KEYWORDS, hints=_keyword_hints(options))
    normals = frames.checked(normals, mask, frame=normal_frame, rotation=normal_rotation)
    if prior is not None and not info.prior:
        # (the method refuses the prior in _solve: no outlier check to warn about before)
        check_prior_outliers(prior_outliers)
        prior_outliers = "keep"
    # (the flip check's hint and prepare's facing-away advice are relative to the frame
    # given; none given: the caller's, e.g. a reader's, stays. prepare outside it advised the
    # frame already given, a review)
    # (and the words on world-space normals: whether a rotation was given)
    with (contextlib.nullcontext() if frames.is_identity(normal_frame)
          else frames.read_in(normal_frame)), frames.rotation_given(normal_rotation is not None):
        problem = _prepare(
            normals, mask, known=known, pixel_size=pixel_size, K=K, backfacing=backfacing,
            outlier_eps=outlier_eps, prior=prior, prior_weight=prior_weight,
            confidence=confidence, grazing_note=note, prior_blur=prior_blur,
            prior_outliers=prior_outliers, isolated=isolated, grazing_share=share,
            steep_isolated=info.steep_isolated and not options.get("discontinuities"),
        )
        surface = _solve(problem, method, t0, max_memory, options)
    # (how the caller's normals reach the camera's facetlift frame: Surface.save's
    # normals= for points.ply and the report take the same array, and were written in the
    # caller's frame, an audit)
    if not frames.is_identity(normal_frame):
        surface.info["normal_frame"] = frames.axis_string(normal_frame)
    if normal_rotation is not None:
        surface.info["normal_rotation"] = np.asarray(normal_rotation, float).tolist()
    return surface


#: :func:`integrate`'s own keyword arguments, offered where a misspelt one looks like one.
_INTEGRATE_KEYWORDS = tuple(k for k in inspect.signature(integrate).parameters
                            if k not in ("normals", "options"))


def _keyword_hints(options: dict) -> dict:
    """What to give instead of keywords :func:`integrate` has not but users expect (an
    audit: ``fov=60``, the command line's --fov, was told "unknown option(s) ['fov']" and
    the method's options alone), for :func:`facetlift.options.validate`."""
    hints = {}
    if "camera" in options:  # (prepare's keyword: an audit was told of dgp's options alone)
        hints["camera"] = ("integrate takes the camera as K= (a 3 x 3 matrix, nine or four "
                           "numbers or a facetlift.camera.Pinhole) or pixel_size= (orthographic); "
                           "camera= is facetlift.prepare's")
    if "fov" not in options:
        return hints
    fov = options["fov"]
    text = (f"{fov:g}" if isinstance(fov, (int, float)) and not isinstance(fov, bool)
            else repr(fov))
    hints["fov"] = ("integrate takes no field of view: give the camera it makes as "
                    f"K=facetlift.camera.K_from_fov(normals.shape[:2], {text}) (degrees across "
                    "the width; the command line's --fov)")
    return hints


def _no_perspective(method: str) -> ValueError:
    """The error for a `K` given to a method without perspective support."""
    able = sorted(k for k, v in methods.REGISTRY.items() if v.perspective)
    return ValueError(
        f"method {method!r} does not support perspective input (`K`); methods that do: "
        f"{able}; or integrate orthographically (K=None; --orthographic ignores a "
        "dataset folder's K.txt)"
    )


def _lacks(method: str, what: str) -> ValueError:
    """The error for a `what` ("prior", "confidence", "prior_blur") that `method` lacks."""
    able = sorted(k for k, v in methods.REGISTRY.items() if getattr(v, what))
    if method == "bini" and what == "prior":
        # (BiNI's reference code has a depth term, lambda1 with depth_map and depth_mask: a
        # BiNI user was told its energy had none, an audit)
        note = ("; facetlift's 'bini' is BiNI without the depth-fusion term of its reference "
                "code (lambda1, depth_map, depth_mask): fuse with method 'dgp' (with "
                "discontinuities=True to keep jumps), NaN where the depth mask is off; "
                "docs/fusion.md relates lambda1 to prior_weight")
        return ValueError(f"method {method!r} does not take a `prior`{note}; methods that "
                          f"do: {able}")
    return ValueError(f"method {method!r} does not take a `{what}` (its energy has no such "
                      f"term); methods that do: {able}")


def _integrate_fitted(kind, normals, mask, *, prior, prior_weight, prior_blur,
                      prior_outliers, **kwargs) -> Surface:
    """:func:`integrate` with a prior known up to scale (and shift): the normals alone
    first, the prior aligned to that surface (:func:`facetlift.prior_fit.fit`), then the
    fusion with the aligned prior."""
    from .methods.dgp import shared_cuts
    from .problem import _is_points, _weight_image, default_prior_weight, fit_zeros, prior_samples

    t0 = time.perf_counter()
    prior_weight = default_prior_weight(prior_weight, prior_blur)
    shape = np.shape(normals)[:2]
    if len(shape) != 2:  # (integrate's own check names the problem)
        return integrate(normals, mask, prior=prior, prior_weight=prior_weight,
                         prior_blur=prior_blur, prior_outliers=prior_outliers, **kwargs)
    inside = None if mask is None else np.asarray(mask)
    inside = inside != 0 if inside is not None and inside.shape == shape else None
    # (raw values: any sign before the alignment)
    raw, own = prior_samples(prior, shape, mask=inside)
    zeros = None
    if kwargs.get("K") is not None and not _is_points(prior, shape):
        # a map for a camera: 0 is a sensor's (or a clipped network's) "unknown", as the
        # unfitted route leaves it out; fitted, the zeros pulled the scale 1e4 off (a review)
        zeros = fit_zeros(raw)
        if zeros is not None:  # (counted in the domain after the first run: _fitted_runs)
            raw = np.where(zeros, np.nan, raw)
    weight = _weight_image(prior_weight, "prior_weight", shape)
    if own is not None:  # (points with their own weights: those times prior_weight, as
        # the fused run below is given them, the aligned prior being a map)
        weight = np.where(np.isfinite(own), weight * own, weight)
        prior_weight = weight
    bar = None
    if kwargs.get("progress") is True:  # (one bar for both runs and the fit between, with
        # its stages named, as the command line's: each run made a bar of its own, an audit)
        from ._progress import progress_bar

        bar, kwargs["progress"] = progress_bar(None)
    if callable(kwargs.get("progress")):  # (one count over both runs, each counting from 1:
        # the bar ran backwards, a review)
        from ._progress import rising

        kwargs["progress"] = rising(kwargs["progress"])
    # (the discontinuity route's prior-free reweightings, run for the first surface, are the
    # second run's first pass: done once, facetlift.methods.dgp.shared_cuts)
    try:
        with shared_cuts():
            return _fitted_runs(kind, normals, mask, raw, weight, t0,
                                prior_weight=prior_weight, prior_blur=prior_blur,
                                prior_outliers=prior_outliers, zeros=zeros, **kwargs)
    finally:
        if bar is not None:
            bar.close()


def _fitted_runs(kind, normals, mask, raw, weight, t0, *, prior_weight, prior_blur,
                 prior_outliers, zeros=None, **kwargs) -> Surface:
    """The two runs of :func:`_integrate_fitted` and the fit between them (`zeros`: the
    prior map's exact zeros, left out, warned about where they lie in the domain)."""
    from . import prior_fit as pf
    from ._progress import announce
    from .problem import prior_blur_value

    failed = None
    with said_if_raised() as said:
        first = integrate(normals, mask, **kwargs)
    if zeros is not None:
        # (those in the domain the normals gave, the first run's: a map's 0 around the object
        # is no sample to miss, and was warned about as 17,148 left out, an audit; with no
        # mask given the domain is the valid normals, a review)
        inside = zeros & first.mask
        if inside.any():
            r, c = np.argwhere(inside)[0]
            # (a review: a network's min-max map holds 0 as a value, at one end; it was called
            # a sensor's mark only)
            warn(f"`prior`: {int(inside.sum())} pixel(s) in the mask hold exactly 0, the first "
                 f"at (row {r}, col {c}): left out of the fit and the fusion as unknown depths "
                 "(a depth sensor's mark, or the end of a map normalised to 0..1, whose few "
                 "pixels there are little lost; NaN is the way to mark unknown depths)")
    with recording() as fitting:
        # (the fit took 16 s of an audit's 1280 x 720 run, under a bar that still read
        # "integrating: 24it" and then counted again from 0 without a word)
        announce(kwargs.get("progress"), "fitting the prior")
        try:
            aligned, details = pf.fit(raw, weight, first, kind, kwargs.get("K") is not None,
                                      blur=prior_blur_value(prior_blur))
        except ValueError as e:
            failed, aligned = e, None
    said = [*said, *fitting]
    for w in said:  # (in their order; the input's only where no second run says them again;
        # others' warnings, a progress callback's or numpy's, as recorded: they were dropped,
        # an audit; one already shown at its line is not recorded again, _warnings.recording)
        if (aligned is None or "prior_fit=" in str(w.message)
                or not getattr(w.message, "from_facetlift", False)):
            reemit(w)
    if failed is not None:
        raise failed
    details["seconds"] = time.perf_counter() - t0
    if aligned is None:  # (left out, with a warning): the normals-only surface
        surface = first
        surface.info["prior"] = {"fit": details, "left_out": True}
    else:
        announce(kwargs.get("progress"), "integrating with the prior")
        with said_if_raised() as fused:
            surface = integrate(normals, mask, prior=aligned, prior_weight=prior_weight,
                                prior_blur=prior_blur, prior_outliers=prior_outliers, **kwargs)
        for w in fused:  # (re-emitted, a torn surface's with what the fit adds to its causes)
            text = str(w.message)
            if text.startswith("discontinuities with a depth prior:") and (
                    "of the facet corners were cut" in text):  # (the torn warning alone)
                # (a user's exact prior with an offset, fitted 'scale' or an 'affine' 4 % off:
                # told it was a noisy dense map, a review)
                text += (f". With prior_fit={kind!r} the prior was aligned first (scale "
                         f"{details['scale']:.4g}, shift {details['shift']:.4g}): an alignment "
                         "a few % off tears a sharp dense prior alike, which a lower "
                         "--prior-weight or --prior-blur also helps"
                         + ("; a prior with an offset needs prior_fit='affine' (a scale alone "
                            "cannot align it)" if kind == "scale" else ""))
                w.message = w.category(text)
            elif text.startswith("the surface deviates from its input normals by") and (
                    "the depth prior fights them" in text):
                # (it asked whether the prior needed prior_fit, given: a network's band along
                # the silhouette was the cause, 55 deg -> 3.9 with it left out, an audit)
                head = text.split("the depth prior fights them.")[0]
                text = (f"{head}the depth prior fights them, though prior_fit={kind!r} aligned "
                        f"it (scale {details['scale']:.4g}, shift {details['shift']:.4g}; "
                        "info['prior']['fit']): a network's depth blends into the background "
                        "along the object's silhouette, which the surface then follows; give "
                        "the prior no weight in a band there (NaN within about 7 px of the "
                        "mask's edge, or a --prior-weight-map that is 0 there; docs/fusion.md, "
                        "'A monocular depth map'), or lower prior_weight (--prior-weight)")
                w.message = w.category(text)
            reemit(w)
        # (left_out always there: a fitted run's lookup of it raised KeyError, a docs check)
        surface.info.setdefault("prior", {}).update(fit=details, left_out=False)
    seconds = surface.info.get("seconds")
    if isinstance(seconds, dict):
        seconds["prior_fit"] = details["seconds"]
        seconds["total"] = time.perf_counter() - t0
    return surface


@functools.wraps(_prepare)
def prepare(normals, mask=None, **kwargs) -> Problem:
    # (the checks integrate makes on the normals as given, first: prepare + solve took a
    # uint8 map as raw 0..255, and [0, 1]-encoded or undecoded float maps, without a word,
    # where integrate decodes or refuses them; architecture.md calls prepare the boundary
    # check, an audit)
    return _prepare(frames.checked(normals, mask), mask, **kwargs)


prepare.__module__ = __name__  # (functools.wraps gave it facetlift.problem's, a review)


def integrate_gradients(
    p, q, mask=None, *, gradient_frame: str = "xy", pixel_size: float = 1.0, **kwargs
) -> Surface:
    """Reconstruct a surface from a gradient field of its height.

    Parameters
    ----------
    p, q : (H, W) array_like of float
        The height's slopes, in height units per world unit (the world width of a pixel is
        `pixel_size`: slopes of a height in other units than the pixels' are no geometric
        slopes); NaN marks a missing sample. The grazing rule of normal maps applies: a
        slope steeper than ``tan(acos(outlier_eps))`` (11.43, 85 degrees, by default; an
        infinite one is a vertical, edge-on facet) is counted as a missing sample, as an
        edge-on normal is (the paper's outlier rule). An exact field with true steep slopes
        (rendered, analytic) keeps them with ``outlier_eps=0``; a field in other height units
        is steeper or flatter by their ratio, so the rule drops other samples (an audit: a
        bump 297.5 high and 6 px wide lost half its samples, the same field in thousandths
        none).
        With ``gradient_frame="xy"`` (default) ``p = dz/dx`` (x right) and ``q = dz/dy``
        (y up); with ``"rowcol"`` (aliases ``"queau"``, ``"numpy"``: Quéau's toolbox,
        ``np.gradient(z)``) ``p = dz/d(row)`` downward and ``q = dz/d(col)``; with ``"image"``
        (aliases ``"matlab"``, ``"opencv"``: MATLAB's ``[FX, FY] = gradient(Z)``, OpenCV's
        Sobel dx and dy) ``p = dz/d(col)`` and ``q = dz/d(row)`` downward.
    mask : (H, W) array_like of bool, optional
        The domain, as for :func:`integrate`; default: where p and q are finite.
    gradient_frame : str
        The layout of (p, q), above ("xy", "rowcol", "image" and their aliases).
    pixel_size : float
        The world width of a pixel: the unit of the slopes' run (default 1: slopes per pixel).
    **kwargs
        As for :func:`integrate` (method, known, solver, outlier_eps, method options); an
        orthographic view only.

    Returns
    -------
    Surface
        ``Surface.height`` is the height whose slopes are (p, q), up to a constant per
        component.

    Raises
    ------
    ValueError
        As :func:`integrate`; also shapes that differ, a bad `gradient_frame`, or `K` /
        `normal_frame` / `normal_rotation` (they do not apply to a gradient field).
    """
    for key in ("K", "normal_frame"):
        if kwargs.get(key) is not None:
            raise ValueError(f"`{key}` does not apply to a gradient field (orthographic slopes)")
    if kwargs.get("normal_rotation") is not None:
        raise ValueError("`normal_rotation` does not apply to a gradient field: its slopes are "
                         "of the height over the image plane, which has no world frame to "
                         "turn from (rotate normals, not slopes: facetlift.integrate(normals, "
                         "normal_rotation=R))")
    px, qy = frames.gradients_to_facetlift(p, q, gradient_frame)
    # (warns when the other layout fits; then the frame check after the solve stays silent)
    layout = frames.layout_check(p, q, gradient_frame, mask)["suggested"]
    normals = normals_from_gradients(px, qy)
    with frames.read_in(frames.GRADIENT_FIELD, layout=layout):  # (hints speak of p and q)
        try:
            return integrate(normals, mask, pixel_size=pixel_size, **kwargs)
        except ValueError as e:
            text = str(e)
            # (a mask, prior or confidence of another size was told to match `normals` and
            # the normal map's size: the field's words, a review)
            said = text.replace("to match `normals`", "to match `p` and `q`").replace(
                "the normal map's size", "the gradient field's size")
            if text.startswith("`normals`"):
                # (the normals are made here from p and q: named so, a user's check)
                said = "`p`, `q` (the normals made from them)" + said[len("`normals`"):]
            if said == text:
                raise
            raise type(e)(said) from None


def _check_discontinuities(info: methods.MethodInfo, value) -> bool:
    """`value` as a bool; True only for a method with the capability (else ValueError)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"`discontinuities` must be True or False; got {value!r}")
    if not value:
        return False
    if not info.discontinuities:
        able = sorted(k for k, v in methods.REGISTRY.items() if v.discontinuities)
        raise ValueError(
            f"method {info.name!r} does not handle depth discontinuities; methods that do: "
            f"{able}"
        )
    return True


def solve(problem: Problem, method: str = "dgp", /, *, max_memory=None, **options):
    """Run `method` on a prepared :class:`~facetlift.problem.Problem`.

    Every option is validated against the method's declarations before it runs
    (:func:`facetlift.options.validate`), and the job's peak memory is planned against
    `max_memory` (:func:`facetlift.memory.plan`); see :func:`integrate` for what is raised.
    The normals `problem` treats as grazing were decided when it was prepared: the
    discontinuity route's own threshold (``MethodInfo.jump_grazing``, cos 87.5 deg for "dgp")
    is applied by :func:`integrate`, so prepare with ``outlier_eps=`` to match it here, and
    with ``grazing_share=`` (``MethodInfo.jump_grazing_share``) for its edge-on surfaces (a
    problem prepared with the camera's own threshold gets a warning where some normal lies
    between the two, either way). Likewise the route's isolated normals
    (``MethodInfo.jump_isolated``): prepare with ``isolated=`` to drop them here (a problem
    prepared without gets a warning where some normal is isolated).
    """
    if not isinstance(problem, Problem):  # (an array gave "no attribute 'counts'": an audit)
        raise ValueError(f"solve() takes a Problem from facetlift.prepare(normals, ...); got "
                         f"{type(problem).__name__} (for a normal map as an array, "
                         "facetlift.integrate(normals, ...) prepares and solves at once)")
    if "method" in options and not any(o.name == "method" for o in methods.get(method).specs()):
        raise ValueError(f"solve() takes the method as its second positional argument: "
                         f"solve(problem, {options['method']!r}); got method={options['method']!r}"
                         " as a keyword")
    return _solve(problem, method, None, max_memory, options)


def _no_progress(iteration, value):
    """(A stand-in for ``progress=True`` while the options are checked.)"""


def _progress_option(options: dict, info) -> None:
    """`options`' ``progress`` checked and taken out where it asks for nothing: False or None
    (``progress=verbose``: False was refused, an audit), or a method without iterations,
    which has nothing to report (progress= is accepted by every method, as the command
    line's --progress is; frankot_chellappa refused a callable, a user's, and took any value,
    an audit)."""
    if "progress" not in options:
        return
    value = options["progress"]
    if isinstance(value, np.bool_):  # (numpy's bools as bool options take them, a review)
        value = options["progress"] = bool(value)
    if value is None or value is False:
        options.pop("progress")
        return
    if not (value is True or callable(value)):
        raise ValueError(f"`progress` must be True (a progress bar on stderr), False, a "
                         f"callable or None; got {value!r}")
    if value is not True:  # (one of the wrong arity failed as a TypeError once the solve had
        # begun, an audit)
        try:
            inspect.signature(value).bind(0, 0.0)
        except TypeError:
            raise ValueError(f"`progress` is called as progress(iteration, value) (the "
                             f"iteration's count and its measure: a deviation, a residual); "
                             f"{getattr(value, '__name__', value)!r} cannot take two "
                             "arguments") from None
        except ValueError:  # (no signature to read: a builtin; called as it is)
            pass
    if "progress" not in info.options():
        options.pop("progress")


def _solve(problem, method, t0, max_memory, options):
    """:func:`solve`, timed from `t0` (integrate's start; None: now). (Its own arguments are
    positional here: an option named ``t0`` or ``problem`` is the method's, refused as such.)"""
    t0 = time.perf_counter() if t0 is None else t0
    if options.get("progress") is True:  # the command line's bar, on stderr
        from ._progress import progress_bar

        bar, update = progress_bar(None)
        try:
            return _solve(problem, method, t0, max_memory, {**options, "progress": update})
        finally:
            bar.close()
    info = methods.get(method)
    options = dict(options)
    _progress_option(options, info)
    values = validate(info.specs(), options, method)
    eps = problem.counts.get("outlier_eps")
    jump = info.jump_grazing
    if (values.get("discontinuities") and jump is not None and eps is not None
            and eps != jump and not problem.extras.get("outlier_eps_given", True)):
        # (integrate applies the route's own threshold; prepare + solve took the camera's:
        # told where some normal lies between the two, either way)
        between = problem.grazing_between(
            eps, jump, share=info.jump_grazing_share if eps < jump else None)
        bear_note = " (the DiLiGenT bear with the pinhole default: 0.28 mm MADE against 0.046)"
        if between:
            warn(f"discontinuities=True on a problem prepared with the camera's grazing "
                 f"threshold (view cosine {eps:.4g}): integrate uses the route's own, cos "
                 f"{np.degrees(np.arccos(jump)):.3g} deg, which would treat {between} "
                 f"{'more' if eps < jump else 'fewer'} normal(s) as missing here"
                 f"{bear_note if eps < jump else ''}; "
                 f"prepare(..., outlier_eps=facetlift.METHODS[{method!r}].jump_grazing, "
                 f"grazing_share=facetlift.METHODS[{method!r}].jump_grazing_share) to match")
    if (values.get("discontinuities") and info.jump_isolated is not None
            and not problem.extras.get("isolated_given", True)):
        # (integrate drops the route's isolated normals; prepare + solve kept them: said)
        from .problem import isolated_rule_text

        kept = int(problem.isolated(info.jump_isolated).sum())
        if kept:
            warn(f"discontinuities=True on a problem prepared without the route's isolated "
                 f"normals rule: integrate would treat {kept} isolated normal(s) as missing "
                 f"here ({isolated_rule_text(info.jump_isolated)}); "
                 f"prepare(..., isolated=facetlift.METHODS[{method!r}].jump_isolated) to "
                 "match")
    if problem.perspective and not info.perspective:
        raise _no_perspective(method)
    for what, given in (("prior", problem.prior is not None),
                        ("confidence", problem.confidence is not None),
                        ("prior_blur", problem.prior_blur > 0)):
        if given and not getattr(info, what):
            raise _lacks(method, what)
    if not problem.usable.all() and not info.missing:
        raise ValueError(
            f"method {method!r} cannot take missing samples ({int((~problem.usable).sum())} "
            "pixels in the mask have no usable normal); fill them or use a method that can, "
            "e.g. 'dgp'"
        )
    plan = memory.plan(problem, method, values, max_memory)
    t1 = time.perf_counter()
    cropped, offset = crop(problem)
    try:
        with memory.headroom(plan):
            result = info.run(cropped, **values)
    except np.linalg.LinAlgError as e:  # a ValueError subclass, but a solver failure
        raise SolverError(f"method {method!r}: linear algebra failed ({e})") from e
    t2 = time.perf_counter()
    if (result.vertex_values is None and result.values is not None
            and "corner_values" not in result.extras):  # (dgp's routes do it themselves)
        result = _flat_where_no_normal(cropped, result)
    surface = make_surface(cropped, result, method)
    t3 = time.perf_counter()
    checks = diagnose(cropped, surface)
    t4 = time.perf_counter()
    surface = uncrop(surface, problem, offset)
    out = dict(result.info)
    out.setdefault("iterations", 1)  # (a direct method: one solve, done)
    out.setdefault("converged", True)
    out.update(checks)
    out["method"] = method
    out["projection"] = problem.camera.projection
    out["input"] = dict(problem.counts)
    out["memory_estimate"] = plan.estimate
    if problem.prior is not None:
        out["prior"] = prior_info(problem, surface)
        blurred = problem.prior_blur > 0 and not (out.get("prior_blur") or {}).get("fallback")
        _far_samples_check(out["prior"], blurred, out.get("solver") == "discontinuous"
                           or not getattr(info, "discontinuities", False),
                           dense=out["prior"].get("samples", 0) > DENSE * problem.domain.n_facets,
                           deviation=out.get("mean_deviation"))
        _prior_fight_check(out.get("mean_deviation"), out.get("solver") == "discontinuous",
                           problem.camera.projection == "orthographic")
    _degenerate_check(surface, out.get("mean_deviation"), bool(problem.usable.any()),
                      problem.prior is not None)
    seconds = dict(out.get("seconds", {}))
    seconds["prepare"] = t1 - t0
    seconds["total"] = time.perf_counter() - t0
    seconds["method"] = t2 - t1
    seconds["diagnose"] = t4 - t3
    out["seconds"] = seconds
    surface.info = out
    if log.isEnabledFor(logging.INFO):
        log.info("%s: %s", method, info_text({k: v for k, v in out.items() if k != "deviation"}))
    return surface


def info_text(info: dict, prefix: str = "") -> str:
    """``surface.info`` as one readable line for the log (``facetlift -v``): ``key=value``
    pairs, nested dicts as dotted keys, floats to 4 significant digits, long lists
    summarised by their length and ends."""

    def value(v):
        if isinstance(v, str):  # (quoted where a space would split the pair)
            return repr(v) if (" " in v or not v) else v
        if isinstance(v, (bool, np.bool_)) or v is None:
            return str(v)
        if isinstance(v, (float, np.floating)):
            return f"{float(v):.4g}"
        if isinstance(v, (list, tuple, np.ndarray)):
            items = [value(x) for x in (v.ravel().tolist() if isinstance(v, np.ndarray) else v)]
            if len(items) > 6:
                return f"[{len(items)}: {', '.join(items[:2])} ... {items[-1]}]"
            return f"[{', '.join(items)}]"
        return str(v)

    parts = []
    for k, v in info.items():
        if isinstance(v, dict):
            if v:
                parts.append(info_text(v, f"{prefix}{k}."))
        else:
            parts.append(f"{prefix}{k}={value(v)}")
    return " ".join(parts)


#: With a depth prior, a surface whose facets deviate from the input normals by more than this
#: mean angle (degrees) is said to be fought over by the prior (a warning). A user's check: a
#: monocular network's disparity (inverse depth) given as the prior returned deviations of 82
#: and 124 deg, depth anti-correlated with the truth, exit 0 and no word; the same scenes'
#: normals alone deviate by 0.1-1.2 deg. A right prior on a scene with depth jumps integrated
#: without discontinuities deviates too (a review: a box at 1 m before a wall at 3 m, 60 deg
#: view, 31-33 deg; an orthographic 60 px jump 28-29 deg), hence 45 and the message's first
#: question.
PRIOR_FIGHT = 45.0


def _prior_fight_check(deviation, discontinuities: bool, orthographic: bool = False) -> None:
    if deviation is not None and np.isfinite(deviation) and deviation > PRIOR_FIGHT:
        jumps = ("" if discontinuities else "If the scene has depth jumps, integrate with "
                 "discontinuities=True (--discontinuities): a prior across a jump bends the "
                 "smooth surface. ")
        # (a user forgot --K with a metric prior: orthographic pixel units against metres)
        camera = ("Without K the depth is orthographic, in units of pixel_size (default 1: "
                  "pixels): a metric prior from a perspective camera needs its K (--K). "
                  if orthographic else "")
        warn(f"the surface deviates from its input normals by {deviation:.0f} deg on average: "
             f"the depth prior fights them. {jumps}{camera}Is the prior depth along the "
             "viewing axis (larger = farther; not disparity or inverse depth, which must be "
             "inverted first), in the output's units (metric with K), and aligned (a monocular "
             "network's relative depth or disparity needs its scale and shift fitted: "
             "prior_fit='affine' or 'disparity', --prior-fit; docs/fusion.md, 'Recipes')? "
             "Else lower prior_weight (--prior-weight)")


#: A perspective result whose farthest facet is more than this many times as far as its
#: nearest is reported as degenerate (:func:`_degenerate_check`): a review's monocular 0..1
#: depth, not fitted (prior_fit) and declared blurred, returned depths from 1e-28 to 3e7 with
#: exit 0 and its mean deviation left out of the summary. A real scene seen by one camera
#: spans far less (a room 0.5-20 m, a street to a few hundred metres: 1e3).
DEGENERATE_RANGE = 1e6


def _degenerate_check(surface, deviation, usable: bool, prior: bool) -> None:
    """Warn where the result is numerically degenerate: a perspective depth range beyond
    :data:`DEGENERATE_RANGE`, or no measurable deviation from the normals (overflow) where
    there are usable normals."""
    why = None
    if surface.camera.perspective:  # (fmin / fmax pass over NaN: no copy of a large map)
        d = surface.depth.ravel()
        lo, hi = float(np.fmin.reduce(d)), float(np.fmax.reduce(d))
        if lo > 0 and hi > DEGENERATE_RANGE * lo:  # (False where all are NaN)
            why = f"its depths span {lo:.3g} to {hi:.3g}"
    if why is None and usable and (deviation is None or not np.isfinite(deviation)):
        why = "its deviation from the input normals cannot be measured (overflow)"
    if why is not None:
        cause = ("A depth prior of another kind than the depth (a relative depth or a "
                 "disparity not fitted, prior_fit / --prior-fit; values near 0) or a wrong K "
                 "can do this; check them, or integrate without the prior to see the normals' "
                 "own surface" if prior else "Check K (--K, --fov) and the normals' frame")
        warn(f"the surface returned is degenerate: {why}. {cause}")


#: A prior sample lies far from the surface returned when its depth difference exceeds both
#: FAR times the samples' median difference and FAR_FLOOR of the scale (the median sample
#: depth with a camera, else the samples' depth range): a warning names how many. A LiDAR
#: user's 154 occluded and flying points (of 2,900) lay up to 0.69 m off, the median 17 mm
#: (a mean error of 22.8 mm against 12.0 without them), with no word. The floor is 2 %: exact
#: samples next to a jump meet a mixed facet there (on an analytic occluder 3 of 60 exact
#: samples lay 0.5-3 % of their range off); 3 % outliers 30-80 mm off 1 % samples of the
#: DiLiGenT bear (1.5 m away) were found at weights 0.01 and 1, not at 100, where the
#: surface meets them (tests/test_fusion.py).
FAR, FAR_FLOOR = 10.0, 0.02


#: A smooth surface that deviates from its normals by less than this mean angle (degrees)
#: bends over depth jumps little, if at all: the far-samples warning then names outliers
#: first and the jumps second (a review: a depth sensor's flying pixels on the jump-free
#: DiLiGenT bear, 0.9-2.4 deg, were told to integrate with discontinuities first, which raised
#: the error 2.77 -> 3.20 mm; the diff review: exact priors on the analytic fold, occluder
#: and helix, 0.9-2.8 deg, do want discontinuities, 0.70 -> 0.014 on the fold, so the jumps
#: stay named).
BENT = 3.0


def _far_samples_check(info: dict, blurred: bool, discontinuities: bool = True,
                       dense: bool = False, deviation=None) -> None:
    """The far-samples warning (:data:`FAR`); `discontinuities`: the route cut jumps, or the
    method cannot (no hint to do so); `dense`: a depth map, not points (a network's blend of
    foreground and background at the silhouettes is the likelier cause); `deviation`: the
    surface's mean deviation from its normals (:data:`BENT`)."""
    far = info.get("far_samples", 0)
    # (the smooth route bends over a depth jump and leaves exact samples there far from it:
    # 1-2 of 12 renders with 5 % exact or noisy samples on the fusion benchmark)
    jumps = ("" if discontinuities else ", or samples across a depth jump that the smooth "
             "surface bends over (discontinuities=True, --discontinuities, cuts it)")
    if far and not blurred:  # (a blurred prior's samples differ from the surface by design)
        r, c = info["farthest_sample"]
        # (a dense map's far samples are mostly its silhouettes, where a monocular network
        # blends foreground and background: the warning spoke only of sensors' flying points
        # and SfM, an audit)
        band = ("; in a dense map (a monocular network's), mostly a band along the "
                "silhouettes where it blends foreground and background: give the prior's blur "
                "(prior_blur, --prior-blur) or zero weight on that band (prior_weight map, "
                "--prior-weight-map; docs/fusion.md, 'A monocular depth map')" if dense else "")
        head = (f"prior: {far} of the {info['samples']} samples lie far from the surface "
                f"returned (more than {info['far_threshold']:.3g} from it, {FAR:g} times the "
                f"median distance or more; the farthest {info['farthest_distance']:.3g} at "
                f"(row {r}, col {c})): ")
        bent = deviation is None or not np.isfinite(deviation) or deviation >= BENT
        if not discontinuities and bent:
            # (the smooth route: the surface, bent over the jumps, is the likelier fault than
            # the samples; an audit of exact priors, 16 of 41 smooth runs warned, and the
            # samples removed as told raised the error on 4 of 5 renders and on the analytic
            # occluder, 3.29 -> 5.4-7.6 %, where discontinuities=True gives 0.063 %)
            warn(head + "the smooth surface bends over depth jumps and leaves correct samples "
                 "far from it: integrate with discontinuities=True (--discontinuities) first. "
                 "Else outliers, such as a depth sensor's occluded or flying points or "
                 f"mismatched SfM points{band}? Outliers pull the surface with them: remove "
                 "them and run again (docs/fusion.md, 'Outlier samples'; info['prior'], "
                 "--json)")
            return
        warn(head + "outliers, such as a depth sensor's occluded or flying points or "
             f"mismatched SfM points, or samples on a depth jump's edge{jumps}{band}? "
             "Outliers pull the surface with them: remove them and run again (docs/fusion.md, "
             "'Outlier samples'; info['prior'], --json)")


def prior_info(problem: Problem, surface: Surface) -> dict:
    """``info["prior"]``: samples used (and ``outside_mask``: samples where there is no normal,
    dropped), components whose constant the prior fixed, those that
    kept the camera's gauge (1-based labels of ``Domain.labels``) and that gauge (None when
    the prior fixed every component), and the fit at the samples (mean and largest absolute
    depth difference; ``far_samples``, and with two or more finite samples ``far_threshold``
    and ``farthest_sample`` (row, col): :data:`FAR`) and ``outliers``: the samples left out
    before the solve (:mod:`facetlift.prior_outliers`; ``removed``, and ``skipped`` with the
    reason where the prior was not checked; None with ``prior_outliers="keep"``): ``samples``
    counts those used, ``info["input"]["prior_samples"]`` those given in the mask (pixels)."""
    d = problem.domain
    w = problem.prior_weight
    used = w > 0
    fixed = problem.prior_components
    depth = surface.depth[d.mask]
    target = problem.camera.to_depth(np.where(used, problem.prior, 0.0))
    diff = np.abs(depth - target)[used]
    # (the camera's gauge applies only to the components without a sample)
    gauge = problem.camera.gauge_name if (~fixed).any() else None
    return {
        "samples": int(used.sum()),
        "outside_mask": int(problem.counts.get("prior_outside_mask", 0)),
        "components": int(d.n_components),
        "prior_components": [int(k) + 1 for k in np.flatnonzero(fixed)],
        "gauged_components": [int(k) + 1 for k in np.flatnonzero(~fixed)],
        "gauge": gauge,
        "outliers": problem.extras.get("prior_outliers"),
        "trend": problem.extras.get("prior_trend"),
        "relief_ratio": problem.extras.get("prior_relief"),
        "relief_warned": bool(problem.extras.get("prior_relief_warned", False)),
        "mean_abs_residual": float(diff.mean()) if diff.size else 0.0,
        "max_abs_residual": float(diff.max()) if diff.size else 0.0,
        **_far_samples(problem, diff, target[used]),
    }


def _far_samples(problem: Problem, diff: np.ndarray, depths: np.ndarray) -> dict:
    """``far_samples`` (how many samples lie far from the surface: :data:`FAR`), the
    threshold and the farthest sample's (row, col)."""
    ok = np.isfinite(diff)  # (a facet flattened or left out: the other samples are checked)
    if ok.sum() < 2:
        return {"far_samples": 0}
    if problem.camera.perspective:
        scale = float(np.median(depths[ok]))
    else:  # (the object's size too: a fronto-parallel wall's samples span no depth, and 3 deg
        # of smooth noise on its normals put one exact sample past 10x the median, a review)
        rows, cols = np.nonzero(problem.domain.mask)
        size = max(np.ptp(rows), np.ptp(cols)) + 1
        scale = max(float(np.ptp(depths[ok])), size * problem.camera.pixel_size)
    threshold = max(FAR * float(np.median(diff[ok])), FAR_FLOOR * scale)
    far = ok & (diff > threshold)
    k = int(np.argmax(np.where(ok, diff, -np.inf)))
    r, c = problem.domain.pixels
    used = np.flatnonzero(problem.prior_weight > 0)
    return {"far_samples": int(far.sum()), "far_threshold": threshold,
            "farthest_sample": [int(r[used[k]]), int(c[used[k]])],
            "farthest_distance": float(diff[k])}


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
    # (a new dict: the methods' messages that name a pixel give it in the image's rows and
    # columns, not the crop's, a review)
    sub.extras = {**sub.extras, "offset": (int(r0), int(c0)), "image_shape": mask.shape}
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
    cuts = disc = split = None
    if surface.cuts is not None:
        right = np.zeros((H, W - 1), bool)
        down = np.zeros((H - 1, W), bool)
        right[r0 : r0 + h, c0 : c0 + w - 1] = surface.cuts[0]
        down[r0 : r0 + h - 1, c0 : c0 + w] = surface.cuts[1]
        cuts = (right, down)
        disc = np.full((H, W), np.nan)
        disc[r0 : r0 + h, c0 : c0 + w] = surface.discontinuities
        corners, i, j, sdepth = surface.split
        split = (corners, i + r0, j + c0, sdepth)
    return Surface(
        depth=depth, vertex_depth=vdepth, mask=problem.domain.mask.copy(), camera=problem.camera,
        cuts=cuts, discontinuities=disc, split=split,
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
    copies = result.extras.get("corner_values")
    mesh = None
    if copies is not None:  # a discontinuity-preserving result: split the mesh at its jumps
        from .operators.split import GAP, from_copies

        mesh = result.extras.get("split_mesh")  # (the method's split of these copies, if any)
        if mesh is None:
            mesh, svals = from_copies(d, copies, GAP * problem.camera.footprint())
        else:
            svals = mesh.values_of(copies)
        result.info["mesh_pieces"] = mesh.n_pieces  # (the pieces of the mesh returned)
        # (those the cuts add to the mask's components, each a piece at least)
        result.info["cut_pieces"] = mesh.n_pieces - d.n_components
        # vertex grid values: the mean of a grid vertex's copies (the mesh uses the copies)
        counts = np.bincount(mesh.vertex, minlength=d.n_vertices)
        grid = np.bincount(mesh.vertex, svals, d.n_vertices) / np.maximum(counts, 1)
        result = methods.MethodResult(values=svals[mesh.corners].mean(axis=1),
                                      vertex_values=grid, info=result.info)
    if result.vertex_values is not None:
        vval = np.asarray(result.vertex_values, dtype=float)
        fval = d.facet_centres(vval) if result.values is None else np.asarray(result.values, float)
    elif result.values is not None:
        fval = np.asarray(result.values, dtype=float)
        vval = vertex_values(problem, fval)
    else:  # pragma: no cover - a method bug
        raise RuntimeError("method returned neither values nor vertex_values")
    cam = problem.camera
    with np.errstate(over="ignore", invalid="ignore"):
        shift = cam.gauge(fval, d.facet_component, d.n_components)
        if problem.has_prior:  # the prior fixed these components' constants
            shift = np.where(problem.prior_components, 0.0, shift)
        depth = cam.to_depth(fval - shift[d.facet_component])
        vdepth = cam.to_depth(vval - shift[d.vertex_component])
    if not (np.isfinite(depth).all() and np.isfinite(vdepth).all()):
        # a non-finite value, or one whose depth overflows (huge slopes, exp of log-depth)
        bad = int((~np.isfinite(depth)).sum())
        raise SolverError(
            f"method {method!r} produced non-finite depth at {bad} of {fval.size} pixels inside "
            "the mask"
        )
    surface = Surface(
        depth=d.to_image(depth), vertex_depth=d.to_vertex_image(vdepth), mask=d.mask.copy(),
        camera=cam,
    )
    if mesh is not None:
        _attach_split(surface, d, mesh, cam.to_depth(svals - shift[_split_component(d, mesh)]))
    return surface


def _flat_where_no_normal(problem: Problem, result):
    """A pixel-value method's components without any usable normal (and no prior sample)
    flat, with one warning, as dgp makes them: the graph methods returned them flat in
    silence, Frankot-Chellappa and kernel made a shape up (a 12-unit bump)."""
    from .methods.dgp.common import empty_components

    d = problem.domain
    empty = empty_components(d, problem.usable,
                             problem.prior_components if problem.has_prior else None,
                             problem.extras.get("offset", (0, 0)))
    if empty.size:
        values = np.array(result.values, dtype=float, copy=True)
        values[np.isin(d.facet_component, empty)] = 0.0
        result = methods.MethodResult(values=values, vertex_values=None, info=result.info,
                                      extras=result.extras)
    return result


def vertex_values(problem: Problem, fval: np.ndarray) -> np.ndarray:
    """Vertex values (n,) for a method that returns only the pixels' (facet centres') values
    `fval` (m,): inside, the mean of the four pixels around a vertex; on the mask's edge
    (fewer than four), the mean of each pixel's value carried to that corner along its own
    normal (half a pixel step of its grid slopes; a pixel without a usable normal carries its
    value flat). The mean of the pixels alone put an edge corner at its one pixel's value,
    folding the edge quads of the mesh (a saddle integrated exactly by ``poisson`` showed a
    mean deviation of 1.1 degrees, all of it on the edge facets)."""
    d = problem.domain
    c = d.corners.ravel()
    counts = np.bincount(c, minlength=d.n_vertices)
    vval = np.bincount(c, np.repeat(fval, 4), d.n_vertices) / counts
    edge = counts < 4
    if edge.any():
        gx, gy = problem.grid_slopes
        sx = np.array([-1.0 + 2.0 * dc for _, dc in CORNER_OFFSETS])  # +1 on the right
        sy = np.array([1.0 - 2.0 * dr for dr, _ in CORNER_OFFSETS])  # +1 on the top (y up)
        carried = fval[:, None] + 0.5 * np.nan_to_num(
            gx[:, None] * sx + gy[:, None] * sy, nan=0.0, posinf=0.0, neginf=0.0)
        vval = np.where(edge, np.bincount(c, carried.ravel(), d.n_vertices) / counts, vval)
    return vval


def _split_component(d: Domain, mesh) -> np.ndarray:
    comp = np.empty(mesh.n_vertices, dtype=np.int64)
    comp[mesh.corners.ravel()] = np.repeat(d.facet_component, 4)
    return comp


def _attach_split(surface: Surface, d: Domain, mesh, sdepth: np.ndarray) -> None:
    """Give `surface` its cut edges, jump map and split mesh; depth is the mean of each facet's
    mesh corners already (see make_surface)."""
    H, W = d.shape
    # the cut edges are those the mesh splits: two facets on an edge with a corner apart (an
    # edge whose copies parted, but whose ends stay joined around it, is no cut: the map and
    # the cut arrays marked it, the mesh did not; found by a fresh-user check)
    sv = np.full((H, W, 4), -1, dtype=np.int64)
    sv[d.pixels] = mesh.corners
    inside_r = d.mask[:, :-1] & d.mask[:, 1:]
    inside_d = d.mask[:-1] & d.mask[1:]
    right = inside_r & ((sv[:, :-1, 1] != sv[:, 1:, 0]) | (sv[:, :-1, 2] != sv[:, 1:, 3]))
    down = inside_d & ((sv[:-1, :, 3] != sv[1:, :, 0]) | (sv[:-1, :, 2] != sv[1:, :, 1]))
    corner = np.full((H, W, 4), np.nan)
    corner[d.pixels] = sdepth[mesh.corners]  # depth of every facet's own corners
    with np.errstate(invalid="ignore"):
        # the jump at a cut edge: the two facets' corner depths on it, averaged over its ends
        jr = 0.5 * (np.abs(corner[:, :-1, 1] - corner[:, 1:, 0])
                    + np.abs(corner[:, :-1, 2] - corner[:, 1:, 3]))
        jd = 0.5 * (np.abs(corner[:-1, :, 3] - corner[1:, :, 0])
                    + np.abs(corner[:-1, :, 2] - corner[1:, :, 1]))
    jr = np.where(right, jr, 0.0)
    jd = np.where(down, jd, 0.0)
    jump = np.zeros(d.shape)
    jump[:, :-1] = np.maximum(jump[:, :-1], jr)
    jump[:, 1:] = np.maximum(jump[:, 1:], jr)
    jump[:-1] = np.maximum(jump[:-1], jd)
    jump[1:] = np.maximum(jump[1:], jd)
    vi, vj = np.nonzero(d.vertex_mask)
    surface.cuts = (right, down)
    surface.discontinuities = np.where(d.mask, jump, np.nan)
    surface.split = (mesh.corners, vi[mesh.vertex], vj[mesh.vertex], sdepth)
